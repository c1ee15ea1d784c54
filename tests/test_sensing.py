"""Delays, encoders and odometry (model.md §1.9): exact shifts, the fractional split against the continuously delayed
command, quantization bounds, odometry on exact arcs and its drift from wrong nominal wheel radius and track."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ddtrack.model.sensing import (
    actuation_delay,
    actuation_push,
    arc_pose,
    delay_contents,
    delay_line,
    delay_push,
    encoder_angle,
    encoder_counts,
    odometry_step,
    split_delay,
)

T = 0.01  # control period [s]
R, L = 0.05, 0.25  # wheel radius, half axle [m]


def commands(n: int, width: int = 2, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).normal(size=(n, width))


def delayed(line, sequence):
    """What a scan pushing ``sequence`` row by row through ``line`` returns, row by row."""
    return np.asarray(jax.lax.scan(delay_push, line, jnp.asarray(sequence))[1])


# --- delays ---------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("periods", [0, 1, 3, 7])
def test_a_delay_of_k_periods_shifts_the_sequence_by_k_rows(periods):
    sequence, initial = commands(12, width=5), np.arange(5.0)  # e.g. BODY measurements
    out = delayed(delay_line(periods, initial), sequence)
    expected = np.vstack([np.tile(initial, (periods, 1)), sequence[: len(sequence) - periods]])
    assert np.array_equal(out, expected)


def test_the_line_holds_the_last_k_values_oldest_first():
    sequence = commands(10)
    line = jax.lax.scan(delay_push, delay_line(4, np.zeros(2)), jnp.asarray(sequence))[0]
    assert np.array_equal(np.asarray(delay_contents(line)), sequence[-4:])
    with pytest.raises(ValueError, match="periods >= 0"):
        delay_line(-1, np.zeros(2))


def test_split_delay_whole_periods_and_fraction():
    assert split_delay(0.03, 0.01) == (3, 0.0)  # 0.03 / 0.01 = 2.9999999999999996 is three whole periods
    assert split_delay(0.0, 0.01) == (0, 0.0)
    whole, fraction = split_delay(0.0375, 0.01)
    assert whole == 3 and fraction == pytest.approx(0.75, abs=1e-12)
    whole, fraction = split_delay(0.004, 0.01)
    assert whole == 0 and fraction == pytest.approx(0.4, abs=1e-12)
    with pytest.raises(ValueError):
        split_delay(-0.01, 0.01)


@pytest.mark.parametrize("delay", [0.0, 0.004, 0.01, 0.0225, 0.05])
def test_the_fractional_split_is_the_continuously_delayed_command(delay):
    """Over each period, f T earlier + (1 - f) T later is the integral of u(t - tau_a) for the zero-order-held
    commands u (the initial command before t = 0), integrated on a grid fine enough to be exact."""
    sequence, initial = commands(15), np.array([0.3, -0.1])
    whole, fraction = split_delay(delay, T)

    def push(state, command):
        state, earlier, later, split = actuation_push(state, command)
        return state, (earlier, later, split)

    _, (earlier, later, split) = jax.lax.scan(push, actuation_delay(delay, T, initial), jnp.asarray(sequence))
    share = np.asarray(split)[:, None]
    held = share * T * np.asarray(earlier) + (1.0 - share) * T * np.asarray(later)
    grid = 400  # midpoints of 400 slices per period: the switch (at a multiple of T / 400) falls between them
    for j in range(len(sequence)):
        t = j * T + (np.arange(grid) + 0.5) * T / grid
        index = np.floor((t - delay) / T + 1e-9).astype(int)
        acting = np.where((index >= 0)[:, None], sequence[np.clip(index, 0, None)], initial)
        np.testing.assert_allclose(held[j], acting.sum(axis=0) * T / grid, rtol=0, atol=1e-14, err_msg=str(j))
    # and which commands they are: those of periods j - k - 1 and j - k
    padded = np.vstack([np.tile(initial, (whole + 1, 1)), sequence])
    assert np.array_equal(np.asarray(earlier), padded[: len(sequence)])
    assert np.array_equal(np.asarray(later), padded[1 : len(sequence) + 1])
    assert np.all(np.asarray(split) == fraction)


# --- encoders -------------------------------------------------------------------------------------------------------


def test_the_encoder_is_exact_at_whole_counts():
    n = 4096
    counts = np.arange(-3 * n, 3 * n + 1, 7, dtype=float)
    angles = counts * (2.0 * np.pi / n)
    assert np.array_equal(np.asarray(encoder_counts(angles, n)), counts)
    assert np.array_equal(np.asarray(encoder_angle(angles, n)), angles)


def test_the_encoder_reads_at_most_one_count_below_the_angle():
    n = 4096
    count = 2.0 * np.pi / n
    angles = np.random.default_rng(1).uniform(-60.0, 60.0, size=20000)
    error = angles - np.asarray(encoder_angle(angles, n))
    assert np.all(error >= 0.0) and np.all(error < count)
    assert error.max() > 0.95 * count and error.min() < 0.05 * count  # it floors (rounding would stay within half)


# --- odometry -------------------------------------------------------------------------------------------------------


def true_arc(pose, v, omega, duration):
    """The pose after constant (v, omega) for ``duration``, in closed form (not the code's sinc form)."""
    x, y, heading = pose
    if omega == 0.0:
        return np.array([x + v * duration * np.cos(heading), y + v * duration * np.sin(heading), heading])
    turned = heading + omega * duration
    return np.array(
        [x + v / omega * (np.sin(turned) - np.sin(heading)), y - v / omega * (np.cos(turned) - np.cos(heading)), turned]
    )


def wheel_increments(v, omega, duration, radius=R, half_axle=L):
    """How far each wheel turns [rad] at constant (v, omega): (v +- L omega) duration / R."""
    return np.array([v + half_axle * omega, v - half_axle * omega]) * duration / radius


def odometry(increments, start, wheel_radius=R, half_axle=L):
    """The estimates after each row of ``increments``, from the pose ``start``, under a scan."""

    def step(estimate, increment):
        new = odometry_step(estimate, increment, wheel_radius=wheel_radius, half_axle=half_axle, period=T)
        return new, new

    estimate0 = jnp.concatenate([jnp.asarray(start, dtype=float), jnp.zeros(2)])
    return np.asarray(jax.lax.scan(step, estimate0, jnp.asarray(increments))[1])


def test_odometry_follows_exact_arcs():
    rng = np.random.default_rng(2)
    speeds = np.column_stack([rng.uniform(-0.8, 0.8, 60), rng.uniform(-3.0, 3.0, 60)])
    speeds[::7, 1] = 0.0  # straight stretches
    speeds[3, 1] = 0.02  # a gentle turn: a 2e-4 rad arc
    pose = np.array([0.4, -1.2, 2.9])
    truth = []
    for v, omega in speeds:
        pose = true_arc(pose, v, omega, T)
        truth.append(pose)
    increments = [wheel_increments(v, omega, T) for v, omega in speeds]
    estimates = odometry(increments, [0.4, -1.2, 2.9])
    np.testing.assert_allclose(estimates[:, :3], np.array(truth), rtol=0, atol=1e-12)
    np.testing.assert_allclose(estimates[:, 3:], speeds, rtol=0, atol=1e-12)  # increment / T


@pytest.mark.parametrize("turn", [0.0, 1e-12, 1e-6, 1.99e-4, 2.01e-4, 0.3])
def test_the_arc_is_smooth_through_a_straight_line(turn):
    """Either side of the series' threshold, and at zero, the arc matches the chord s sinc(dtheta / 2) computed
    by NumPy; its derivatives are finite at zero turn."""
    pose, distance = jnp.asarray([1.0, 2.0, 0.7]), 0.35
    chord = distance * np.sinc(turn / 2.0 / np.pi)
    expected = [1.0 + chord * np.cos(0.7 + turn / 2.0), 2.0 + chord * np.sin(0.7 + turn / 2.0), 0.7 + turn]
    np.testing.assert_allclose(np.asarray(arc_pose(pose, distance, turn)), expected, rtol=1e-15, atol=1e-15)
    jacobian = jax.jacfwd(arc_pose, argnums=(1, 2))(pose, jnp.asarray(distance), jnp.asarray(turn))
    assert all(np.all(np.isfinite(np.asarray(j))) for j in jacobian)
    gradient = jax.grad(lambda t: arc_pose(pose, distance, t)[1])(jnp.asarray(turn))
    assert np.isfinite(float(gradient)) and float(gradient) != 0.0


def test_a_one_percent_wheel_radius_error_stretches_a_straight_line_by_one_percent():
    v, periods, heading = 0.5, 500, 0.3
    increments = [wheel_increments(v, 0.0, T)] * periods
    estimates = odometry(increments, [0.0, 0.0, heading], wheel_radius=1.01 * R)
    travelled = np.hypot(estimates[:, 0], estimates[:, 1])
    true = v * T * np.arange(1, periods + 1)
    np.testing.assert_allclose(travelled, 1.01 * true, rtol=1e-12, atol=0)  # the distance error is 1 % of it
    np.testing.assert_allclose((travelled - true) / true, 0.01, rtol=0, atol=1e-10)
    assert np.all(estimates[:, 2] == heading)  # both wheels equally wrong: no turn
    np.testing.assert_allclose(np.arctan2(estimates[:, 1], estimates[:, 0]), heading, rtol=0, atol=1e-14)


def test_a_track_error_on_a_circle_scales_the_heading_by_true_over_nominal_track():
    """With L-hat = 1.05 L the estimate turns at omega L / L-hat: after t, its heading error is omega t (L / L-hat
    - 1), and it draws the circle of that turn rate (radius v L-hat / (omega L))."""
    v, omega, periods, nominal = 0.5, 0.4, 1000, 1.05 * L
    increments = [wheel_increments(v, omega, T)] * periods
    estimates = odometry(increments, [0.0, 0.0, 0.0], half_axle=nominal)
    t = T * np.arange(1, periods + 1)
    np.testing.assert_allclose(estimates[:, 2] - omega * t, omega * t * (L / nominal - 1.0), rtol=1e-12, atol=1e-13)
    believed = omega * L / nominal
    circle = np.array([true_arc((0.0, 0.0, 0.0), v, believed, s) for s in t])
    np.testing.assert_allclose(estimates[:, :3], circle, rtol=0, atol=1e-11)
    assert abs(estimates[-1, 2] - omega * t[-1]) > 0.15  # 0.19 rad after 10 s: the drift is visible


def test_quantized_odometry_heading_error_stays_within_one_count_per_wheel():
    """The heading estimate is R (dphi_R - dphi_L) / (2 L) summed: the increments telescope, so its error is at
    most R / (2 L) times two counts, however long the run."""
    n, v, omega, periods = 1024, 0.5, 0.4, 2000
    count = 2.0 * np.pi / n
    t = T * np.arange(periods + 1)
    wheel_angles = np.column_stack([(v + L * omega) * t / R, (v - L * omega) * t / R])
    read = np.asarray(encoder_angle(wheel_angles, n))
    estimates = odometry(np.diff(read, axis=0), [0.0, 0.0, 0.0])
    error = estimates[:, 2] - omega * t[1:]
    assert np.max(np.abs(error)) < R / (2.0 * L) * 2.0 * count
    assert np.max(np.abs(error)) > 0.1 * R / (2.0 * L) * count  # the counts do show


# --- inside a compiled scan body ------------------------------------------------------------------------------------


def test_all_of_it_compiles_into_one_scan_body():
    """A period of a delayed, encoder-fed odometry loop as a jitted scan equals the same steps run eagerly."""
    n = 4096

    def period(carry, command):
        actuation, measurement, angles, estimate = carry
        actuation, earlier, later, fraction = actuation_push(actuation, command)
        held = fraction * earlier + (1.0 - fraction) * later  # a stand-in for the plant: wheel speeds held
        new_angles = angles + held * T
        increments = encoder_angle(new_angles, n) - encoder_angle(angles, n)
        estimate = odometry_step(estimate, increments, wheel_radius=R, half_axle=L, period=T)
        measurement, seen = delay_push(measurement, estimate)
        return (actuation, measurement, new_angles, estimate), seen

    start = (actuation_delay(0.025, T, jnp.zeros(2)), delay_line(2, jnp.zeros(5)), jnp.zeros(2), jnp.zeros(5))
    sequence = jnp.asarray(np.abs(commands(40)) * 10.0)
    compiled = jax.jit(lambda carry, xs: jax.lax.scan(period, carry, xs))
    _, seen = compiled(start, sequence)
    carry, eager = start, []
    for command in sequence:
        carry, out = period(carry, command)
        eager.append(np.asarray(out))
    np.testing.assert_allclose(np.asarray(seen), np.array(eager), rtol=1e-13, atol=1e-15)
    assert np.array_equal(np.asarray(seen)[:2], np.zeros((2, 5))) and np.any(np.asarray(seen)[-1] != 0.0)
