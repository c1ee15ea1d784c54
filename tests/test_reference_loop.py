"""An independent scalar re-implementation of the closed loop, written from SPEC 1.3, 2.2, 2.4, 2.5 and 2.7
with ``math`` only (no ddtrack function is called by it), compared with ddtrack's simulator on the
paper's two cases.

What the reference loop does, per control period k (t_k = k T_c), SPEC 2.7:
  1. measure the true state (no noise in the paper scenarios) and the reference at t_k;
  2. Kanayama posture error e_p = T_e(theta) (q_r - q), e_theta wrapped to (-pi, pi];
  3. nu_c from eq. 12, clamped to |v_c| <= v_max, |omega_c| <= w_max, analytic nu_c_dot (0 in a clamped channel);
  4. u = nu_c_dot + K_c (nu_c - nu); tau = B_bar^-1 (M_hat u + V_hat(nu) nu) with the nominal model
     (no friction model), clipped to |tau| <= tau_max;
  5. hold tau and the disturbance tau_d(t_k) over the period and integrate the true plant (friction,
     disturbance) with 10 RK4 sub-steps.
The disturbance is held per period, as ddtrack documents in ``ddtrack.model.disturbance``.

Tolerance 1e-9 throughout: both sides do the same float64 arithmetic up to reassociation (a few ulps
per operation, ~1e-15 relative), and the closed loop is contracting, so the accumulated difference stays
many orders below 1e-9 (measured: <= 2e-13 over 22 s) unless a formula differs.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import ddtrack

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
TOL = 1e-9


# --- the reference implementation (scalars and math only) -------------------------------------------


def wrap(angle: float) -> float:
    """To (-pi, pi]."""
    wrapped = math.atan2(math.sin(angle), math.cos(angle))
    return math.pi if wrapped <= -math.pi else wrapped


def line_reference(t, *, speed, start, heading):
    """SPEC 4.2: constant speed along a fixed heading; omega_r = v_r_dot = omega_r_dot = 0."""
    return (
        start[0] + speed * t * math.cos(heading),
        start[1] + speed * t * math.sin(heading),
        heading,
        speed,
        0.0,
        0.0,
        0.0,
    )


def square_reference(t, *, corner, side, speed):
    """SPEC 4.3, sharp corners: C0 -> C1 -> C2 -> C3 -> C0 counter-clockwise, looping every 4 S / v_r."""
    s = math.fmod(speed * t, 4.0 * side)
    leg = min(int(s // side), 3)
    sigma = s - leg * side
    x0, y0 = corner
    if leg == 0:
        x, y, th = x0 + sigma, y0, 0.0
    elif leg == 1:
        x, y, th = x0 + side, y0 + sigma, math.pi / 2
    elif leg == 2:
        x, y, th = x0 + side - sigma, y0 + side, math.pi
    else:
        x, y, th = x0, y0 + side - sigma, -math.pi / 2
    return x, y, th, speed, 0.0, 0.0, 0.0


def plant_rates(state, tau_r, tau_l, dist_r, dist_l, p):
    """SPEC 1.3, scalar form. p: mass, inertia (I_C), d, R, L, b_w, tau_c, eps."""
    _x, _y, th, v, w = state
    m, i_c, d, r, half, b_w, tau_c, eps = p
    i_a = i_c + m * d * d
    phi_r, phi_l = (v + half * w) / r, (v - half * w) / r
    f_r = b_w * phi_r + tau_c * math.tanh(phi_r / eps)
    f_l = b_w * phi_l + tau_c * math.tanh(phi_l / eps)
    v_dot = ((tau_r + tau_l - f_r - f_l - dist_r - dist_l) / r + m * d * w * w) / m
    w_dot = (half / r * (tau_r - tau_l - f_r + f_l - dist_r + dist_l) - m * d * w * v) / i_a
    return [v * math.cos(th), v * math.sin(th), w, v_dot, w_dot]


def rk4_period(state, tau, dist, p, period, substeps):
    h = period / substeps
    for _ in range(substeps):
        k1 = plant_rates(state, *tau, *dist, p)
        k2 = plant_rates([s + 0.5 * h * k for s, k in zip(state, k1, strict=True)], *tau, *dist, p)
        k3 = plant_rates([s + 0.5 * h * k for s, k in zip(state, k2, strict=True)], *tau, *dist, p)
        k4 = plant_rates([s + h * k for s, k in zip(state, k3, strict=True)], *tau, *dist, p)
        state = [s + h / 6.0 * (a + 2.0 * b + 2.0 * c + e) for s, a, b, c, e in zip(state, k1, k2, k3, k4, strict=True)]
    return state


def control(state, ref, gains, kc, nominal, v_max, w_max, tau_max):
    """Steps 2-5 of SPEC 2.7. Returns (e_p, tau_r, tau_l, v_c, w_c, saturated)."""
    x, y, th, v, w = state
    x_r, y_r, th_r, v_r, w_r, v_r_dot, w_r_dot = ref
    kx, ky, kth = gains
    # SPEC 2.2
    dx, dy = x_r - x, y_r - y
    e_x = math.cos(th) * dx + math.sin(th) * dy
    e_y = -math.sin(th) * dx + math.cos(th) * dy
    e_th = wrap(th_r - th)
    # SPEC 2.4, eq. 12
    v_c = v_r * math.cos(e_th) + kx * e_x
    w_c = w_r + v_r * (ky * e_y + kth * math.sin(e_th))
    # SPEC 2.3 with the measured nu, then SPEC 2.5's analytic derivative
    de_x = w * e_y - v + v_r * math.cos(e_th)
    de_y = -w * e_x + v_r * math.sin(e_th)
    de_th = w_r - w
    v_c_dot = v_r_dot * math.cos(e_th) - v_r * math.sin(e_th) * de_th + kx * de_x
    w_c_dot = w_r_dot + v_r_dot * (ky * e_y + kth * math.sin(e_th)) + v_r * (ky * de_y + kth * math.cos(e_th) * de_th)
    saturated = False
    if abs(v_c) > v_max:
        v_c, v_c_dot, saturated = math.copysign(v_max, v_c), 0.0, True
    if abs(w_c) > w_max:
        w_c, w_c_dot, saturated = math.copysign(w_max, w_c), 0.0, True
    # SPEC 2.5: eq. 11 and eq. 7 with the nominal model (no friction model)
    m, i_c, d, r, half = nominal
    u_v, u_w = v_c_dot + kc[0] * (v_c - v), w_c_dot + kc[1] * (w_c - w)
    g_v = m * u_v - m * d * w * w
    g_w = (i_c + m * d * d) * u_w + m * d * w * v
    tau_r, tau_l = r / 2.0 * (g_v + g_w / half), r / 2.0 * (g_v - g_w / half)
    if abs(tau_r) > tau_max or abs(tau_l) > tau_max:
        saturated = True
        tau_r, tau_l = max(-tau_max, min(tau_max, tau_r)), max(-tau_max, min(tau_max, tau_l))
    return (e_x, e_y, e_th), tau_r, tau_l, v_c, w_c, saturated


def reference_loop(reference, x0, n_steps, *, period, substeps, gains, kc, nominal, plant, limits, disturbance):
    """The whole loop; ``disturbance(t) -> (tau_dR, tau_dL)``. Returns rows like ddtrack.timeseries."""
    rows = {
        k: []
        for k in (
            "t",
            "x",
            "y",
            "theta",
            "v",
            "omega",
            "x_ref",
            "y_ref",
            "theta_ref",
            "e_x",
            "e_y",
            "e_theta",
            "v_cmd",
            "omega_cmd",
            "tau_r",
            "tau_l",
            "saturated",
        )
    }
    state = list(x0)
    for k in range(n_steps):
        t = k * period
        ref = reference(t)
        e, tau_r, tau_l, v_c, w_c, saturated = control(state, ref, gains, kc, nominal, *limits)
        tau_r, tau_l = max(-plant[-1], min(plant[-1], tau_r)), max(-plant[-1], min(plant[-1], tau_l))  # the motor
        for name, value in zip(rows, (t, *state, *ref[:3], *e, v_c, w_c, tau_r, tau_l, float(saturated)), strict=True):
            rows[name].append(value)
        state = rk4_period(state, (tau_r, tau_l), disturbance(t), plant[:-1], period, substeps)
    rows = {k: np.asarray(v) for k, v in rows.items()}
    rows["e_tr"] = np.hypot(rows["e_x"], rows["e_y"])
    return rows


# --- driving it from a scenario ----------------------------------------------------------------------


def from_scenario(scenario, n_steps, *, with_disturbance=True):
    sim, robot, ctrl = scenario.simulation, scenario.robot, scenario.controller
    plant = scenario.plant_params()  # [plant] over [robot]
    traj = scenario.trajectory
    if traj.kind == "line":

        def reference(t):
            return line_reference(t, speed=traj.speed, start=traj.start, heading=traj.heading)
    else:
        assert traj.kind == "square" and traj.corner_radius == 0.0

        def reference(t):
            return square_reference(t, corner=traj.corner, side=traj.side, speed=traj.speed)

    dist = scenario.disturbance
    assert dist.kind == "sinusoid"

    def disturbance(t):
        if not with_disturbance:
            return 0.0, 0.0
        return tuple(
            b + a * math.sin(dist.frequency * t + ph)
            for b, a, ph in zip(dist.bias, dist.amplitude, dist.phase, strict=True)
        )

    if scenario.initial.pose is not None:
        pose = scenario.initial.pose
    else:
        pose = reference(0.0)[:3]
    return reference_loop(
        reference,
        [*pose, *scenario.initial.velocity],
        n_steps,
        period=sim.control_period,
        substeps=sim.substeps,
        gains=ctrl.gains,
        kc=ctrl.kc,
        nominal=(robot.mass, robot.inertia, robot.com_offset, robot.wheel_radius, robot.half_axle),
        plant=(
            plant.mass,
            plant.inertia,
            plant.com_offset,
            plant.wheel_radius,
            plant.half_axle,
            plant.viscous_friction,
            plant.coulomb_friction,
            plant.friction_smoothing,
            plant.max_torque,
        ),
        limits=(ctrl.max_velocity, ctrl.max_yaw_rate, robot.max_torque),
        disturbance=disturbance,
    )


COMPARED = (
    "x",
    "y",
    "theta",
    "v",
    "omega",
    "x_ref",
    "y_ref",
    "theta_ref",
    "e_x",
    "e_y",
    "e_theta",
    "e_tr",
    "v_cmd",
    "omega_cmd",
    "tau_r",
    "tau_l",
)


def assert_same_run(ours, theirs, n):
    for name in COMPARED:
        np.testing.assert_allclose(theirs[name][:n], ours[name][:n], rtol=0, atol=TOL, err_msg=name)
    np.testing.assert_array_equal(theirs["saturated"][:n], ours["saturated"][:n])
    np.testing.assert_allclose(theirs["t"][:n], ours["t"][:n], rtol=0, atol=1e-12)


def load(name, duration):
    return ddtrack.load_scenario(
        SCENARIOS / name, overrides=[f"simulation.duration={duration}", f"simulation.metric_window=[0.0, {duration}]"]
    )


@pytest.fixture(scope="module")
def paper_line():
    scenario = load("paper_line.toml", 5.0)  # 500 control periods; the clamps release at ~3.7 s
    return scenario, ddtrack.timeseries(ddtrack.run(scenario))


@pytest.fixture(scope="module")
def paper_square():
    scenario = load("paper_square.toml", 22.0)  # C1 is reached at t = S / v_r = 20 s
    return scenario, ddtrack.timeseries(ddtrack.run(scenario))


def test_paper_line_matches_reference_loop(paper_line):
    scenario, theirs = paper_line
    n = scenario.simulation.n_steps
    assert n == 500 and len(theirs["t"]) == n
    ours = from_scenario(scenario, n)
    assert_same_run(ours, theirs, n)
    # the comparison covers saturated and unsaturated rows, velocity clamps and the torque limit
    assert 0 < ours["saturated"].sum() < n
    assert (
        np.max(np.abs(ours["tau_r"])) == scenario.robot.max_torque
        or np.max(np.abs(ours["tau_l"])) == scenario.robot.max_torque
    )


def test_paper_line_disturbance_is_seen(paper_line):
    """The sinusoid disturbance matters at this tolerance: leaving it out of the reference loop breaks the match."""
    scenario, theirs = paper_line
    n = scenario.simulation.n_steps
    ours = from_scenario(scenario, n, with_disturbance=False)
    assert np.max(np.abs(theirs["v"] - ours["v"])) > 1e3 * TOL


def test_paper_square_matches_reference_loop_over_a_corner(paper_square):
    scenario, theirs = paper_square
    n = scenario.simulation.n_steps
    ours = from_scenario(scenario, n)
    assert_same_run(ours, theirs, n)
    # the corner at t = 20 s is in the run: the reference heading jumps by pi/2 and the yaw clamp acts
    corner = round(20.0 / scenario.simulation.control_period)
    assert ours["theta_ref"][corner - 1] == 0.0 and ours["theta_ref"][corner] == pytest.approx(math.pi / 2)
    assert ours["saturated"][corner] == 1.0 and ours["saturated"][:corner].sum() == 0.0
    assert np.max(np.abs(ours["e_theta"][corner:])) > 1.0
