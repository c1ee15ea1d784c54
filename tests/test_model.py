"""The robot model against the analytic facts of SPEC 6, items 1-5 (and SPEC 1.1-1.3).

Every random sample comes from a numpy Generator with a fixed seed; batches are evaluated with one
``jax.vmap`` so that each property costs one compilation.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ddtrack  # noqa: F401  (turns on float64)
from ddtrack.model import (
    DynamicPlant,
    KinematicPlant,
    MeasurementNoise,
    RobotParams,
    WheelDisturbance,
    body_acceleration,
    body_velocity,
    constraint_matrix,
    coriolis_vector,
    energy,
    input_matrix,
    mass_matrix,
    pose_rate,
    reduced_coriolis,
    reduced_input,
    reduced_input_inverse,
    reduced_mass,
    velocity_basis,
    wheel_friction,
    wheel_speeds,
)
from ddtrack.sim import rk4

N_SAMPLES = 64


def random_params(rng, n):
    """n random robots, with a signed centre-of-mass offset d (C ahead of or behind the axle)."""
    return {
        "mass": rng.uniform(1.0, 30.0, n),
        "inertia": rng.uniform(0.05, 3.0, n),
        "com_offset": rng.uniform(-0.3, 0.3, n),
        "wheel_radius": rng.uniform(0.02, 0.2, n),
        "half_axle": rng.uniform(0.1, 0.6, n),
    }


def make_params(p, **extra):
    return RobotParams(
        mass=p["mass"],
        inertia=p["inertia"],
        com_offset=p["com_offset"],
        wheel_radius=p["wheel_radius"],
        half_axle=p["half_axle"],
        **extra,
    )


def batch(fn, *args):
    """Evaluate ``fn`` over the leading axis of every argument (dicts of arrays included), jitted."""
    return jax.jit(jax.vmap(fn))(*args)


def s_dot(theta, omega):
    """d/dt S(q) = omega dS/dtheta, written out from SPEC 1.1 (independent of the package)."""
    c, s = jnp.cos(theta), jnp.sin(theta)
    return omega * jnp.array([[-s, 0.0], [c, 0.0], [0.0, 0.0]])


# --- SPEC 6.1: the constraint and its null space ---------------------------------------------


def test_constraint_annihilates_velocity_basis():
    theta = np.random.default_rng(1).uniform(-10.0, 10.0, N_SAMPLES)
    a, s = batch(lambda th: (constraint_matrix(th), velocity_basis(th)), theta)
    assert a.shape == (N_SAMPLES, 1, 3) and s.shape == (N_SAMPLES, 3, 2)
    a_s = jnp.einsum("nij,njk->nik", a, s)
    st_at = jnp.einsum("nji,nkj->nik", s, a)
    # SPEC 6.1: tol 1e-14 (entries are +-sin*cos products of unit-size numbers)
    assert np.max(np.abs(a_s)) < 1e-14
    assert np.max(np.abs(st_at)) < 1e-14
    # S is the basis of SPEC 1.1, not merely some null-space basis: q_dot = S nu = [v c, v s, w]
    expected = np.zeros((N_SAMPLES, 3, 2))
    expected[:, 0, 0], expected[:, 1, 0], expected[:, 2, 1] = np.cos(theta), np.sin(theta), 1.0
    np.testing.assert_allclose(s, expected, rtol=0, atol=1e-15)  # same formula: exact up to rounding


def test_pose_rate_is_velocity_basis_times_nu():
    rng = np.random.default_rng(2)
    theta, nu = rng.uniform(-4, 4, N_SAMPLES), rng.normal(size=(N_SAMPLES, 2))
    q_dot, s_nu = batch(lambda th, n: (pose_rate(th, n[0], n[1]), velocity_basis(th) @ n), theta, nu)
    np.testing.assert_allclose(q_dot, s_nu, rtol=0, atol=1e-15)  # one product per entry: rounding only
    # no lateral slip: the velocity has no component along the body y axis
    lateral = -np.sin(theta) * q_dot[:, 0] + np.cos(theta) * q_dot[:, 1]
    assert np.max(np.abs(lateral)) < 1e-14  # SPEC 6.1 tolerance


# --- SPEC 6.2: reduced mass, input matrix, wheel map ------------------------------------------


def test_reduced_mass_and_input_are_projections_of_full_model():
    rng = np.random.default_rng(3)
    p = random_params(rng, N_SAMPLES)
    theta = rng.uniform(-10.0, 10.0, N_SAMPLES)

    def one(pp, th):
        params = make_params(pp)
        s = velocity_basis(th)
        return (
            s.T @ mass_matrix(params, th) @ s,
            reduced_mass(params),
            s.T @ input_matrix(params, th),
            reduced_input(params),
            reduced_input(params) @ reduced_input_inverse(params),
        )

    stms, mbar, stb, bbar, eye = batch(one, p, theta)
    i_a = p["inertia"] + p["mass"] * p["com_offset"] ** 2
    expected_mbar = np.zeros((N_SAMPLES, 2, 2))
    expected_mbar[:, 0, 0], expected_mbar[:, 1, 1] = p["mass"], i_a
    # a few roundings on entries of size <= 30: relative 1e-14 of the largest entry
    scale = np.maximum(p["mass"], i_a)[:, None, None]
    assert np.all(np.abs(stms - expected_mbar) <= 1e-14 * scale)
    assert np.all(np.abs(mbar - expected_mbar) <= 1e-14 * scale)
    # d has both signs in the sample, so the sign convention of M_13, M_23 is exercised
    assert np.any(p["com_offset"] < -0.1) and np.any(p["com_offset"] > 0.1)

    r = p["wheel_radius"][:, None, None]
    expected_bbar = (
        np.array([[1.0, 1.0], [1.0, -1.0]])[None]
        * np.stack([np.ones(N_SAMPLES), p["half_axle"]], axis=1)[:, :, None]
        / r
    )
    np.testing.assert_allclose(stb, expected_bbar, rtol=1e-14, atol=0)  # c^2 + s^2 = 1 up to rounding
    np.testing.assert_allclose(bbar, expected_bbar, rtol=1e-15, atol=0)
    np.testing.assert_allclose(eye, np.broadcast_to(np.eye(2), eye.shape), rtol=0, atol=1e-14)


def test_wheel_speeds_and_body_velocity_are_inverse():
    rng = np.random.default_rng(4)
    p = random_params(rng, N_SAMPLES)
    nu, phi = rng.normal(size=(N_SAMPLES, 2)), rng.normal(scale=20.0, size=(N_SAMPLES, 2))

    def one(pp, n, ph):
        params = make_params(pp)
        return (
            wheel_speeds(params, n),
            body_velocity(params, wheel_speeds(params, n)),
            wheel_speeds(params, body_velocity(params, ph)),
        )

    w_nu, nu_back, phi_back = batch(one, p, nu, phi)
    np.testing.assert_allclose(nu_back, nu, rtol=1e-13, atol=1e-14)  # a handful of roundings
    np.testing.assert_allclose(phi_back, phi, rtol=1e-13, atol=1e-12)  # |phi| ~ 20: 1e-12 absolute
    # the forward map is SPEC 1.1: phi_R = (v + L w)/R, phi_L = (v - L w)/R
    r, half = p["wheel_radius"], p["half_axle"]
    expected = np.stack([(nu[:, 0] + half * nu[:, 1]) / r, (nu[:, 0] - half * nu[:, 1]) / r], axis=1)
    np.testing.assert_allclose(w_nu, expected, rtol=1e-14, atol=1e-14)


# --- SPEC 6.3: skew Coriolis, energy conservation ---------------------------------------------


def test_reduced_coriolis_does_no_work():
    rng = np.random.default_rng(5)
    p = random_params(rng, N_SAMPLES)
    nu = rng.normal(scale=2.0, size=(N_SAMPLES, 2))
    vnu = batch(lambda pp, n: reduced_coriolis(make_params(pp), n), p, nu)
    md = p["mass"] * p["com_offset"]
    # SPEC 1.3: V_bar nu = [-m d w^2, m d w v]
    expected = np.stack([-md * nu[:, 1] ** 2, md * nu[:, 1] * nu[:, 0]], axis=1)
    np.testing.assert_allclose(vnu, expected, rtol=1e-14, atol=1e-14)
    power = np.sum(nu * vnu, axis=1)
    # nu . V_bar nu cancels exactly in exact arithmetic; terms are <= |m d| |nu|^3 ~ 1e2: 1e-13 relative
    scale = np.abs(md) * np.sum(nu**2, axis=1) ** 1.5
    assert np.all(np.abs(power) <= 1e-14 * np.maximum(scale, 1.0))


def test_energy_is_conserved_without_torque_friction_or_disturbance():
    # C ahead of the axle, so the Coriolis term is active and v, w exchange energy (v changes a lot)
    plant = DynamicPlant(RobotParams(com_offset=0.08, viscous_friction=0.0, coulomb_friction=0.0))
    x0 = jnp.array([0.3, -0.2, 0.7, 0.4, 1.5])
    zero = jnp.zeros(2)

    @jax.jit
    def run(x0):
        f = lambda x: plant.derivative(x, zero, zero)  # noqa: E731
        return rk4(f, x0, 10.0, 10_000)  # 10 s at 1 ms (SPEC 6.3)

    x_end = run(x0)
    e0, e1 = energy(plant.params, x0[3:]), energy(plant.params, x_end[3:])
    assert abs(float(e1 - e0)) / float(e0) < 1e-8  # SPEC 6.3
    # the test is not vacuous: the Coriolis coupling really moved energy between v and w
    assert abs(float(x_end[3] - x0[3])) > 1e-2
    # energy() is the formula of SPEC 6.3
    p = plant.params
    assert float(e0) == pytest.approx(0.5 * (p.mass * 0.4**2 + (p.inertia + p.mass * 0.08**2) * 1.5**2), rel=1e-15)


# --- SPEC 6.4: reduced model from the full Lagrangian -----------------------------------------


def test_reduced_model_matches_full_lagrangian():
    rng = np.random.default_rng(6)
    p = random_params(rng, N_SAMPLES)
    theta = rng.uniform(-10.0, 10.0, N_SAMPLES)
    nu, nu_dot = rng.normal(scale=2.0, size=(N_SAMPLES, 2)), rng.normal(scale=5.0, size=(N_SAMPLES, 2))

    def one(pp, th, n, nd):
        params = make_params(pp)
        s = velocity_basis(th)
        q_dot = s @ n
        q_ddot = s_dot(th, n[1]) @ n + s @ nd
        lhs = s.T @ (mass_matrix(params, th) @ q_ddot + coriolis_vector(params, th, q_dot[2]))
        rhs = reduced_mass(params) @ nd + reduced_coriolis(params, n)
        return lhs, rhs

    lhs, rhs = batch(one, p, theta, nu, nu_dot)
    # entries up to ~30 kg * 10 m/s^2: 1e-12 absolute is ~1e4 ulps of slack for the 3x3 products
    np.testing.assert_allclose(lhs, rhs, rtol=0, atol=1e-12)


def test_body_acceleration_satisfies_full_equations_with_constraint_force():
    """M q_ddot + V + B tau_f + B tau_d = B tau - A^T lambda with lambda = -m (v w + d w_dot) (SPEC 1.2)."""
    rng = np.random.default_rng(7)
    p = random_params(rng, N_SAMPLES)
    theta = rng.uniform(-10.0, 10.0, N_SAMPLES)
    nu = rng.normal(scale=1.0, size=(N_SAMPLES, 2))
    tau, tau_d = rng.uniform(-5, 5, (N_SAMPLES, 2)), rng.uniform(-0.5, 0.5, (N_SAMPLES, 2))

    def one(pp, th, n, u, ud):
        params = make_params(pp, viscous_friction=0.005, coulomb_friction=0.05, friction_smoothing=0.01)
        nd = body_acceleration(params, n, u, ud)
        s = velocity_basis(th)
        q_ddot = s_dot(th, n[1]) @ n + s @ nd
        b = input_matrix(params, th)
        friction = b @ wheel_friction(params, wheel_speeds(params, n))
        lam = -params.mass * (n[0] * n[1] + params.com_offset * nd[1])
        residual = (
            mass_matrix(params, th) @ q_ddot
            + coriolis_vector(params, th, n[1])
            + friction
            + b @ ud
            - b @ u
            + constraint_matrix(th)[0] * lam
        )
        return residual, b @ u

    residual, force = batch(one, p, theta, nu, tau, tau_d)
    scale = np.max(np.abs(force), axis=1)  # generalised forces up to ~1e3 N
    assert np.all(np.max(np.abs(residual), axis=1) <= 1e-12 * np.maximum(scale, 1.0))  # rounding only


def test_body_acceleration_scalar_form():
    """The scalar equations of SPEC 1.3, typed out independently."""
    params = RobotParams(
        mass=12.0,
        inertia=0.7,
        com_offset=0.08,
        wheel_radius=0.05,
        half_axle=0.25,
        viscous_friction=0.005,
        coulomb_friction=0.05,
        friction_smoothing=0.01,
    )
    v, w = 0.4, -0.7
    tau, tau_d = np.array([1.3, -0.4]), np.array([0.03, -0.02])
    m, i_a, d, r, half = 12.0, 0.7 + 12.0 * 0.08**2, 0.08, 0.05, 0.25
    phi = np.array([(v + half * w) / r, (v - half * w) / r])
    tf = 0.005 * phi + 0.05 * np.tanh(phi / 0.01)
    v_dot = ((tau[0] + tau[1] - tf[0] - tf[1] - tau_d[0] - tau_d[1]) / r + m * d * w**2) / m
    w_dot = (half / r * (tau[0] - tau[1] - tf[0] + tf[1] - tau_d[0] + tau_d[1]) - m * d * w * v) / i_a
    got = body_acceleration(params, jnp.array([v, w]), jnp.asarray(tau), jnp.asarray(tau_d))
    np.testing.assert_allclose(got, [v_dot, w_dot], rtol=1e-13)  # same formula: rounding only
    x = jnp.array([1.0, 2.0, 0.3, v, w])
    x_dot = DynamicPlant(params).derivative(x, jnp.asarray(tau), jnp.asarray(tau_d))
    np.testing.assert_allclose(x_dot, [v * np.cos(0.3), v * np.sin(0.3), w, v_dot, w_dot], rtol=1e-13)


# --- SPEC 6.5: pure kinematics ----------------------------------------------------------------


def test_kinematic_plant_drives_closed_form_arc():
    rng = np.random.default_rng(8)
    n = 16
    q0 = np.column_stack([rng.uniform(-5, 5, n), rng.uniform(-5, 5, n), rng.uniform(-np.pi, np.pi, n)])
    v = rng.uniform(-1.0, 1.0, n)
    w = rng.choice([-1.0, 1.0], n) * rng.uniform(0.2, 2.0, n)  # both turning directions, |w| > 0
    duration = 5.0
    plant = KinematicPlant()

    def one(q, vv, ww):
        x = plant.hold(jnp.concatenate([q, jnp.zeros(2)]), jnp.stack([vv, ww]))
        return rk4(lambda z: plant.derivative(z, jnp.stack([vv, ww]), jnp.zeros(2)), x, duration, 5000)

    x_end = batch(one, q0, v, w)
    th = q0[:, 2] + w * duration
    expected_x = q0[:, 0] + v / w * (np.sin(th) - np.sin(q0[:, 2]))
    expected_y = q0[:, 1] - v / w * (np.cos(th) - np.cos(q0[:, 2]))
    # RK4 at 1 ms: global error ~ h^4 |x^(5)| T ~ 1e-12 * 2^4 * 5; 1e-9 leaves room for rounding
    np.testing.assert_allclose(x_end[:, 0], expected_x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(x_end[:, 1], expected_y, rtol=0, atol=1e-9)
    np.testing.assert_allclose(x_end[:, 2], th, rtol=0, atol=1e-12)  # theta is linear in t: exact
    np.testing.assert_allclose(x_end[:, 3:], np.column_stack([v, w]), rtol=0, atol=0)  # held input
    # the end point lies on the circle of radius |v/w| about the centre q0 + (v/w) n(theta0)
    centre = q0[:, :2] + (v / w)[:, None] * np.column_stack([-np.sin(q0[:, 2]), np.cos(q0[:, 2])])
    radius = np.hypot(x_end[:, 0] - centre[:, 0], x_end[:, 1] - centre[:, 1])
    np.testing.assert_allclose(radius, np.abs(v / w), rtol=0, atol=1e-9)  # as above


def test_kinematic_plant_hold_sets_velocity_and_ignores_disturbance():
    plant = KinematicPlant()
    x = jnp.array([1.0, 2.0, 0.5, 9.0, -9.0])
    held = plant.hold(x, jnp.array([0.3, -0.2]))
    np.testing.assert_array_equal(held, [1.0, 2.0, 0.5, 0.3, -0.2])
    a = plant.derivative(held, jnp.array([0.3, -0.2]), jnp.zeros(2))
    b = plant.derivative(held, jnp.array([0.3, -0.2]), jnp.array([5.0, -5.0]))
    np.testing.assert_array_equal(a, b)
    np.testing.assert_allclose(a, [0.3 * np.cos(0.5), 0.3 * np.sin(0.5), -0.2, 0.0, 0.0], rtol=1e-15)


# --- friction, disturbance, noise ---------------------------------------------------------------


def test_wheel_friction_opposes_motion_with_tanh_smoothing():
    params = RobotParams(viscous_friction=0.005, coulomb_friction=0.05, friction_smoothing=0.01)
    phi = jnp.array([-50.0, -1.0, -0.01, -1e-4, 0.0, 1e-4, 0.01, 1.0, 50.0])
    tf = np.asarray(wheel_friction(params, phi))
    # sign: opposes the wheel's motion (positive torque opposes positive speed on the LHS), zero at rest
    np.testing.assert_array_equal(np.sign(tf), np.sign(phi))
    np.testing.assert_allclose(tf, -tf[::-1], rtol=1e-15)  # odd in phi
    # smoothing: at phi = eps_f the Coulomb part is tau_c tanh(1), far away it saturates at tau_c
    assert tf[6] == pytest.approx(0.005 * 0.01 + 0.05 * np.tanh(1.0), rel=1e-14)
    assert tf[8] == pytest.approx(0.005 * 50.0 + 0.05, rel=1e-14)  # tanh(5000) = 1 in float64
    # continuous through zero: slope tau_c/eps_f + b_w near the origin (linear regime of tanh)
    # phi/eps = 0.01, tanh(x) = x (1 - x^2/3 + ...): relative deviation 3.3e-5 < 1e-4
    assert tf[5] == pytest.approx((0.05 / 0.01 + 0.005) * 1e-4, rel=1e-4)
    # and in the robot: coasting forward or spinning, friction decelerates
    plant = DynamicPlant(params)
    zero = jnp.zeros(2)
    forward = plant.derivative(jnp.array([0.0, 0.0, 0.0, 0.5, 0.0]), zero, zero)
    spin = plant.derivative(jnp.array([0.0, 0.0, 0.0, 0.0, 1.0]), zero, zero)
    assert float(forward[3]) < 0.0 and float(spin[4]) < 0.0
    # magnitude: both wheels at v/R = 10 rad/s carry b*10 + tau_c tanh(1000) each
    assert float(forward[3]) == pytest.approx(-2 * (0.005 * 10 + 0.05) / 0.05 / 10.0, rel=1e-12)
    # friction off: exactly zero torque
    assert np.all(np.asarray(wheel_friction(RobotParams(), phi)) == 0.0)


def test_positive_constant_disturbance_decelerates_forward_motion():
    params = RobotParams(com_offset=0.05)
    plant = DynamicPlant(params)
    x = jnp.array([0.0, 0.0, 0.3, 0.5, 0.0])
    tau = jnp.array([0.2, 0.2])
    dist = WheelDisturbance(bias=(0.05, 0.05))
    tau_d = dist.torque(3.0, jnp.zeros(2))
    with_d = plant.derivative(x, tau, tau_d)
    without = plant.derivative(x, tau, jnp.zeros(2))
    assert float(with_d[3]) < float(without[3])
    # exact: two wheels x 0.05 N m / R / m
    assert float(without[3] - with_d[3]) == pytest.approx(2 * 0.05 / 0.05 / 10.0, rel=1e-13)
    assert float(with_d[4]) == pytest.approx(float(without[4]), abs=1e-15)  # symmetric: no yaw
    # coasting (no torque): the disturbance alone slows the robot down
    coast = plant.derivative(x, jnp.zeros(2), tau_d)
    assert float(coast[3]) < 0.0
    # on the right wheel only: a negative (clockwise) yaw torque L/R * 0.05
    right = plant.derivative(x, jnp.zeros(2), jnp.array([0.05, 0.0]))
    assert float(right[4]) == pytest.approx(-0.25 / 0.05 * 0.05 / params.inertia_axle, rel=1e-13)


def test_wheel_disturbance_matches_formula():
    rng = np.random.default_rng(9)
    n = 200
    t, xi = rng.uniform(0, 40, n), rng.standard_normal((n, 2))
    dist = WheelDisturbance(
        bias=(0.03, -0.01), amplitude=(0.05, -0.05), frequency=0.5, phase=(0.0, 0.3), std=(0.02, 0.04)
    )
    got = batch(dist.torque, t, xi)
    expected = (
        np.array([0.03, -0.01])
        + np.array([0.05, -0.05]) * np.sin(0.5 * t[:, None] + np.array([0.0, 0.3]))
        + np.array([0.02, 0.04]) * xi
    )
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-15)  # same formula: rounding only
    # Gaussian-only disturbance: the draws are scaled and shifted, bias + std * xi
    gauss = WheelDisturbance(bias=(0.1, 0.2), std=(0.5, 0.25))
    got = batch(gauss.torque, t, xi)
    np.testing.assert_allclose(got, np.array([0.1, 0.2]) + np.array([0.5, 0.25]) * xi, rtol=0, atol=1e-15)
    # default: no disturbance at all, whatever the draw
    assert np.all(np.asarray(batch(WheelDisturbance().torque, t, xi)) == 0.0)


def test_measurement_noise_adds_scaled_draws():
    rng = np.random.default_rng(10)
    x, xi = rng.normal(size=(50, 5)), rng.standard_normal((50, 5))
    std = (1e-3, 2e-3, 1e-3, 0.0, 0.5)
    got = batch(MeasurementNoise(std=std).measure, x, xi)
    np.testing.assert_allclose(got, x + np.asarray(std) * xi, rtol=0, atol=1e-15)  # rounding only
    np.testing.assert_array_equal(got[:, 3], x[:, 3])  # zero std leaves that channel untouched
    np.testing.assert_array_equal(batch(MeasurementNoise().measure, x, xi), x)


# --- wheel spin inertia (model.md §1.6) ----------------------------------------------------------


def test_wheel_inertia_adds_to_the_mass_and_yaw_inertia_the_torques_see():
    """From rest, no friction: equal torques tau give v_dot = (2 tau / R) / (m + 2 J_w / R^2), opposite ones
    omega_dot = (2 L tau / R) / (I_A + 2 J_w L^2 / R^2) (model.md §1.6); a centre-of-mass offset changes nothing
    at rest, since the Coriolis terms need omega."""
    tau, zero = 0.7, jnp.zeros(2)
    for com_offset in (0.0, 0.08):
        for j_w in (0.0, 0.002, 0.03):
            p = RobotParams(com_offset=com_offset, wheel_inertia=j_w)
            r, half = p.wheel_radius, p.half_axle
            forward = body_acceleration(p, zero, jnp.array([tau, tau]), zero)
            assert float(forward[0]) == pytest.approx(2 * tau / r / (p.mass + 2 * j_w / r**2), rel=1e-14)
            assert abs(float(forward[1])) < 1e-14  # rounding only
            turn = body_acceleration(p, zero, jnp.array([tau, -tau]), zero)
            expected = 2 * half * tau / r / (p.inertia + p.mass * com_offset**2 + 2 * j_w * half**2 / r**2)
            assert float(turn[1]) == pytest.approx(expected, rel=1e-14)
            assert abs(float(turn[0])) < 1e-14
    # the inertia matters: 0.03 kg m^2 on a 0.05 m wheel is 24 kg more for the torques to push
    light = body_acceleration(RobotParams(), zero, jnp.array([tau, tau]), zero)
    heavy = body_acceleration(RobotParams(wheel_inertia=0.03), zero, jnp.array([tau, tau]), zero)
    assert float(heavy[0]) == pytest.approx(float(light[0]) * 10.0 / 34.0, rel=1e-14)


def test_with_wheel_inertia_the_power_of_the_torques_is_the_rate_of_the_energy():
    """d/dt [1/2 (m v^2 + I_A omega^2) + 1/2 J_w (phi_dot_R^2 + phi_dot_L^2)] = tau . phi_dot without friction
    or disturbance, in any state: the spin energy is counted once, and the Coriolis terms do no work."""
    rng = np.random.default_rng(21)
    p = random_params(rng, N_SAMPLES)
    j_w = rng.uniform(0.0, 0.05, N_SAMPLES)
    nu, tau = rng.uniform(-2.0, 2.0, (N_SAMPLES, 2)), rng.uniform(-5.0, 5.0, (N_SAMPLES, 2))

    def power_balance(p, j_w, nu, tau):
        params = make_params(p, wheel_inertia=j_w)
        nu_dot = body_acceleration(params, nu, tau, jnp.zeros(2))
        energy_rate = jax.jvp(lambda n: energy(params, n), (nu,), (nu_dot,))[1]
        return energy_rate, tau @ wheel_speeds(params, nu)

    energy_rate, power = jax.vmap(power_balance)(p, j_w, nu, tau)
    np.testing.assert_allclose(energy_rate, power, rtol=1e-11, atol=1e-11)
    # the spin energy is in energy(): 1/2 J_w |W nu|^2 more than the body's
    params = RobotParams(com_offset=0.0, wheel_inertia=0.01)
    nu0 = jnp.array([0.4, 1.5])
    body = 0.5 * (params.mass * 0.4**2 + params.inertia * 1.5**2)
    spin = 0.5 * 0.01 * float(jnp.sum(wheel_speeds(params, nu0) ** 2))
    assert float(energy(params, nu0)) == pytest.approx(body + spin, rel=1e-14)


def test_with_wheel_inertia_each_wheel_obeys_its_own_newton_equation():
    """The floor's force on each wheel, from the body's motion alone (``traction.contact_forces``, which does not
    know J_w), satisfies J_w phi_ddot_i = tau_i - R F_i: the spinning wheels take their share of the torque and the
    contact forces the grip check reads stay right (model.md §1.5, 1.6)."""
    from ddtrack.model.traction import contact_forces

    rng = np.random.default_rng(22)
    for _ in range(20):
        params = RobotParams(
            mass=rng.uniform(1.0, 20.0),
            inertia=rng.uniform(0.05, 2.0),
            com_offset=rng.uniform(-0.2, 0.2),
            wheel_radius=rng.uniform(0.03, 0.15),
            half_axle=rng.uniform(0.1, 0.4),
            wheel_inertia=rng.uniform(0.001, 0.05),
        )
        nu, tau = jnp.asarray(rng.uniform(-1.0, 1.0, 2)), jnp.asarray(rng.uniform(-2.0, 2.0, 2))
        nu_dot = np.asarray(body_acceleration(params, nu, tau, jnp.zeros(2)))
        h = 1e-3  # two samples a step h apart, so the forward difference is nu_dot exactly (up to rounding)
        right, left, _ = contact_forces(
            [0.0, h],
            [float(nu[0]), float(nu[0]) + h * nu_dot[0]],
            [float(nu[1]), float(nu[1]) + h * nu_dot[1]],
            mass=params.mass,
            inertia_axle=params.inertia_axle,
            com_offset=params.com_offset,
            half_axle=params.half_axle,
        )
        phi_ddot = np.asarray(wheel_speeds(params, jnp.asarray(nu_dot)))
        forces = np.array([right[0], left[0]])
        np.testing.assert_allclose(
            params.wheel_inertia * phi_ddot, np.asarray(tau) - params.wheel_radius * forces, rtol=0, atol=1e-9
        )
        assert np.max(np.abs(params.wheel_inertia * phi_ddot)) > 1e-3  # the wheels really took torque


def test_computed_torque_uses_the_nominal_wheel_inertia():
    """Computed torque on a nominal model with the plant's J_w makes nu_dot = u exactly; leaving J_w out of the
    nominal model on the same plant does not (model.md §1.6, 2.5)."""
    import dataclasses

    from ddtrack.controllers import ComputedTorque, VelocityCommand

    plant = RobotParams(com_offset=0.08, wheel_inertia=0.01, max_torque=1e9)
    y = jnp.asarray([0.0, 0.0, 0.3, 0.4, 0.2])
    command = VelocityCommand(jnp.asarray([0.5, 0.1]), jnp.asarray([0.3, -0.2]), jnp.zeros(2), jnp.asarray(0.0))
    u = np.asarray(command.nu_c_dot + 10.0 * (command.nu_c - y[3:5]))
    tau, _, _ = ComputedTorque(plant).torque(y, command, ())
    np.testing.assert_allclose(body_acceleration(plant, y[3:5], tau, jnp.zeros(2)), u, rtol=0, atol=1e-12)
    tau, _, _ = ComputedTorque(dataclasses.replace(plant, wheel_inertia=0.0)).torque(y, command, ())
    slow = np.asarray(body_acceleration(plant, y[3:5], tau, jnp.zeros(2)))
    assert np.all(np.abs(slow - u) > 0.1 * np.abs(u))  # 8 kg and 0.5 kg m^2 too little: a clear shortfall
