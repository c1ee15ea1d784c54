"""Identifying a velocity-commanded base (docs/identification.md): the lag model recovered from synthetic logs of a
known plant within its reported uncertainty, excitation plans within the robot's limits, and logs that cannot
identify anything refused with one line, exit 2, nothing written."""

from __future__ import annotations

import re
from itertools import pairwise

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from scipy.signal import lfilter

from ddtrack.errors import ConfigError
from ddtrack.model.lag import PIONEER_3DX_WITH_LASER
from ddtrack.ros.messages import header, message, planar_pose, twist, typestore
from ddtrack.sysid import (
    LAG,
    SpeedLog,
    body_log,
    excitation_plan,
    identify_body,
    identify_lag,
    lag_log,
    plant_keys,
    torque_plan,
)
from ddtrack.sysid.body import equivalent_robot, plant_std
from ddtrack.sysid.fit import propagated
from ddtrack.sysid.output_error import WINDOW, cut
from ddtrack.sysid.schedule import held_at

THETA = np.array(PIONEER_3DX_WITH_LASER)
PLAN = excitation_plan(max_speed=1.2, max_yaw_rate=5.24, duration=60.0, rate=20.0, seed=0)
SEEDS = range(20)


def z_scores(**conditions) -> tuple[np.ndarray, list]:
    fits = [identify_lag(lag_log(THETA, PLAN, seed=seed, **conditions), max_delay=0.15) for seed in SEEDS]
    return np.array([(fit.params - THETA) / fit.std for fit in fits]), fits


@pytest.mark.parametrize(
    ("conditions", "delay", "interval_mean"),
    [
        ({"noise": (0.005, 0.01), "delay": 0.1}, 0.1, False),
        ({"noise": (0.002, 0.005), "encoder_counts": 2000, "delay": 0.05}, 0.05, True),
    ],
    ids=["noise-and-latency", "encoders-noise-and-latency"],
)
def test_the_lag_model_is_recovered_within_its_reported_uncertainty(conditions, delay, interval_mean):
    z, fits = z_scores(**conditions)
    covered = np.abs(z) <= 1.96
    # 120 intervals at a nominal 95 %: below 85 % has probability < 1e-4 if the intervals are right
    assert covered.mean() >= 0.85, np.round(z, 2)
    assert np.all(np.abs(z) < 5), np.round(z, 2)  # and no estimate is far outside its interval
    # the delay is fitted, continuous, and its interval holds the truth; at equal rates a reading as instants mimics
    # odometry's interval means h/2 later (to second order) and fits as well, which the fit says in a note
    step = float(np.median(np.diff(PLAN.t)))
    right = [fit for fit in fits if fit.interval_mean is interval_mean]
    delay_z = np.array([(fit.delay - delay) / fit.delay_std for fit in right])
    assert len(right) >= 5 and np.all(np.abs(delay_z) < 4), np.round(delay_z, 2)
    assert (np.abs(delay_z) <= 1.96).mean() >= 0.8, np.round(delay_z, 2)
    shift = step / 2 if interval_mean else -step / 2
    for fit in (fit for fit in fits if fit.interval_mean is not interval_mean):
        assert "cannot tell them apart" in " ".join(fit.notes) and abs(fit.delay - delay - shift) < step / 4
    assert min(min(fit.fit_percent.values()) for fit in fits) > 90.0


def test_the_output_error_simulates_each_window_of_the_fitted_record_from_its_own_start():
    plan = excitation_plan(max_speed=1.2, max_yaw_rate=5.24, duration=30.0, rate=20.0, seed=0)
    log = lag_log(THETA, plan, seed=0, noise=(0.005, 0.01))
    windows = cut(log.t[:450], log.speed[:450], WINDOW)
    assert WINDOW == 2.0 and windows.mask.shape == (12, 40) and windows.mask.sum() == 450  # the last: 10 + padding
    assert np.array_equal(windows.speed[:, 0], log.speed[:450:40])  # where each window starts from
    fit, whole = identify_lag(log, max_delay=0.0), identify_lag(log, max_delay=0.0, window=np.inf)
    assert fit.samples == (450, 150) and fit.windows == 12 and whole.windows == 1
    assert np.all(fit.std > whole.std)  # the windows' starts are fitted too: they take some of the log's information


def test_a_log_that_never_turns_while_driving_says_the_coupling_terms_are_not_separated():
    plan = excitation_plan(max_speed=1.2, max_yaw_rate=5.24, duration=30.0, rate=20.0, seed=1)
    arcs = plan.t >= 0.5 * plan.t[-1]  # the arcs phase: keep the turns but stop the robot while it turns
    stopped = type(plan)(t=plan.t, v=np.where(arcs, 0.0, plan.v), omega=plan.omega)
    fit = identify_lag(lag_log(THETA, stopped, seed=0, noise=(0.005, 0.01)))
    named = " ".join(fit.notes)
    assert "theta_5" in named and "theta_1" not in named and "theta_2" not in named


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda log: SpeedLog(log.t[:50], log.command[:50], log.speed[:50], "log"), "has 50 samples"),
        (lambda log: SpeedLog(log.t, log.command * [1, 0], log.speed, "log"), "omega command never changes"),
        (lambda log: SpeedLog(log.t[::-1], log.command, log.speed, "log"), "sample 1: time does not increase"),
        (lambda log: SpeedLog(log.t, log.command, log.speed * np.nan, "log"), "sample 0: v is nan, not a number"),
    ],
)
def test_logs_that_cannot_identify_are_refused(change, message):
    log = lag_log(THETA, PLAN, seed=0, noise=(0.005, 0.01))
    with pytest.raises(ConfigError, match=message):
        identify_lag(change(log))


def test_the_plan_drives_then_turns_then_arcs_within_the_limits():
    plan = excitation_plan(max_speed=0.22, max_yaw_rate=2.84, duration=40.0, rate=20.0, seed=3, fraction=0.5)
    assert np.all(np.abs(plan.v) <= 0.5 * 0.22 + 1e-15) and np.all(np.abs(plan.omega) <= 0.5 * 2.84 + 1e-15)
    quarter = (plan.t[-1] - 2.0) / 4
    first, second = plan.t < 1.0 + quarter, (plan.t >= 1.0 + quarter) & (plan.t < 1.0 + 2 * quarter)
    assert np.all(plan.omega[first] == 0) and np.ptp(plan.v[first]) > 0.05
    assert np.all(plan.v[second] == 0) and np.ptp(plan.omega[second]) > 0.5
    arcs = plan.t >= 1.0 + 2 * quarter
    assert np.mean((plan.v[arcs] != 0) & (plan.omega[arcs] != 0)) > 0.8
    again = excitation_plan(max_speed=0.22, max_yaw_rate=2.84, duration=40.0, rate=20.0, seed=3, fraction=0.5)
    assert np.array_equal(again.v, plan.v) and np.array_equal(again.omega, plan.omega)


def write_log_bag(path, log, *, cmd_topic="/cmd_vel", odom_clock_behind=0.0) -> None:
    """A bag of what a base records: the commands on ``cmd_topic`` as sent (stamped on receipt), its odometry's
    twist at each sample, its header stamped by the robot's clock, ``odom_clock_behind`` [s] behind the recorder's."""
    store = typestore()
    origin = 1_700_000_000_000_000_000
    sent_t, sent = log.inputs()
    with Writer(path, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        commands = writer.add_connection(cmd_topic, "geometry_msgs/msg/Twist", typestore=store)
        odometry = writer.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=store)
        messages = [
            (origin + round(t * 1e9), commands, twist(*u), "geometry_msgs/msg/Twist")
            for t, u in zip(sent_t, sent, strict=True)
        ]
        for t, (v, w) in zip(log.t, log.speed, strict=True):
            ns = origin + round(t * 1e9)
            odom = message(
                "nav_msgs/msg/Odometry",
                header=header(ns - round(odom_clock_behind * 1e9), "odom"),
                child_frame_id="base_link",
                pose=message(
                    "geometry_msgs/msg/PoseWithCovariance", pose=planar_pose(0, 0, 0), covariance=np.zeros(36)
                ),
                twist=message("geometry_msgs/msg/TwistWithCovariance", twist=twist(v, w), covariance=np.zeros(36)),
            )
            messages.append((ns + 1, odometry, odom, "nav_msgs/msg/Odometry"))
        for ns, connection, msg, kind in sorted(messages, key=lambda m: m[0]):
            writer.write(connection, ns, store.serialize_cdr(msg, kind))


def test_a_bag_whose_odometry_runs_on_another_clock_and_rate_is_identified_on_the_commands_clock(tmp_path, cli):
    log = lag_log(THETA, PLAN, seed=2, noise=(0.005, 0.01), delay=0.06, odometry_rate=30.0)
    bag = tmp_path / "log"
    write_log_bag(bag, log, odom_clock_behind=0.5)  # the robot's clock half a second behind the recorder's
    code, printed, _ = cli("identify", bag, "--max-delay", "0.15")
    assert code == 0 and "/odom's stamps run 0.5 s behind /cmd_vel's clock" in printed, printed
    found = re.search(r"command delay (\S+) \+- (\S+) s", printed)
    assert found and abs(float(found[1]) - 0.06) < float(found[2]), printed  # within its 95 % interval
    theta = [float(x) for x in re.search(r"lag = \[(.*)\]", printed)[1].split(",")]
    main = [0, 1, 3, 5]  # the inertias and dampings (the coupling terms are ~70 % uncertain on any 60 s log)
    assert np.allclose(np.array(theta)[main], THETA[main], rtol=0.01), theta


def test_speeds_that_answer_commands_before_they_were_sent_are_refused_as_clocks_apart():
    log = lag_log(THETA, PLAN, seed=0, noise=(0.005, 0.01), delay=0.06, odometry_rate=30.0)
    late = SpeedLog(log.t, log.command, log.speed, "log", sent_t=log.sent_t + 0.5, sent=log.sent)
    with pytest.raises(ConfigError, match="clocks are apart") as refused:
        identify_lag(late)
    assert "record both topics on one clock" in refused.value.suggestion


def test_identify_a_bag_writes_a_plant_that_a_scenario_runs(tmp_path, cli):
    from ddtrack.scenario import load_scenario

    log = lag_log(THETA, PLAN, seed=4, noise=(0.005, 0.01), delay=0.1)
    bag = tmp_path / "log"
    write_log_bag(bag, log)
    out = tmp_path / "pioneer.toml"
    code, printed, _ = cli("identify", bag, "--out", out)
    assert code == 0 and f"wrote {out}" in printed
    found = re.search(r"command delay (\S+) \+- (\S+) s", printed)
    assert found and abs(float(found[1]) - 0.1) < float(found[2]), printed  # the truth within the 95 % interval
    fragment = out.read_text()
    written = re.search(r"\[sensing\]\nactuation_delay = (\S+)  # \+- \S+ s \(95 %\), fitted\n", fragment)
    assert '[plant]\nmodel = "lag"\nlag = [' in fragment and written and written[1] == found[1], fragment
    scenario = tmp_path / "scenario.toml"
    scenario.write_text(
        'name = "identified"\n[simulation]\nduration = 2.0\ncontrol_period = 0.05\nmetric_window = [0.0, 2.0]\n'
        + fragment
        + '[trajectory]\nkind = "line"\nspeed = 0.3\n[controller]\nkind = "kinematic_backstepping"\n'
    )
    spec = load_scenario(scenario)
    assert np.allclose(spec.plant.lag, THETA, rtol=0.05, atol=0.01)
    code, _, err = cli("identify", bag, "--cmd-topic", "/cmd_vl")
    assert code == 2 and "did you mean '/cmd_vel'?" in err


def test_identify_refuses_a_table_without_the_columns_and_writes_nothing(tmp_path, cli):
    table = tmp_path / "log.csv"
    table.write_text("t,v,omega\n" + "".join(f"{k * 0.05},0,0\n" for k in range(100)))
    out = tmp_path / "fit.toml"
    code, _, err = cli("identify", table, "--out", out)
    assert code == 2 and "lacks the columns v_cmd, omega_cmd" in err and not out.exists()


def test_every_error_on_a_log_names_its_line_or_message(tmp_path, cli):
    """A table's bad cell, short row, missing value or step back in time is named by its line (a CSV) or row (a
    Parquet table); a bag's by the messages it came from; exit 2, nothing written."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    log = lag_log(THETA, PLAN, seed=0, noise=(0.005, 0.01))
    lines = ["# a comment line", "t [s],v_cmd,omega_cmd,v,omega"]
    lines += [
        ",".join(repr(float(x)) for x in (t, *c, *m)) for t, c, m in zip(log.t, log.command, log.speed, strict=True)
    ]
    out = tmp_path / "fit.toml"
    cells = lines[12].split(",")  # line 13 of the file, the 11th sample (a comment and the header before it)
    cases = {
        "abc": (",".join([*cells[:4], "abc"]), "line 13, column omega: 'abc' is not a number"),
        "short": (",".join(cells[:3]), "line 13: 3 cells under a header of 5"),
        "nan": (",".join([*cells[:3], "nan", cells[4]]), "line 13: v is nan, not a number"),
        "back": (",".join(["0.01", *cells[1:]]), "line 13: time does not increase (t = 0.01 s after"),
    }
    for name, (row, expected) in cases.items():
        table = tmp_path / f"{name}.csv"
        table.write_text("\n".join([*lines[:12], row, *lines[13:]]) + "\n")
        code, _, err = cli("identify", table, "--out", out)
        assert code == 2 and expected in err and not out.exists(), (name, err)
    columns = {"t": log.t, "v_cmd": log.command[:, 0], "omega_cmd": log.command[:, 1], "v": log.speed[:, 0]}
    speeds = log.speed[:, 1].copy()
    speeds[6] = np.inf
    pq.write_table(pa.table(columns | {"omega": speeds}), tmp_path / "log.parquet")
    code, _, err = cli("identify", tmp_path / "log.parquet", "--out", out)
    assert code == 2 and "row 7: omega is inf, not a number" in err
    broken = SpeedLog(log.t, log.command.copy(), log.speed, "log")
    broken.command[4, 0] = np.nan
    write_log_bag(tmp_path / "bag", broken)
    code, _, err = cli("identify", tmp_path / "bag", "--out", out)
    assert code == 2 and "/odom message 5 (stamp 1700000000" in err and "under /cmd_vel message 5" in err, err
    assert "the v command is nan, not a number" in err


def test_excite_writes_a_csv_and_a_bag_of_timed_commands(tmp_path, cli):
    from rosbags.highlevel import AnyReader

    csv_out, bag_out = tmp_path / "plan.csv", tmp_path / "plan.mcap"
    code, printed, _ = cli("excite", "--preset", "turtlebot3_burger", "--duration", "20", "--out", csv_out)
    assert code == 0 and "clear that much floor" in printed
    rows = np.loadtxt(csv_out, delimiter=",", skiprows=1)
    assert rows.shape == (400, 3) and np.max(np.abs(rows[:, 1])) <= 0.6 * 0.22 + 1e-12
    assert (
        cli("excite", "--preset", "turtlebot3_burger", "--duration", "20", "--out", bag_out, "--start", "1e9")[0] == 0
    )
    with AnyReader([bag_out], default_typestore=typestore()) as reader:
        stamps = [t for _, t, _ in reader.messages()]
    assert len(stamps) == 400 and stamps[1] - stamps[0] == 50_000_000
    code, _, err = cli("excite", "--preset", "turtlebot3_burger", "--out", csv_out)
    assert code == 2 and err.startswith(f"error: --out: '{csv_out}' exists")  # replaced only with --overwrite
    code, _, err = cli("excite", "--preset", "turtlebot3_burgr", "--out", tmp_path / "x.csv")
    assert code == 2 and "did you mean 'turtlebot3_burger'?" in err and not (tmp_path / "x.csv").exists()


# --- the body model of a torque-driven robot ------------------------------------------------------------------

RADIUS, HALF = 0.05, 0.25
#: the paper's true plant with geared wheels: M_v = m + 2 J_w / R^2, m d, M_w = I_C + m d^2 + 2 J_w L^2 / R^2,
#: b_w, tau_c
M, D, I_C, J_W = 12.0, 0.08, 0.7, 0.002
BODY = np.array([M + 2 * J_W / RADIUS**2, M * D, I_C + M * D**2 + 2 * J_W * HALF**2 / RADIUS**2, 0.005, 0.05])


def test_the_body_model_is_recovered_within_its_reported_uncertainty():
    t, torque = torque_plan(max_torque=1.5, duration=16.0, rate=50.0, seed=0)
    z, z_keys, equivalent = [], [], equivalent_robot(BODY)
    for seed in SEEDS:
        log = body_log(
            BODY, t, torque, wheel_radius=RADIUS, half_axle=HALF, noise=(0.002, 0.005), delay=0.02, seed=seed
        )
        fit = identify_body(log, wheel_radius=RADIUS, half_axle=HALF, max_delay=0.02)
        assert 0.02 - 4 * fit.delay_std <= fit.delay <= 0.02 and not fit.interval_mean  # max_delay bounds it
        z.append((fit.params - BODY) / fit.std)
        keys, std = plant_keys(fit), plant_std(fit)  # the fragment's keys, their errors by the delta method
        z_keys.append([(keys[k] - equivalent[k]) / std[k] for k in ("inertia", "com_offset")])
    covered = np.abs(np.array(z)) <= 1.96
    assert covered.mean() >= 0.85 and np.all(np.abs(np.array(z)) < 5), np.round(np.array(z), 2)  # 100 intervals
    assert (np.abs(np.array(z_keys)) <= 1.96).mean() >= 0.8, np.round(np.array(z_keys), 2)  # 40 intervals


def test_the_delta_method_gives_a_ratios_error():
    """var(a / b) = (sigma_a / b)^2 + (a sigma_b / b^2)^2 - 2 a cov_ab / b^3, to first order."""
    covariance = np.array([[0.04, 0.01], [0.01, 0.09]])
    std = propagated(lambda x: {"ratio": x[0] / x[1]}, np.array([2.0, 4.0]), covariance)
    exact = 0.04 / 16 + (2 * 0.3 / 16) ** 2 - 2 * 2 * 0.01 / 64
    assert std["ratio"] == pytest.approx(np.sqrt(exact), rel=1e-6)


def test_windows_keep_the_intervals_more_honest_under_a_slowly_varying_torque_the_model_lacks():
    """A torque the body model lacks, 0.3 mN m per wheel varying over about 3 s (a floor not quite level), is far
    below the plan's torques, but the body's speeds forget it only over M_v R^2 / (2 b_w) = 3.4 s: simulated over
    the whole record, its effect accumulates into residuals correlated for seconds, which the whole-record fit
    reads as signal (its intervals hold the truth about half the time). Each 2 s window restarts from its own
    speeds, so the disturbance acts over 2 s at most (about three quarters hold it: inside a window it still
    acts)."""
    t, torque = torque_plan(max_torque=1.5, duration=16.0, rate=50.0, seed=0)
    keep = np.exp(-(t[1] - t[0]) / 3.0)  # an Ornstein-Uhlenbeck torque, correlated over 3 s
    z = {WINDOW: [], np.inf: []}
    for seed in range(10):
        white = np.random.default_rng(seed).normal(size=(t.size, 2))
        slope = 3e-4 * np.sqrt(1 - keep**2) * lfilter([1.0], [1.0, -keep], white, axis=0)  # std 0.3 mN m
        log = body_log(BODY, t, torque + slope, wheel_radius=RADIUS, half_axle=HALF, noise=(0.002, 0.005), seed=seed)
        logged = SpeedLog(t, torque, log.speed, "a floor not quite level")  # the torques as commanded
        for window, scores in z.items():
            fit = identify_body(logged, wheel_radius=RADIUS, half_axle=HALF, max_delay=0.0, window=window)
            scores.append((fit.params - BODY) / fit.std)
    covered = {window: float(np.mean(np.abs(scores) <= 1.96)) for window, scores in z.items()}
    assert covered[np.inf] < 0.65 and covered[WINDOW] > covered[np.inf] + 0.15, covered  # 50 intervals each


def test_ddtrack_identifies_its_own_torque_plant_from_a_bag_of_a_closed_loop_run(tmp_path, cli):
    """Backstepping drives the paper's true plant on a figure eight; the run, exported as a bag (/joint_states
    efforts, /odom), gives back the plant's mass, centre of mass, inertia and friction."""
    scenario = tmp_path / "truth.toml"
    scenario.write_text(
        'name = "truth"\n[simulation]\nduration = 12.0\nmetric_window = [0.0, 12.0]\n[robot]\npreset = "paper"\n'
        f"[plant]\nmass = {M}\ninertia = {I_C}\ncom_offset = {D}\nviscous_friction = 0.005\ncoulomb_friction = 0.05\n"
        '[trajectory]\nkind = "figure_eight"\nsize = 2.0\nperiod = 20.0\n[initial]\npose = [0.0, 0.0, 0.0]\n'
        '[controller]\nkind = "backstepping"\n'
    )
    assert cli("run", scenario, "--out", tmp_path / "run")[0] == 0
    assert cli("export", tmp_path / "run", "--to", tmp_path / "run.mcap")[0] == 0
    out = tmp_path / "body.toml"
    code, printed, _ = cli(
        "identify", tmp_path / "run.mcap", "--model", "body", "--preset", "paper", "--max-delay", "0", "--out", out
    )
    assert code == 0 and "spin inertia is folded into mass and inertia" in printed
    import tomllib

    truth = {"mass": M, "com_offset": D, "inertia": I_C, "viscous_friction": 0.005, "coulomb_friction": 0.05}
    words = ("identify", tmp_path / "run.mcap", "--model", "body", "--preset", "paper", "--max-delay", "0")
    joints = tmp_path / "joints.toml"  # the speeds measured by the wheel joints instead of the odometry
    assert cli(*words, "--speeds", "joints", "--out", joints)[0] == 0
    for fragment in (out, joints):
        plant = tomllib.loads(fragment.read_text())["plant"]
        for key, value in truth.items():
            assert plant[key] == pytest.approx(value, rel=1e-3), (fragment.name, key)
    code, _, err = cli("identify", tmp_path / "run.mcap", "--speeds", "joints")  # the lag model: no geometry
    assert code == 2 and "wheel-joint speeds, need the robot's geometry" in err
    code, _, err = cli("identify", tmp_path / "run.mcap", "--model", "body")
    assert code == 2 and "--preset, or --wheel-radius and --half-axle" in err


def test_two_readings_that_fit_alike_are_named_with_each_ones_delay():
    from ddtrack.sysid.fit import ambiguous_reading
    from ddtrack.sysid.output_error import OutputError

    def fit(cost, delay):
        return OutputError(np.ones(2), np.ones(2), cost, np.ones(2), 1, 4, np.eye(2), delay, 1e-4)

    (note,) = ambiguous_reading({False: fit(1.00, 0.0753), True: fit(1.01, 0.0501)})
    assert "instants (delay 0.0753 s)" in note and "interval (delay 0.0501 s)" in note
    assert ambiguous_reading({False: fit(1.00, 0.0753), True: fit(1.05, 0.0501)}) == ()  # told apart: no note
    assert ambiguous_reading({False: fit(np.inf, 0.0), True: fit(1.0, 0.05)}) == ()  # one failed: nothing to compare


def test_a_fast_log_is_screened_coarsely_then_on_half_samples_and_finds_the_fine_grids_delay(monkeypatch):
    from ddtrack.sysid import fit as fitting

    plan = excitation_plan(max_speed=1.2, max_yaw_rate=5.24, duration=20.0, rate=200.0, seed=0)
    log = lag_log(THETA, plan, seed=0, noise=(0.005, 0.01), delay=0.0625)  # 12.5 samples
    sent_t, sent = log.inputs()
    record = fitting.Record(log.t, log.speed, sent_t, sent, fitting.slots_for(log.t, sent_t))
    fine = fitting.delay_grid(0.5 * float(np.median(np.diff(log.t))), 0.15)
    costs = [fitting.equation_error(LAG, log.t, held_at(log.t, sent_t, sent, d), log.speed, cost=True) for d in fine]
    calls = []
    counted = fitting.equation_error
    monkeypatch.setattr(fitting, "equation_error", lambda *a, **k: calls.append(1) or counted(*a, **k))
    assert fitting.screened_delay(LAG, record, 0.15, "log") == fine[int(np.argmin(costs))]
    assert abs(fine[int(np.argmin(costs))] - 0.0625) <= fine[1] - fine[0]
    assert len(calls) < len(fine) / 3  # a 10 ms grid, then the half samples around its minima


def test_a_rejected_step_keeps_its_jacobian_and_both_readings_share_one_compiled_fit(monkeypatch):
    from ddtrack.sysid import output_error as oe

    plan = excitation_plan(max_speed=1.2, max_yaw_rate=5.24, duration=30.0, rate=20.0, seed=0)
    log = lag_log(THETA, plan, seed=3, noise=(0.005, 0.01), delay=0.1)  # whole samples: a corner in the delay
    events = []  # ("J" or "R", the parameters and delay)
    jacobians, simulate = oe._jacobians, oe._residuals
    record = lambda kind, a: events.append((kind, np.asarray(a[4]).tobytes()))  # noqa: E731
    monkeypatch.setattr(oe, "_jacobians", lambda *a: record("J", a) or jacobians(*a))
    monkeypatch.setattr(oe, "_residuals", lambda *a: record("R", a) or simulate(*a))
    jacobians.jitted.clear_cache()
    simulate.jitted.clear_cache()
    fit = identify_lag(log, max_delay=0.15)
    linearised = {point for kind, point in events if kind == "J"}
    assert sum(kind == "R" and point not in linearised for kind, point in events) >= 3  # steps were rejected ...
    # ... and none re-linearised where it stood, nor did re-weighting the channels or the covariance at the end
    for kind in "JR":
        points = [point for k, point in events if k == kind]
        assert all(a != b for a, b in pairwise(points)), f"{kind} taken again where it stood"
    assert jacobians.jitted._cache_size() == simulate.jitted._cache_size() == 1  # instants and interval means: one
    assert abs(fit.delay - 0.1) < 2 * fit.delay_std + 1e-9


def test_the_fit_stops_within_a_hundredth_of_a_standard_error_of_where_a_stricter_one_stops(monkeypatch):
    from ddtrack.sysid import output_error as oe

    plan = excitation_plan(max_speed=1.2, max_yaw_rate=5.24, duration=30.0, rate=20.0, seed=1)
    log = lag_log(THETA, plan, seed=4, noise=(0.005, 0.01), delay=0.07)
    fit = identify_lag(log, max_delay=0.15)
    monkeypatch.setattr(oe, "STILL", 1e-6)
    strict = identify_lag(log, max_delay=0.15)
    assert fit.interval_mean is strict.interval_mean
    assert np.all(np.abs(fit.params - strict.params) < 0.05 * strict.std), (fit.params - strict.params) / strict.std
    assert abs(fit.delay - strict.delay) < 0.05 * strict.delay_std
    assert np.allclose(fit.std, strict.std, rtol=0.02)
