"""The odometry estimate's covariance (ddtrack.ros.covariance) against a Monte Carlo of real quantising encoders:
floor-quantised wheel angles integrated as arcs, written here apart from ddtrack's odometry, thousands of times."""

from __future__ import annotations

import numpy as np
import pytest

from ddtrack.ros.covariance import CovariancePropagation, odometry_covariances

RADIUS, HALF_AXLE, PERIOD, COUNTS = 0.033, 0.08, 0.05, 4096
STEPS, RUNS = 400, 4000


def arc(pose: np.ndarray, right: np.ndarray, left: np.ndarray) -> np.ndarray:
    """Poses (runs, 3) after wheel increments [rad]: the arc they imply, chord s sinc(turn / 2)."""
    distance, turn = RADIUS * (right + left) / 2, RADIUS * (right - left) / (2 * HALF_AXLE)
    chord = distance * np.sinc(turn / 2 / np.pi)
    middle = pose[:, 2] + turn / 2
    return np.stack([pose[:, 0] + chord * np.cos(middle), pose[:, 1] + chord * np.sin(middle), pose[:, 2] + turn], 1)


def monte_carlo(
    fix_every: int = 0, gain: float = 0.0, position_std: float = 0.0, heading_std: float = 0.0, gyro: float = 0.0
):
    """True and estimated poses (STEPS + 1, RUNS, 3) of a robot on a varying arc, each run's encoders zeroed at a
    random angle and its wheel speeds jittered by 1 % per period (so successive count remainders differ); with
    ``gyro`` > 0 the estimate turns by the true turn plus white rate noise of that density [rad/s/sqrt(Hz)]."""
    rng = np.random.default_rng(7)
    t = np.arange(STEPS) * PERIOD
    speeds = np.stack([6.0 + 2.0 * np.sin(0.4 * t), 5.0 + 0.0 * t])  # wheel rates [rad/s], right and left
    jitter = 1.0 + 0.01 * rng.standard_normal((2, STEPS, RUNS))
    angles = np.concatenate([np.zeros((2, 1, RUNS)), np.cumsum(speeds[:, :, None] * PERIOD * jitter, axis=1)], 1)
    angles += rng.uniform(0.0, 2 * np.pi, (2, 1, RUNS))
    count = 2 * np.pi / COUNTS
    read = np.floor(angles / count) * count
    truth, estimate = [np.zeros((RUNS, 3))], [np.zeros((RUNS, 3))]
    for k in range(STEPS):
        true_step, read_step = np.diff(angles[:, k : k + 2], axis=1)[:, 0], np.diff(read[:, k : k + 2], axis=1)[:, 0]
        truth.append(arc(truth[-1], *true_step))
        seen = arc(estimate[-1], *read_step)
        if gyro:  # the encoders' distance along the gyro's turn
            distance = RADIUS * (read_step[0] + read_step[1]) / 2
            turn = truth[-1][:, 2] - truth[-2][:, 2] + gyro * np.sqrt(PERIOD) * rng.standard_normal(RUNS)
            chord, middle = distance * np.sinc(turn / 2 / np.pi), estimate[-1][:, 2] + turn / 2
            seen = estimate[-1] + np.stack([chord * np.cos(middle), chord * np.sin(middle), turn], 1)
        if fix_every and (k + 1) % fix_every == 0:
            noise = rng.standard_normal((RUNS, 3)) * [position_std, position_std, heading_std]
            seen = seen + gain * (truth[-1] + noise - seen)
        estimate.append(seen)
    return np.array(truth), np.array(estimate)


def predicted(truth: np.ndarray, **fix) -> np.ndarray:
    """The module's pose covariance (STEPS + 1, 3, 3) along the runs' mean path."""
    mean = truth.mean(axis=1)
    step = np.diff(mean, axis=0, prepend=mean[:1])  # each row: the period that ends there
    v, omega = np.hypot(step[:, 0], step[:, 1]) / PERIOD, step[:, 2] / PERIOD
    columns = {"odom_theta": mean[:, 2], "odom_v": v, "odom_omega": omega}
    propagation = CovariancePropagation(
        wheel_radius=RADIUS, half_axle=HALF_AXLE, period=PERIOD, encoder_counts=COUNTS, **fix
    )
    pose, _ = odometry_covariances(columns, propagation)
    return pose.reshape(-1, 6, 6)[:, [0, 1, 5]][:, :, [0, 1, 5]]


@pytest.mark.parametrize(
    "fix",
    [
        {},
        {"fix_periods": 20, "fix_gain": 0.5, "fix_position_std": 2e-4, "fix_heading_std": 1e-4},
        {"gyro_noise_density": 1.7e-4},  # the TurtleBot3's MPU-9250: 0.01 deg/s/sqrt(Hz)
    ],
    ids=["encoders", "encoders and a fix", "encoders and a gyro"],
)
def test_the_covariance_is_the_spread_of_quantised_odometry(fix):
    truth, estimate = monte_carlo(
        fix.get("fix_periods", 0),
        fix.get("fix_gain", 0.0),
        fix.get("fix_position_std", 0.0),
        fix.get("fix_heading_std", 0.0),
        fix.get("gyro_noise_density", 0.0),
    )
    error = estimate - truth
    model = predicted(truth, **fix)
    for k in (1, 50, 199, 200, STEPS):  # just after the start, mid-run, either side of a fix, the end
        spread = np.cov(error[k].T)
        # each variance within 10 % (4000 runs: a variance's sampling error is 2.2 %), the correlations within 0.1
        assert np.diag(spread) == pytest.approx(np.diag(model[k]), rel=0.1), k
        scale = np.sqrt(np.outer(np.diag(spread), np.diag(spread)))
        assert np.abs(spread / scale - model[k] / scale).max() < 0.1, k
