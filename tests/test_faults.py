"""Numerical faults end as a status, never as an exception or a NaN in JSON (issue 7, item 2).

Each fault kind goes through the real ``ddtrack run``: exit code 1, one line on stderr naming the status, the time
and the remedy (``sim.REMEDIES``); ``metrics.json`` is strict JSON with the status, the failure time and null
statistics; ``timeseries.parquet`` holds the rows up to and including the failing period, and nothing else.
Then a Monte Carlo batch and a sweep holding a failing run carry on with the others.
"""

from __future__ import annotations

import dataclasses
import json
import math
import shutil
from typing import Any

import jax.numpy as jnp
import numpy as np
import pyarrow.parquet as pq
import pytest
from conftest import SCENARIOS

import ddtrack
import ddtrack.runner
from ddtrack import pytree_dataclass
from ddtrack.metrics import summarize
from ddtrack.sim import REMEDIES

SHORT = ["simulation.duration=2", "simulation.metric_window=[0, 2]"]
UNSTABLE_INNER_LOOP = "the inner loop (computed_torque) is unstable with its torques held over"
# the columns that hold x_k, ref_k and e_p(x_k, ref_k): finite on every row, the failing one included (the state is
# frozen at the last finite value); the commands and logs of the failing row may be what made it fail
STATE_COLUMNS = (
    "t",
    "x",
    "y",
    "theta",
    "v",
    "omega",
    "x_ref",
    "y_ref",
    "theta_ref",
    "v_ref",
    "omega_ref",
    "e_x",
    "e_y",
    "e_theta",
    "e_tr",
)
STATISTICS = ("e_tr_mean", "e_tr_rms", "e_tr_max", "e_tr_final", "settling_time", "effort", "saturation_fraction")


def strict_json(text: str) -> Any:
    """json.loads that rejects NaN, Infinity and -Infinity (Python's json accepts them by default)."""

    def reject(constant: str) -> None:
        raise ValueError(f"non-standard JSON constant {constant}")

    return json.loads(text, parse_constant=reject)


def assert_failed_run(out, code: int, stderr: str, status: str, failure_time: float, cause: str = "") -> dict:
    """The checks every failing ``ddtrack run`` must pass; returns the time-series columns. ``cause``: the start of
    the remedy the run names (default: the status's generic one)."""
    assert code == 1, stderr
    line = f"run {status} at t = {failure_time:.2f} s: {cause or REMEDIES[status]}"
    assert len(stderr.strip().splitlines()) == 1 and stderr.startswith(line), (
        stderr
    )  # status, time, remedy; no traceback
    metrics = strict_json((out / "metrics.json").read_text())
    assert metrics["status"] == status
    assert metrics["failure_time"] == pytest.approx(failure_time, abs=1e-12)
    assert all(metrics[name] is None for name in STATISTICS), metrics
    table = pq.read_table(out / "timeseries.parquet")
    columns = {name: np.asarray(values) for name, values in table.to_pydict().items()}
    t = columns["t"]
    # rows 0 .. k: t_k = k T_c up to the failing period, nothing after it
    assert t[-1] == metrics["failure_time"]
    assert np.all(np.diff(t) > 0) and len(t) == round(failure_time / 0.01) + 1
    for name in STATE_COLUMNS:
        assert np.all(np.isfinite(columns[name])), name
    for name, values in columns.items():
        assert np.all(np.isfinite(values[:-1])), name  # every period before the failing one was sound
        if status == "diverged":
            assert np.all(np.isfinite(values)), name  # diverged: too far or too fast, but finite
    assert (out / "figures" / "path.png").stat().st_size > 0
    return columns


def run_cli(cli, tmp_path, *overrides: str, scenario=SCENARIOS / "paper_line.toml"):
    out = tmp_path / "run"
    sets = [a for o in (*SHORT, *overrides) for a in ("--set", o)]
    code, _, stderr = cli("run", scenario, *sets, "--out", out)
    return out, code, stderr


def test_unstable_inner_loop_diverges(tmp_path, cli):
    """K_c = 1000 /s with T_c = 10 ms (K_c T_c = 10 >> 2: the sampled computed-torque loop is unstable) and no torque
    limit to hide it: the speed runs away within a few periods."""
    out, code, stderr = run_cli(cli, tmp_path, "controller.kc=[1000, 1000]", "robot.max_torque=1e6")
    assert_failed_run(out, code, stderr, "diverged", 0.02, UNSTABLE_INNER_LOOP)  # named as the cause


def test_unstable_gains_that_overflow_are_non_finite(tmp_path, cli):
    """K_c = 1e8 /s, no torque limit and no divergence bound to stop it first: the first period overflows."""
    out, code, stderr = run_cli(
        cli, tmp_path, "controller.kc=[1e8, 1e8]", "robot.max_torque=1e300", "simulation.divergence_error=1e300"
    )
    columns = assert_failed_run(out, code, stderr, "non_finite", 0.0, UNSTABLE_INNER_LOOP)
    assert abs(columns["tau_r"][-1]) > 1e6  # the recorded torque is finite, but x_1 under it overflowed


@pytest.mark.slow
def test_control_period_too_long_diverges(tmp_path, cli):
    """T_c = 0.5 s with one RK4 step per period against the 10 m initial error: the zero-order-held loop overshoots
    and grows."""
    out, code, stderr = run_cli(cli, tmp_path, "simulation.control_period=0.5", "simulation.substeps=1")
    assert code == 1 and stderr.startswith("run diverged at t = 1.50 s: "), stderr
    metrics = strict_json((out / "metrics.json").read_text())
    assert metrics["failure_time"] == 1.5 and all(metrics[name] is None for name in STATISTICS)
    t = pq.read_table(out / "timeseries.parquet").column("t").to_numpy()
    np.testing.assert_array_equal(t, [0.0, 0.5, 1.0, 1.5])  # rows up to the failing period


def test_initial_pose_beyond_the_divergence_bound_diverges_at_once(tmp_path, cli):
    # 70.7 m off the line y = x, beyond a fixed 50 m bound (the default bound scales with the initial error)
    out, code, stderr = run_cli(cli, tmp_path, "initial.pose=[0, 100, 0]", "simulation.divergence_error=50")
    columns = assert_failed_run(out, code, stderr, "diverged", 0.0)
    assert len(columns["t"]) == 1 and columns["y"][0] == 100.0


@pytree_dataclass
class NaNAfter:
    """The scenario's controller, whose torques turn NaN once t > ``start`` [s] (a controller bug)."""

    inner: Any
    start: float = 0.5

    def init(self, x0, ref0, key):
        return self.inner.init(x0, ref0, key)

    def step(self, t, y, ref, memory):
        torque, memory, logs = self.inner.step(t, y, ref, memory)
        return jnp.where(t > self.start, jnp.nan, torque), memory, logs


@pytest.mark.slow
def test_controller_returning_nan_is_non_finite(tmp_path, cli, monkeypatch):
    """A scenario cannot name a broken controller: ``ddtrack run`` is run in-process with ``runner.prepare``
    wrapping the scenario's controller, so the CLI's own writing and reporting are what is tested."""
    prepare = ddtrack.runner.prepare

    def broken(*args, **kwargs):
        setup, draws = prepare(*args, **kwargs)
        return dataclasses.replace(setup, controller=NaNAfter(setup.controller)), draws

    monkeypatch.setattr(ddtrack.runner, "prepare", broken)
    out, code, stderr = run_cli(cli, tmp_path)
    columns = assert_failed_run(out, code, stderr, "non_finite", 0.51)  # t_51 = 0.51 s is the first t > 0.5 s
    assert np.isnan(columns["tau_r"][-1]) and np.isnan(columns["tau_l"][-1])
    assert len(columns["t"]) == 52


# --- a batch and a sweep carry on -------------------------------------------------------------------


@pytest.mark.slow
def test_mc_carries_on_past_a_diverged_run(tmp_path, cli):
    """``ddtrack mc`` where seed 1 diverges (a 5 cm divergence bound, as in tests/test_batch.py): the other runs are
    ok and their metrics equal their single runs; the diverged one has null metrics; the files are strict JSON."""
    overrides = [*SHORT, "simulation.divergence_error=0.05"]
    out = tmp_path / "mc"
    code, _stdout, stderr = cli(
        "mc",
        SCENARIOS / "figure_eight.toml",
        "-n",
        "3",
        "--vary",
        "mass=uniform:0.2",
        *[a for o in overrides for a in ("--set", o)],
        "--chunk",
        "3",
        "--out",
        out,
    )
    assert code == 1 and "1 of 3 runs diverged" in stderr, stderr  # results written; exit 1 as for run and sweep
    rows = pq.read_table(out / "runs.parquet").to_pylist()
    assert [r["status"] for r in rows] == ["ok", "diverged", "ok"]
    assert all(rows[1][name] is None for name in STATISTICS)
    summary = strict_json((out / "summary.json").read_text())
    assert summary["controllers"]["backstepping"]["failures"] == 1
    assert summary["controllers"]["backstepping"]["e_tr_mean"]["n"] == 2
    scenario = ddtrack.load_scenario(
        SCENARIOS / "figure_eight.toml", overrides=[*overrides, 'randomize.mass={distribution="uniform", relative=0.2}']
    )
    sim = scenario.simulation
    for seed in (0, 2):
        single = ddtrack.run(scenario, seed=seed)
        expected = summarize(
            ddtrack.timeseries(single),
            status=single.status_name,
            window=sim.window,
            control_period=sim.control_period,
            settling_threshold=sim.settling_threshold,
        )
        for name in STATISTICS:
            # vmapped vs single: XLA may reassociate a sum (tests/test_determinism.py measures the difference)
            assert rows[seed][name] == pytest.approx(expected[name], rel=0, abs=1e-12), name


@pytest.mark.slow
def test_sweep_carries_on_past_an_unstable_value(tmp_path, cli):
    """A grid over K_c with an unstable value (1000 /s, no torque limit): its runs are recorded as diverged with
    null metrics and the sweep exits 1; the stable configuration's runs are ok and equal to direct runs."""
    shutil.copy(SCENARIOS / "figure_eight.toml", tmp_path / "figure_eight.toml")
    path = tmp_path / "sweep.toml"
    path.write_text(
        'scenario = "figure_eight.toml"\ncontrollers = ["backstepping"]\nseeds = 2\nchunk = 2\n'
        '[set]\n"simulation.duration" = 2.0\n"simulation.metric_window" = [0.0, 2.0]\n'
        '"robot.max_torque" = 1e6\n[grid]\n"controller.kc" = [[10.0, 10.0], [1000.0, 1000.0]]\n'
    )
    out = tmp_path / "out"
    code, stdout, stderr = cli("sweep", path, "--out", out, "--workers", "1")
    assert code == 1, stderr
    assert "4 runs (2 configurations x 2 seeds)" in stdout and "2 diverged or non-finite, 0 errors" in stdout
    records = [strict_json(p.read_text()) for p in sorted((out / "records").glob("*.json"))]
    by_kc = {}
    for record in records:
        by_kc.setdefault(tuple(record["configuration"]["overrides"]["controller.kc"]), []).append(record)
    assert sorted(r["status"] for r in by_kc[(1000.0, 1000.0)]) == ["diverged", "diverged"]
    for record in by_kc[(1000.0, 1000.0)]:
        assert record["metrics"]["failure_time"] is not None
        assert all(record["metrics"][name] is None for name in STATISTICS)
    scenario = ddtrack.load_scenario(
        SCENARIOS / "figure_eight.toml",
        overrides=[
            "simulation.duration=2",
            "simulation.metric_window=[0, 2]",
            "robot.max_torque=1e6",
            "controller.kc=[10, 10]",
        ],
    )
    direct = {row["seed"]: row for row in ddtrack.studies.batches.monte_carlo(scenario, [0, 1], chunk_size=2)}
    assert sorted(r["seed"] for r in by_kc[(10.0, 10.0)]) == [0, 1]
    for record in by_kc[(10.0, 10.0)]:
        assert record["status"] == "ok"
        for name in STATISTICS:
            value = direct[record["seed"]][name]
            expected = None if isinstance(value, float) and not math.isfinite(value) else value
            assert record["metrics"][name] == expected, name  # the same chunk shape: the same bits
    table = pq.read_table(out / "results.parquet")
    assert sorted(table.column("status").to_pylist()) == ["diverged", "diverged", "ok", "ok"]


def test_the_default_divergence_bound_scales_with_the_scenario():
    # 3 (initial error + the reference's extent + 2 L): the paper's line (10 m from the reference point at t = 0,
    # 20 m long, L = 0.25 m) and a Burger's 0.5 m circle, which a fixed 50 m bound would have let wander 50 m
    line = ddtrack.load_scenario(SCENARIOS / "paper_line.toml")
    assert line.divergence_distance() == pytest.approx(3 * (10.0 + 20.0 + 0.5), rel=1e-6)
    burger = ddtrack.load_scenario(SCENARIOS / "burger_sized_20hz.toml")
    assert 2.0 < burger.divergence_distance() < 6.0
    fixed = ddtrack.load_scenario(SCENARIOS / "paper_line.toml", overrides=["simulation.divergence_error=50"])
    assert fixed.divergence_distance() == 50.0
