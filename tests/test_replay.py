"""``[controller] kind = "replay"``: a plan of timed (v, omega) commands drives a velocity-commanded plant open loop,
held row by row, delayed as ``[sensing]`` says, refused when it is malformed or beyond the robot; and a run of an
excitation plan, exported as a bag, identifies the plant it ran on (the loop excite, run, export, identify)."""

from __future__ import annotations

import numpy as np
import pyarrow.parquet as pq
import pytest

import ddtrack
from ddtrack.model.lag import PIONEER_3DX_WITH_LASER
from ddtrack.ros import export_run
from ddtrack.sysid import excitation_plan, identify_lag, read_speed_log

PERIOD = 0.03  # 11 T_c rounds to 0.32999999999999996 s, below the row at 0.33 s that it must pick
# rows off the control grid (0.1, 0.8), on it (0.12, 0.33, 0.6), a turn, a reversal, a last row that is not a stop
PLAN = "# a plan\nt,v,omega\n0.1,0.3,0.0\n0.12,0.4,0.5\n0.33,0.2,-0.25\n0.6,-0.1,0.0\n0.8,0.15,0.1\n"


def scenario_text(
    *,
    controller: str = 'file = "plan.csv"',
    plant: str = "unicycle",
    extra: str = "",
    duration: float = 1.2,
    speed: float = 0.1,
    period: float = PERIOD,
) -> str:
    return (
        f'name = "replay"\n[simulation]\nduration = {duration}\ncontrol_period = {period}\n'
        f'metric_window = [0.0, {duration}]\n[robot]\npreset = "pioneer_3dx"\n[plant]\nmodel = "{plant}"\n{extra}'
        f'[trajectory]\nkind = "line"\nspeed = {speed}\n[controller]\nkind = "replay"\n{controller}\n'
    )


def load(tmp_path, plan: str = PLAN, **kwargs):
    (tmp_path / "plan.csv").write_text(plan)
    (tmp_path / "scenario.toml").write_text(scenario_text(**kwargs))
    return ddtrack.load_scenario(tmp_path / "scenario.toml")


def held(times: list[float], commands: list[tuple[float, float]], t: np.ndarray, end: float) -> np.ndarray:
    """The plan's command at each t by its definition: the last row at or before t, zero before and after."""
    out = np.zeros((len(t), 2))
    for k, tk in enumerate(t):
        rows = [i for i, ti in enumerate(times) if ti <= tk + 1e-9]
        if rows and tk < end - 1e-9:
            out[k] = commands[rows[-1]]
    return out


def test_the_commands_are_the_files_rows_held_and_the_unicycle_takes_them_one_period_later(tmp_path):
    scenario = load(tmp_path)
    assert scenario.controller.times == [0.1, 0.12, 0.33, 0.6, 0.8]
    columns = ddtrack.timeseries(ddtrack.run(scenario))
    t = np.arange(len(columns["t"])) * PERIOD
    # the last row (t = 0.8) is held as long as the step before it (0.2 s), then the robot stops
    expected = held(scenario.controller.times, scenario.controller.commands, t, end=1.0)
    np.testing.assert_array_equal(np.column_stack([columns["v_cmd"], columns["omega_cmd"]]), expected)
    assert 11 * PERIOD < 0.33 and np.all(expected[11] == [0.2, -0.25])  # k T_c picks row k despite rounding
    assert np.all(expected[:4] == 0) and np.all(expected[(t > 0.79) & (t < 1.0)] == [0.15, 0.1])
    assert np.all(expected[t > 1.0] == 0) and len(t) == 40
    np.testing.assert_array_equal(columns["saturated"], 0.0)
    # the ideal unicycle's speeds at t_{k+1} are the command held over [t_k, t_k+1)
    np.testing.assert_array_equal(np.column_stack([columns["v"], columns["omega"]])[1:], expected[:-1])


def test_an_actuation_delay_shifts_the_commands_as_the_sensing_chain_documents(tmp_path):
    """tau_a = 1.5 T_c: during period j the command of period j - 2 acts for the first half of the period and that
    of period j - 1 for the rest (ddtrack.model.sensing), so the robot driving straight advances by their mean."""
    straight = "t,omega,v\n0.0,0,0.2\n0.1,0,0.5\n0.25,0,-0.3\n0.5,0,0.1\n"  # columns in another order
    scenario = load(tmp_path, straight, extra=f"[sensing]\nactuation_delay = {1.5 * PERIOD}\n")
    columns = ddtrack.timeseries(ddtrack.run(scenario))
    command = columns["v_cmd"]
    np.testing.assert_array_equal(command[:10], [0.2] * 4 + [0.5] * 5 + [-0.3])  # the plan itself, not delayed
    before = np.concatenate([[0.0, 0.0], command])  # nothing was commanded before the run
    earlier, later = before[:-2], before[1:-1]  # the commands of periods j - 2 and j - 1
    np.testing.assert_allclose(np.diff(columns["x"]), PERIOD * 0.5 * (earlier + later)[:-1], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(columns["v"][1:], later[:-1])


def test_the_resolved_scenario_holds_the_rows_inline_and_reruns_to_the_same_bits(tmp_path, cli):
    load(tmp_path)
    first, again = tmp_path / "first", tmp_path / "again"
    assert cli("run", tmp_path / "scenario.toml", "--out", first)[0] == 0
    resolved = (first / "scenario.toml").read_text()
    assert "file" not in resolved and "times = [" in resolved and "commands = [" in resolved
    reloaded = ddtrack.load_scenario(first / "scenario.toml")
    original = load(tmp_path).controller
    assert (reloaded.controller.times, reloaded.controller.commands) == (original.times, original.commands)
    assert cli("run", first / "scenario.toml", "--out", again)[0] == 0
    a, b = pq.read_table(first / "timeseries.parquet"), pq.read_table(again / "timeseries.parquet")
    assert a.column_names == b.column_names and a.num_rows == b.num_rows == 40
    for name in a.column_names:  # NaN where a velocity plant has no torques: equal_nan
        assert np.array_equal(a.column(name).to_numpy(), b.column(name).to_numpy(), equal_nan=True), name
    assert np.ptp(a.column("v_cmd").to_numpy()) > 0  # the plan reached the run


@pytest.mark.parametrize(
    ("plan", "message"),
    [
        ("t,v,omega\n0,0.1,0\n0.2,0.2,0\n0.2,0.3,0\n", "line 4: t = 0.2 s is not after 0.2 s"),
        ("t,v,omega\n0,0.1,0\n0.1,nan,0\n", "line 3: '0.1,nan,0' holds NaN or inf"),
        ("t,v,omega\n0,0.1\n", "line 2: expected 3 numbers 't,v,omega'"),
        ("t,v\n0,0.1\n", "line 1: the header has no 'omega' column; t, v and omega are required"),
        ("t,v,yaw\n0,0.1,0\n", "line 1: unknown column 'yaw'"),
        ("# no header\n0,0.1,0\n", "line 2: a header line naming the columns t, v, omega"),
        ("t,v,omega\n", "has no rows"),
    ],
    ids=["time-goes-back", "nan", "short-row", "no-omega", "unknown-column", "no-header", "no-rows"],
)
def test_bad_plan_files_are_refused_naming_the_line(tmp_path, plan, message):
    with pytest.raises(ddtrack.ConfigError, match=r"^controller\.file: replay file '.*plan\.csv' .*" + message):
        load(tmp_path, plan)


@pytest.mark.parametrize(
    ("controller", "message"),
    [
        ('file = "../plan.csv"', r"controller\.file: '\.\./plan\.csv' leads outside the scenario's folder"),
        ("times = [0.0, 0.1]\ncommands = [[0.1, 0.0]]", r"controller\.commands: has 1 rows for 2 times"),
        ("times = [0.0, 0.0]\ncommands = [[0.1, 0.0], [0.2, 0.0]]", r"controller\.times\[1\]: 0 s is not after 0 s"),
        ("times = []\ncommands = []", r"controller\.times: is empty"),
        ("times = [0.0]", r"(?s)controller\.commands: is missing.*give 'file'"),
        ('file = "plan.csv"\ntimes = [0.0]\ncommands = [[0.0, 0.0]]', r"controller\.file: give only one of"),
        ("commands = [[0.0, 0.0, 1.0]]\ntimes = [0.0]", r"controller\.commands\[0\]"),
    ],
    ids=["outside", "lengths", "inline-time-goes-back", "empty", "no-commands", "both", "three-numbers"],
)
def test_bad_plans_are_refused_naming_the_field(tmp_path, controller, message):
    with pytest.raises(ddtrack.ConfigError, match=message):
        load(tmp_path, controller=controller)


def test_a_plan_beyond_the_presets_top_speeds_is_refused_naming_the_line(tmp_path):
    fast = "t,v,omega\n0,0.5,0\n1,1.5,0\n"  # a Pioneer 3-DX tops out at 1.2 m/s
    with pytest.raises(ddtrack.ConfigError, match=r"(?s)^controller\.file: .*line 3 commands a speed of 1\.5 m/s.*"):
        load(tmp_path, fast)
    spinning = "times = [0.0, 1.0]\ncommands = [[0.0, 0.0], [0.0, -6.0]]"  # 300 deg/s = 5.24 rad/s
    with pytest.raises(ddtrack.ConfigError, match=r"controller\.commands\[1\]: .*yaw rate of 6 rad/s.*5\.236"):
        load(tmp_path, controller=spinning)
    # any reference loads, even beyond the robot: a replay has no clamp to check it against (the reference is unused)
    assert load(tmp_path, "t,v,omega\n0,1.2,5.2\n", speed=5.0).controller.commands == [(1.2, 5.2)]


def test_a_replayed_excitation_plan_identifies_the_lag_plant_it_ran_on(tmp_path, cli):
    """``ddtrack excite``'s plan (20 s within 60 % of a Pioneer 3-DX's limits) replayed on its identified lags with
    a 0.1 s command delay, exported as a bag, gives back theta and the delay. The log has no noise: the fit is off
    by about 1e-7 relative (the plant's RK4 steps against the fit's model), far inside 0.1 %."""
    plan = excitation_plan(max_speed=1.2, max_yaw_rate=5.24, duration=20.0, rate=20.0, fraction=0.6)
    rows = zip(plan.t.tolist(), plan.v.tolist(), plan.omega.tolist(), strict=True)
    (tmp_path / "plan.csv").write_text("t,v,omega\n" + "".join(f"{t!r},{v!r},{w!r}\n" for t, v, w in rows))
    text = scenario_text(plant="lag", extra="[sensing]\nactuation_delay = 0.1\n", duration=20.0, period=0.05)
    (tmp_path / "scenario.toml").write_text(text)
    assert cli("run", tmp_path / "scenario.toml", "--out", tmp_path / "run")[0] == 0
    export_run(tmp_path / "run", tmp_path / "log.mcap")
    fit = identify_lag(read_speed_log(tmp_path / "log.mcap"))
    theta = np.array(PIONEER_3DX_WITH_LASER)
    assert fit.delay == pytest.approx(0.1, abs=1e-6)  # a continuous parameter now, fitted to the RK4 error
    np.testing.assert_allclose(fit.params, theta, rtol=1e-3)
    assert np.all(fit.std < 1e-6 * np.abs(theta).max())  # no noise: the reported errors are tiny too
    assert min(fit.fit_percent.values()) > 99.99
