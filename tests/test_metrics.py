"""Metrics (SPEC 4.4, 6.26, 6.27): statistics on synthetic arrays with hand-computed answers, summaries
of failed runs, and zero steady error without uncertainty."""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

import ddtrack
from ddtrack.controllers import Backstepping, Cascade, ComputedTorque
from ddtrack.metrics import (
    effort,
    improvement,
    lost_path_time,
    pooled_improvement,
    rate_ci,
    saturation_fraction,
    settling_time,
    summarize,
    window_statistics,
)
from ddtrack.model import DynamicPlant, RobotParams
from ddtrack.sim import ClosedLoop, Draws, simulate
from ddtrack.trajectories import Line

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"


# --- item 26 ----------------------------------------------------------------------------------------


def test_improvement_reproduces_the_paper():
    assert round(improvement(0.0547, 0.0216), 2) == 60.51  # 60.5119...
    assert round(improvement(0.0976, 0.0468), 2) == 52.05  # 52.0492 (the paper truncates to 52.04)
    assert improvement(0.0976, 0.0468) == pytest.approx(100 * (0.0976 - 0.0468) / 0.0976, rel=1e-15)


def test_improvement_sign_and_bad_baseline():
    assert improvement(0.1, 0.1) == 0.0
    assert improvement(0.1, 0.15) == pytest.approx(-50.0)  # worse than the baseline: negative
    assert improvement(0.2, 0.0) == 100.0
    for baseline in (0.0, -1.0, math.nan):
        with pytest.raises(ValueError):
            improvement(baseline, 0.01)


# --- window statistics, settling, effort, saturation ------------------------------------------------


def test_pooled_improvement_stays_finite_near_a_zero_baseline():
    # an exact-model cell: both errors near zero; the mean of per-pair ratios would explode, the pooled one does not
    gain = pooled_improvement([1e-12, 0.04, 0.12], [3e-9, 0.01, 0.03])
    assert gain["mean"] == pytest.approx(100 * (1 - (3e-9 + 0.04) / (1e-12 + 0.16)))
    assert gain["ci_low"] < gain["mean"] < gain["ci_high"] and gain["n"] == 3
    assert pooled_improvement([0.1, None], [0.05, 0.02])["missing"] == 1


def test_pooled_improvement_interval_covers_the_true_ratio():
    # delta-method interval of a ratio of means: about 95 % coverage on paired data with a known ratio 0.4
    rng = np.random.default_rng(0)
    covered = 0
    for _ in range(400):
        base = rng.uniform(0.02, 0.1, 40)
        cand = 0.4 * base + rng.normal(0.0, 0.01, 40)
        gain = pooled_improvement(list(base), list(cand))
        covered += gain["ci_low"] <= 60.0 <= gain["ci_high"]
    assert 0.92 <= covered / 400 <= 0.98  # binomial sd at 95 %: 1.1 %


def test_window_statistics_by_hand():
    t = np.arange(10) * 0.1  # 0.30000000000000004 etc.: the window edges need the tolerance
    e = np.array([9.0, 9.0, 9.0, 3.0, 4.0, 0.0, 5.0, 9.0, 9.0, 9.0])
    stats = window_statistics(t, e, (0.3, 0.6))  # samples 3..6: 3, 4, 0, 5
    assert stats["e_tr_mean"] == pytest.approx(3.0, rel=1e-15)
    assert stats["e_tr_rms"] == pytest.approx(math.sqrt((9 + 16 + 0 + 25) / 4), rel=1e-15)
    assert stats["e_tr_max"] == 5.0
    assert stats["e_tr_final"] == 5.0
    whole = window_statistics(t, e, (0.0, 0.9))
    assert whole["e_tr_mean"] == pytest.approx(e.mean(), rel=1e-15) and whole["e_tr_final"] == 9.0


def test_window_statistics_empty_window():
    t = np.arange(10) * 0.1
    stats = window_statistics(t, np.ones(10), (2.0, 3.0))
    assert stats == {"e_tr_mean": None, "e_tr_rms": None, "e_tr_max": None, "e_tr_final": None}


def test_settling_time_by_hand():
    t = np.arange(6) * 0.5
    # last sample at or above 0.1 is index 3 (0.2): settled from index 4 on
    assert settling_time(t, np.array([0.5, 0.3, 0.05, 0.2, 0.05, 0.01]), 0.1) == 2.0
    # a sample equal to the threshold is not "below" it
    assert settling_time(t, np.array([0.5, 0.05, 0.05, 0.1, 0.05, 0.01]), 0.1) == 2.0
    # never settles: the last sample is above
    assert settling_time(t, np.array([0.5, 0.05, 0.05, 0.05, 0.05, 0.2]), 0.1) is None
    # always settled: the first sample time (t need not start at 0)
    assert settling_time(t + 3.0, np.full(6, 0.01), 0.1) == 3.0


def test_effort_by_hand():
    tau_r, tau_l = np.array([1.0, 2.0, 3.0]), np.array([0.0, 1.0, -1.0])
    # (1 + 0) + (4 + 1) + (9 + 1) = 16 N^2 m^2, times T_c = 0.1 s (exact under the ZOH)
    assert effort(tau_r, tau_l, 0.1) == pytest.approx(1.6, rel=1e-15)
    assert effort(np.array([1.0, np.nan]), np.zeros(2), 0.1) is None
    with np.errstate(over="ignore"):
        assert effort(np.array([1e200, 1e200]), np.zeros(2), 0.1) is None  # overflow to inf


def test_saturation_fraction_by_hand():
    assert saturation_fraction(np.array([0.0, 1.0, 1.0, 0.0])) == 0.5
    assert saturation_fraction(np.array([1.0, 0.0, 0.0, 0.0, 0.0])) == 0.2
    assert saturation_fraction(np.zeros(7)) == 0.0


def test_summarize_ok_run_by_hand():
    t = np.arange(6) * 0.5
    columns = {
        "t": t,
        "e_tr": np.array([0.5, 0.3, 0.05, 0.2, 0.05, 0.01]),
        "tau_r": np.ones(6),
        "tau_l": -np.ones(6),
        "saturated": np.array([1.0, 1.0, 0, 0, 0, 0]),
        "kx": np.full(6, 1.0),
        "ky": np.full(6, 55.0),
        "ktheta": np.full(6, 15.0),
    }
    metrics = summarize(columns, status="ok", window=(1.0, 2.5), control_period=0.5, settling_threshold=0.1)
    assert metrics["status"] == "ok" and metrics["window"] == [1.0, 2.5]
    assert metrics["e_tr_mean"] == pytest.approx((0.05 + 0.2 + 0.05 + 0.01) / 4, rel=1e-14)
    assert metrics["e_tr_max"] == 0.2 and metrics["e_tr_final"] == 0.01
    assert metrics["settling_time"] == 2.0
    assert metrics["effort"] == pytest.approx(6.0, rel=1e-15)  # 6 rows * 2 N^2 m^2 * 0.5 s
    assert metrics["saturation_fraction"] == pytest.approx(1 / 3)
    assert metrics["final_gains"] == [1.0, 55.0, 15.0]
    json.dumps(metrics, allow_nan=False)


def test_summarize_failed_run_is_null_and_valid_json():
    """A real failed run (absurd outer gains, clamps off): statistics are null, the failure time is kept."""
    trajectory = Line(start=(0.2, 0.1), heading=0.9, speed=0.5)
    controller = Cascade(
        Backstepping(kx=1e4, ky=1e7, ktheta=1e4, max_velocity=1e9, max_yaw_rate=1e9),
        ComputedTorque(RobotParams(max_torque=1e9)),
    )
    ref0 = trajectory(0.0)
    x0 = jnp.asarray([float(ref0.x), float(ref0.y) + 0.5, float(ref0.theta) + 0.3, 0.0, 0.0])
    n = 2000
    loop = ClosedLoop(DynamicPlant(RobotParams(max_torque=1e9)), controller, trajectory, control_period=0.01)
    result = simulate(loop, x0, Draws.zeros(n), n_steps=n)
    assert result.status_name in ("diverged", "non_finite")
    columns = ddtrack.timeseries(result)
    metrics = summarize(
        columns,
        status=result.status_name,
        window=(0.0, 20.0),
        control_period=0.01,
        settling_threshold=0.1,
        failure_time=result.failure_time,
    )
    for key in ("e_tr_mean", "e_tr_rms", "e_tr_max", "e_tr_final", "settling_time", "effort", "saturation_fraction"):
        assert metrics[key] is None, key
    assert metrics["status"] == result.status_name
    assert metrics["failure_time"] == result.failure_time and metrics["failure_time"] is not None
    text = json.dumps(metrics, allow_nan=False)  # must not raise: no NaN/inf anywhere
    assert json.loads(text)["e_tr_mean"] is None


def test_summarize_failed_run_with_non_finite_columns():
    """Even when the recorded columns hold NaN and inf (the failing row), the summary is valid JSON."""
    columns = {
        "t": np.array([0.0, 0.01]),
        "e_tr": np.array([0.1, np.nan]),
        "tau_r": np.array([1.0, np.inf]),
        "tau_l": np.array([1.0, np.nan]),
        "saturated": np.zeros(2),
        "kx": np.array([1.0, np.nan]),
        "ky": np.array([55.0, 55.0]),
        "ktheta": np.array([15.0, 15.0]),
    }
    metrics = summarize(
        columns, status="non_finite", window=(0.0, 0.01), control_period=0.01, settling_threshold=0.1, failure_time=0.01
    )
    assert metrics["e_tr_mean"] is None and metrics["effort"] is None
    assert metrics["final_gains"] is None  # a NaN gain is not reported as a number
    json.dumps(metrics, allow_nan=False)


# --- item 27 ----------------------------------------------------------------------------------------


def test_no_uncertainty_gives_zero_steady_error():
    """The paper's line with plant = robot, no friction, no disturbance, the paper's clamps and torque
    limit, starting 0.05 m off the line at rest: no clamp ever acts and e_tr -> 0."""
    data = tomllib.loads((SCENARIOS / "paper_line.toml").read_text())
    data.pop("plant")  # every plant key takes the [robot] value
    data.pop("disturbance")  # none
    heading = data["trajectory"]["heading"]
    data["initial"]["pose"] = [-0.05 * math.sin(heading), 0.05 * math.cos(heading), heading]  # 5 cm to the left
    scenario = ddtrack.validate_scenario(data)
    assert scenario.plant_params() == scenario.robot.params()
    assert scenario.plant_params().viscous_friction == 0.0 and scenario.disturbance.kind == "none"
    result = ddtrack.run(scenario)
    columns = ddtrack.timeseries(result)
    assert result.status_name == "ok"
    assert columns["e_tr"][0] == pytest.approx(0.05, rel=1e-12)
    np.testing.assert_array_equal(columns["saturated"], 0.0)  # no clamp acts anywhere
    metrics = summarize(columns, status="ok", window=(20.0, 40.0), control_period=0.01, settling_threshold=0.1)
    # SPEC 6.27: after the transient the error is below 1e-6 (slowest pole Kx = 1: ~5e-2 e^-20 ~ 1e-10)
    assert metrics["e_tr_max"] < 1e-6
    assert metrics["saturation_fraction"] == 0.0
    # within 0.1 m from the start (settled at t = 0); within 1e-6 m after a finite transient, before 20 s
    assert np.max(columns["e_tr"]) < 0.1 and metrics["settling_time"] == 0.0
    assert 5.0 < settling_time(columns["t"], columns["e_tr"], 1e-6) < 20.0


def _coverage(draw, true_mean: float, domain: str, n: int, repeats: int = 1000) -> tuple[float, float, bool]:
    """Coverage of mean_ci in ``domain`` and of the plain t-interval; whether every interval stayed in the domain."""
    from ddtrack.metrics import mean_ci

    rng = np.random.default_rng(0)
    bounds = {"nonnegative": (0.0, np.inf), "fraction": (0.0, 1.0)}[domain]
    covered = covered_t = 0
    inside = True
    for _ in range(repeats):
        values = list(draw(rng, n))
        ours, plain = mean_ci(values, domain=domain), mean_ci(values)
        covered += ours["ci_low"] <= true_mean <= ours["ci_high"]
        covered_t += plain["ci_low"] <= true_mean <= plain["ci_high"]
        inside &= bounds[0] <= ours["ci_low"] <= ours["mean"] <= ours["ci_high"] <= bounds[1]
    return covered / repeats, covered_t / repeats, inside


def test_mean_ci_of_skewed_nonnegative_values_stays_nonnegative_and_covers():
    # lognormal(0, 0.5), n = 10: a skewed error over seeds. The log-scale (delta-method) interval's coverage is
    # ~93 % here (measured over 4000 draws; the t-interval's ~92.5 %); 1000 repeats: binomial sd 0.8 %.
    coverage, coverage_t, inside = _coverage(
        lambda rng, n: rng.lognormal(0.0, 0.5, n), math.exp(0.125), "nonnegative", 10
    )
    assert inside
    assert 0.91 <= coverage <= 0.975 and coverage >= coverage_t - 0.01


def test_mean_ci_of_fractions_stays_in_0_1_and_covers():
    # beta(0.5, 5), n = 10: saturation fractions near 0. The t-interval goes below 0 in ~20 % of draws and
    # covers ~88 %; the logit-scale interval ~93 % (4000 draws), always inside [0, 1]. Binomial sd 0.8 %.
    coverage, coverage_t, inside = _coverage(lambda rng, n: rng.beta(0.5, 5.0, n), 0.5 / 5.5, "fraction", 10)
    assert inside
    assert 0.91 <= coverage <= 0.975 and coverage > coverage_t


def test_mean_ci_on_the_domain_edge_and_one_value():
    from ddtrack.metrics import mean_ci

    none = mean_ci([0.0, 0.0, 0.0], domain="fraction")  # no saturation in any run: exactly [0, 0]
    assert (none["ci_low"], none["ci_high"]) == (0.0, 0.0)
    assert mean_ci([1.0, 1.0], domain="fraction")["ci_high"] == 1.0
    assert mean_ci([0.0, 0.0], domain="nonnegative")["ci_low"] == 0.0
    one = mean_ci([0.2], domain="fraction")
    assert one["mean"] == 0.2 and one["ci_low"] is None
    gain = mean_ci([99.0, 20.0, 97.0], domain="at_most_100")  # improvements in %: never above 100
    assert gain["ci_high"] <= 100.0 and gain["ci_low"] < gain["mean"]
    with pytest.raises(ValueError, match="domain"):
        mean_ci([-0.1, 0.2], domain="nonnegative")


def test_the_leaderboards_saturation_interval_is_a_percentage_inside_0_100():
    # the case: saturation 0.04 [-0.021, 0.1] from a t-interval on fractions
    from ddtrack._format import interval_text
    from ddtrack.metrics import mean_ci

    summary = mean_ci([0.0, 0.0, 0.0, 0.2], domain="fraction")
    text = interval_text(summary, 100.0)
    low, high = (float(v) for v in text.split("[")[1].rstrip("]").split(","))
    assert text.startswith("5.00 [") and 0.0 <= low < 5.0 < high <= 100.0


def test_a_run_has_lost_the_path_only_when_it_stays_beyond_the_bound_for_the_last_fifth():
    t = np.arange(0.0, 10.001, 0.1)  # window [0, 10]: the hold is 2 s
    window = (0.0, 10.0)
    gone = np.where(t >= 6.0, 2.0, 0.1)  # off from 6 s to the end
    assert lost_path_time(t, gone, window, 1.0) == pytest.approx(6.0)
    late = np.where(t >= 8.5, 2.0, 0.1)  # off for the last 1.5 s only: a swing, not yet lost
    assert lost_path_time(t, late, window, 1.0) is None
    back = np.where((t >= 2.0) & (t < 9.0), 2.0, 0.1)  # far off for 7 s, then back by the end
    assert lost_path_time(t, back, window, 1.0) is None
    start = np.full_like(t, 5.0)  # off the whole window
    assert lost_path_time(t, start, window, 1.0) == 0.0
    assert lost_path_time(t, gone, (6.5, 10.0), 1.0) == pytest.approx(6.5)  # only the window counts
    assert lost_path_time(t, gone, window, 2.0) is None  # at the bound is not beyond it


def test_a_lost_run_says_so_in_its_metrics_and_warns():
    columns = {"t": np.arange(0.0, 10.001, 0.1), "tau_r": np.zeros(101), "tau_l": np.zeros(101)}
    columns["e_tr"] = np.where(columns["t"] >= 6.0, 2.0, 0.1)
    common = {"status": "ok", "window": (0.0, 10.0), "control_period": 0.1, "settling_threshold": 0.5}
    lost = summarize(columns, **common, lost_path_error=1.0)
    assert (lost["lost_path"], lost["lost_path_time"], lost["lost_path_error"]) == (True, pytest.approx(6.0), 1.0)
    assert "lost_path" not in summarize(columns, **common)  # not judged without a bound
    from ddtrack.runner import lost_path_warnings

    (warning,) = lost_path_warnings(lost)
    assert warning["code"] == "lost_path" and "from t = 6 s" in warning["message"]
    assert lost_path_warnings(summarize(columns, **common, lost_path_error=3.0)) == []


@pytest.mark.parametrize(("count", "total"), [(0, 10), (3, 10), (10, 10), (1, 36), (17, 30)])
def test_a_rate_carries_the_wilson_interval(count, total):
    from scipy import stats

    expected = stats.binomtest(count, total).proportion_ci(confidence_level=0.95, method="wilson")
    rate = rate_ci(count, total)
    assert rate["mean"] == count / total and rate["n"] == total
    assert (rate["ci_low"], rate["ci_high"]) == pytest.approx((expected.low, expected.high), abs=1e-12)
    assert rate_ci(0, 0)["mean"] is None
    # at the ends the bound is exact, not a rounding away from it (a board printed "0 [2.78e-15, 39.0]")
    assert rate_ci(0, total)["ci_low"] == 0.0 and rate_ci(total, total)["ci_high"] == 1.0
