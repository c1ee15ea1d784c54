"""The emulator network of the NN-adaptive controller: SPEC 6, items 21-23, and SPEC 3.7.

Jacobian (eq. 34 corrected) and backprop against autodiff and finite differences, the momentum-SGD
step with gradient-norm clipping, the body-frame one-step targets, the fixed I/O scales and the
initialisation.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import central_difference
from jax.flatten_util import ravel_pytree

import ddtrack  # noqa: F401  (float64)
from ddtrack import geometry
from ddtrack.controllers import MLP, Emulator, Scales, emulator_scales, init_mlp, nn
from ddtrack.controllers.nn import forward, zeros_like
from ddtrack.geometry import rotation, wrap_angle

# jitted once per shape: eager op-by-op dispatch would dominate the run time of the loops below
predict = jax.jit(nn.predict)
input_jacobian = jax.jit(nn.input_jacobian)
sample_loss = jax.jit(nn.sample_loss)
backprop = jax.jit(nn.backprop)
momentum_step = jax.jit(nn.momentum_step)
predict_jacfwd = jax.jit(jax.jacfwd(nn.predict, argnums=2))
loss_grad = jax.jit(jax.grad(nn.sample_loss))
body_increment = jax.jit(geometry.body_increment)


def random_mlp(seed: int, n_in: int = 4, n_hidden: int = 20, n_out: int = 3, scale: float = 1.0) -> MLP:
    """Random weights *and* biases (init_mlp's biases are zero, which would hide b1/b2 errors)."""
    k1, k2, k3, k4 = jax.random.split(jax.random.PRNGKey(seed), 4)
    return MLP(
        w1=scale * jax.random.normal(k1, (n_hidden, n_in)),
        b1=scale * jax.random.normal(k2, (n_hidden,)),
        w2=scale * jax.random.normal(k3, (n_out, n_hidden)),
        b2=scale * jax.random.normal(k4, (n_out,)),
    )


def random_scales(rng, n_in: int = 4, n_out: int = 3) -> Scales:
    return Scales(inputs=jnp.asarray(rng.uniform(0.5, 3.0, n_in)), outputs=jnp.asarray(rng.uniform(1e-3, 0.1, n_out)))


def leaves(tree) -> np.ndarray:
    return np.concatenate([np.ravel(np.asarray(x)) for x in jax.tree_util.tree_leaves(tree)])


# --- item 21: input-output Jacobian ----------------------------------------------------------------


@pytest.mark.parametrize("n_in", [4, 2], ids=["E1", "E0"])
def test_input_jacobian_matches_finite_differences_and_jacfwd(n_in):
    rng = np.random.default_rng(21)
    for trial in range(10):
        mlp = random_mlp(100 + trial, n_in=n_in, scale=0.7)
        scales = random_scales(rng, n_in=n_in)
        z = rng.uniform(-2.0, 2.0, n_in)
        jac = np.asarray(input_jacobian(mlp, scales, jnp.asarray(z)))
        assert jac.shape == (3, n_in)
        fd = central_difference(lambda x, mlp=mlp, scales=scales: predict(mlp, scales, jnp.asarray(x)), z, 1e-5)
        # central differences at h = 1e-5: O(h^2) truncation ~1e-10 and rounding ~eps/h ~1e-11, relative
        np.testing.assert_allclose(jac, fd, rtol=1e-6, atol=1e-6 * np.max(np.abs(jac)))
        ad = np.asarray(predict_jacfwd(mlp, scales, jnp.asarray(z)))
        # the same derivative by forward-mode AD: only float64 rounding (a few ulps of the largest entry) differs
        np.testing.assert_allclose(jac, ad, rtol=1e-12, atol=1e-13 * np.max(np.abs(jac)))


def test_input_jacobian_closed_form_in_index_notation():
    """dy_i/dz_j = s_y,i sum_l W2_il (1 - h_l^2) W1_lj / s_z,j (SPEC 3.7), written out with explicit sums."""
    rng = np.random.default_rng(210)
    mlp, scales = random_mlp(7, scale=0.5), random_scales(rng)
    z = rng.uniform(-1.0, 1.0, 4)
    w1, b1, w2 = (np.asarray(a) for a in (mlp.w1, mlp.b1, mlp.w2))
    sz, sy = np.asarray(scales.inputs), np.asarray(scales.outputs)
    h = np.tanh(w1 @ (z / sz) + b1)
    expected = np.array(
        [
            [sy[i] * sum(w2[i, k] * (1 - h[k] ** 2) * w1[k, j] for k in range(20)) / sz[j] for j in range(4)]
            for i in range(3)
        ]
    )
    # the same sums in another order: rounding only
    np.testing.assert_allclose(input_jacobian(mlp, scales, jnp.asarray(z)), expected, rtol=1e-12, atol=1e-16)


# --- item 21: backprop --------------------------------------------------------------------------------


def test_backprop_matches_autodiff_and_finite_differences():
    rng = np.random.default_rng(211)
    for trial in range(5):
        mlp = random_mlp(200 + trial, scale=0.5)
        z, target = jnp.asarray(rng.uniform(-1.5, 1.5, 4)), jnp.asarray(rng.uniform(-1.0, 1.0, 3))
        grad = backprop(mlp, z, target)
        auto = loss_grad(mlp, z, target)
        for name in ("w1", "b1", "w2", "b2"):
            ours, theirs = np.asarray(getattr(grad, name)), np.asarray(getattr(auto, name))
            assert ours.shape == np.asarray(getattr(mlp, name)).shape
            # closed form vs reverse-mode AD of the same loss: float64 rounding only
            np.testing.assert_allclose(ours, theirs, rtol=1e-12, atol=1e-14)
        # finite differences of E in every weight, through the flattened parameter vector
        flat, unravel = ravel_pytree(mlp)

        def loss(p, unravel=unravel, z=z, target=target):
            return float(sample_loss(unravel(jnp.asarray(p)), z, target))

        fd = central_difference(loss, np.asarray(flat), 1e-6)
        ours = np.asarray(ravel_pytree(grad)[0])
        # h = 1e-6 on a loss of O(1): truncation ~1e-12, rounding ~eps/h ~1e-10; SPEC 6.21 asks 1e-6
        np.testing.assert_allclose(ours, fd, rtol=1e-6, atol=1e-6 * np.max(np.abs(ours)))


# --- item 22: the momentum-SGD step -----------------------------------------------------------------


def test_small_sgd_step_lowers_the_sample_loss_by_eta_grad_squared():
    rng = np.random.default_rng(22)
    for trial in range(5):
        mlp = random_mlp(300 + trial, scale=0.5)
        z, target = jnp.asarray(rng.uniform(-1.0, 1.0, 4)), jnp.asarray(rng.uniform(-1.0, 1.0, 3))
        grad = backprop(mlp, z, target)
        eta = 1e-4
        new, velocity = momentum_step(mlp, zeros_like(mlp), grad, learning_rate=eta, momentum=0.3, clip_norm=1e6)
        before, after = float(sample_loss(mlp, z, target)), float(sample_loss(new, z, target))
        assert after < before
        # first order: E drops by eta |grad|^2, up to an O(eta^2 |grad|^2 |Hessian|) remainder of a few %
        predicted = eta * float(np.sum(leaves(grad) ** 2))
        assert (before - after) == pytest.approx(predicted, rel=0.05)
        # with no previous velocity the step is exactly -eta * grad
        np.testing.assert_allclose(leaves(velocity), -eta * leaves(grad), rtol=1e-15, atol=0)
        np.testing.assert_allclose(leaves(new), leaves(mlp) + leaves(velocity), rtol=1e-15, atol=0)


def test_gradient_norm_clipping_caps_the_step():
    mlp = random_mlp(400)
    huge = jax.tree_util.tree_map(lambda w: 1e6 * w, random_mlp(401))
    eta, clip = 0.2, 5.0
    _, velocity = momentum_step(mlp, zeros_like(mlp), huge, learning_rate=eta, momentum=0.3, clip_norm=clip)
    v = leaves(velocity)
    # the clipped step has norm eta * clip_norm exactly, up to rounding of the norm (a few ulps)
    assert np.linalg.norm(v) == pytest.approx(eta * clip, rel=1e-12)
    # and points along -grad (a rescaling, not a per-entry clip)
    g = leaves(huge)
    np.testing.assert_allclose(v, -eta * clip * g / np.linalg.norm(g), rtol=1e-12, atol=1e-15)
    # a gradient just below the clip norm is not rescaled
    small = jax.tree_util.tree_map(lambda w: 0.99 * clip * w / np.linalg.norm(g), huge)
    _, velocity = momentum_step(mlp, zeros_like(mlp), small, learning_rate=eta, momentum=0.3, clip_norm=clip)
    np.testing.assert_allclose(leaves(velocity), -eta * leaves(small), rtol=1e-15, atol=0)


def test_momentum_accumulates_over_two_steps():
    """dW(k) = -eta grad(k) + beta dW(k-1), W <- W + dW (SPEC 3.7), two steps by hand."""
    eta, beta = 0.2, 0.3
    w0 = random_mlp(500, scale=0.5)
    rng = np.random.default_rng(223)
    z1, t1 = jnp.asarray(rng.uniform(-1, 1, 4)), jnp.asarray(rng.uniform(-1, 1, 3))
    z2, t2 = jnp.asarray(rng.uniform(-1, 1, 4)), jnp.asarray(rng.uniform(-1, 1, 3))
    g1 = backprop(w0, z1, t1)
    w1, v1 = momentum_step(w0, zeros_like(w0), g1, learning_rate=eta, momentum=beta, clip_norm=1e9)
    g2 = backprop(w1, z2, t2)
    w2, v2 = momentum_step(w1, v1, g2, learning_rate=eta, momentum=beta, clip_norm=1e9)
    hand_v1 = -eta * leaves(g1)
    hand_v2 = -eta * leaves(g2) + beta * hand_v1
    # the same three multiply-adds per entry as the package: agreement to rounding
    np.testing.assert_allclose(leaves(v1), hand_v1, rtol=1e-14, atol=1e-16)
    np.testing.assert_allclose(leaves(v2), hand_v2, rtol=1e-14, atol=1e-16)
    np.testing.assert_allclose(leaves(w2), leaves(w0) + hand_v1 + hand_v2, rtol=1e-14, atol=1e-15)
    # the momentum term is really there: without it the second step differs by beta * v1
    assert np.max(np.abs(leaves(v2) + eta * leaves(g2))) > 1e-3


def test_clip_uses_the_global_norm_and_momentum_is_not_clipped():
    """The clip acts on the gradient (all arrays together), before the momentum term is added."""
    mlp = random_mlp(600)
    grad = jax.tree_util.tree_map(lambda w: 1e3 * w, random_mlp(601))
    previous = jax.tree_util.tree_map(lambda w: 10.0 * w, random_mlp(602))
    eta, beta, clip = 0.2, 0.3, 5.0
    _, velocity = momentum_step(mlp, previous, grad, learning_rate=eta, momentum=beta, clip_norm=clip)
    g = leaves(grad)
    expected = -eta * clip * g / np.linalg.norm(g) + beta * leaves(previous)
    # rounding of the norm only
    np.testing.assert_allclose(leaves(velocity), expected, rtol=1e-12, atol=1e-14)


# --- item 23: body-frame targets ----------------------------------------------------------------------


def test_translation_along_the_heading_is_forward_only():
    rng = np.random.default_rng(23)
    thetas = np.r_[rng.uniform(-np.pi, np.pi, 50), np.pi, -np.pi + 1e-12, 0.0, np.pi / 2, -np.pi / 2]
    for theta in thetas:
        pose = np.array([rng.uniform(-20, 20), rng.uniform(-20, 20), theta])
        distance = rng.uniform(1e-4, 0.05)
        nxt = pose + np.array([distance * np.cos(theta), distance * np.sin(theta), 0.0])
        inc = np.asarray(body_increment(jnp.asarray(pose), jnp.asarray(nxt)))
        # positions of O(20) m: the subtraction x' - x loses ~eps * 20 ~ 4e-15 m
        np.testing.assert_allclose(inc, [distance, 0.0, 0.0], rtol=0, atol=1e-13)


@pytest.mark.parametrize(
    ("theta", "d_theta"),
    [
        (0.3, 0.02),
        (-1.0, -0.03),
        (np.pi - 0.01, 0.03),  # crosses +pi: the next heading is stored as about -pi + 0.02
        (-np.pi + 0.01, -0.03),  # crosses -pi
        (np.pi, 0.01),
        (np.pi, -0.01),
    ],
)
def test_pure_rotation_gives_the_wrapped_heading_change(theta, d_theta):
    pose = np.array([1.5, -2.0, theta])
    for stored in (theta + d_theta, float(wrap_angle(theta + d_theta))):  # unwrapped and wrapped storage
        inc = np.asarray(body_increment(jnp.asarray(pose), jnp.asarray([1.5, -2.0, stored])))
        # wrapping adds/subtracts 2 pi: an absolute rounding of a few eps * 2 pi
        np.testing.assert_allclose(inc, [0.0, 0.0, d_theta], rtol=0, atol=1e-14)


def test_body_increment_inverts_the_emulator_prediction():
    """q(k+1) = q(k) + R_3(theta_k) y  <=>  body_increment(q(k), q(k+1)) = y (SPEC 3.7, E1)."""
    rng = np.random.default_rng(230)
    for _ in range(50):
        pose = np.array([rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(-np.pi, np.pi)])
        y = np.array([rng.uniform(-0.02, 0.02), rng.uniform(-1e-3, 1e-3), rng.uniform(-0.05, 0.05)])
        nxt = pose + np.asarray(rotation(jnp.asarray(pose[2]))) @ y
        # rotation and back: rounding of O(5) m coordinates
        np.testing.assert_allclose(body_increment(jnp.asarray(pose), jnp.asarray(nxt)), y, rtol=0, atol=1e-14)


def test_body_increment_lateral_sign():
    """A step to the robot's left is a positive lateral increment (body y-axis CCW of the heading)."""
    theta = 2.0
    pose = np.array([0.0, 0.0, theta])
    left = np.array([-np.sin(theta) * 0.01, np.cos(theta) * 0.01, theta])
    # rounding only
    np.testing.assert_allclose(body_increment(jnp.asarray(pose), jnp.asarray(left)), [0.0, 0.01, 0.0], atol=1e-16)


# --- SPEC 3.7: fixed scales, the emulator's input, initialisation ----------------------------------------


def test_emulator_scales_e1_and_e0():
    tc = 0.01
    e1 = emulator_scales(tc, uses_velocity=True)
    # s_z = [v_max, w_max, v_max, w_max] = [1, 2, 1, 2]; s_y = [T_c v_max, 0.05 T_c v_max, T_c w_max]; one rounding
    np.testing.assert_allclose(e1.inputs, [1.0, 2.0, 1.0, 2.0], rtol=1e-15)
    np.testing.assert_allclose(e1.outputs, [0.01, 5e-4, 0.02], rtol=1e-15)
    e0 = emulator_scales(tc, uses_velocity=False)
    np.testing.assert_allclose(e0.inputs, [1.0, 2.0], rtol=1e-15)
    np.testing.assert_allclose(e0.outputs, [0.01, 5e-4, 0.02], rtol=1e-15)
    other = emulator_scales(0.02, uses_velocity=True, max_velocity=1.5, max_yaw_rate=3.0)
    np.testing.assert_allclose(other.inputs, [1.5, 3.0, 1.5, 3.0], rtol=1e-15)
    np.testing.assert_allclose(other.outputs, [0.03, 0.0015, 0.06], rtol=1e-15)


def test_emulator_inputs_e1_and_e0():
    nu_c, nu = jnp.asarray([0.4, -0.2]), jnp.asarray([0.38, -0.1])
    mlp = init_mlp(jax.random.PRNGKey(0), 4, 20, 3)
    e1 = Emulator(mlp, emulator_scales(0.01, uses_velocity=True), True)
    e0 = Emulator(init_mlp(jax.random.PRNGKey(0), 2, 20, 3), emulator_scales(0.01, uses_velocity=False), False)
    np.testing.assert_array_equal(e1.inputs(nu_c, nu), [0.4, -0.2, 0.38, -0.1])
    np.testing.assert_array_equal(e0.inputs(nu_c, nu), [0.4, -0.2])


@pytest.mark.parametrize(("n_in", "n_hidden"), [(4, 20), (2, 20), (4, 7)])
def test_init_mlp_bounds_shapes_and_determinism(n_in, n_hidden):
    mlp = init_mlp(jax.random.PRNGKey(3), n_in, n_hidden, 3)
    assert mlp.w1.shape == (n_hidden, n_in) and mlp.b1.shape == (n_hidden,)
    assert mlp.w2.shape == (3, n_hidden) and mlp.b2.shape == (3,)
    assert mlp.w1.dtype == jnp.float64
    w1, w2 = np.abs(np.asarray(mlp.w1)), np.abs(np.asarray(mlp.w2))
    assert np.all(w1 <= 1 / np.sqrt(n_in)) and np.all(w2 <= 1 / np.sqrt(n_hidden))
    # U(-1, 1)/sqrt(n): with >= 21 draws the largest |w| exceeds 0.6/sqrt(n) unless P < 0.4^21 ~ 4e-9
    assert w1.max() > 0.6 / np.sqrt(n_in) and w2.max() > 0.6 / np.sqrt(n_hidden)
    # both signs occur (uniform on a symmetric interval)
    assert np.asarray(mlp.w1).min() < 0 < np.asarray(mlp.w1).max()
    np.testing.assert_array_equal(mlp.b1, 0.0)
    np.testing.assert_array_equal(mlp.b2, 0.0)
    again = init_mlp(jax.random.PRNGKey(3), n_in, n_hidden, 3)
    np.testing.assert_array_equal(leaves(again), leaves(mlp))
    other = init_mlp(jax.random.PRNGKey(4), n_in, n_hidden, 3)
    assert not np.array_equal(np.asarray(other.w1), np.asarray(mlp.w1))
    # W1 and W2 come from different sub-keys (not the same stream rescaled)
    unit_w1 = np.asarray(mlp.w1).ravel()[:3] * np.sqrt(n_in)
    unit_w2 = np.asarray(mlp.w2).ravel()[:3] * np.sqrt(n_hidden)
    assert not np.allclose(unit_w1, unit_w2)


def test_forward_is_tanh_hidden_linear_output():
    """y~ = W2 tanh(W1 z~ + b1) + b2 and y = s_y * y~(z / s_z) (SPEC 3.7)."""
    rng = np.random.default_rng(37)
    mlp, scales = random_mlp(700, scale=0.8), random_scales(rng)
    z = rng.uniform(-1, 1, 4)
    w1, b1, w2, b2 = (np.asarray(a) for a in (mlp.w1, mlp.b1, mlp.w2, mlp.b2))
    h = np.tanh(w1 @ (z / np.asarray(scales.inputs)) + b1)
    out, hidden = forward(mlp, jnp.asarray(z / np.asarray(scales.inputs)))
    # same operations in numpy: rounding only
    np.testing.assert_allclose(hidden, h, rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(out, w2 @ h + b2, rtol=1e-13, atol=1e-14)
    np.testing.assert_allclose(
        predict(mlp, scales, jnp.asarray(z)), np.asarray(scales.outputs) * (w2 @ h + b2), rtol=1e-13, atol=1e-16
    )
    target = rng.uniform(-1, 1, 3)
    loss = float(sample_loss(mlp, jnp.asarray(z / np.asarray(scales.inputs)), jnp.asarray(target)))
    assert loss == pytest.approx(0.5 * np.sum((w2 @ h + b2 - target) ** 2), rel=1e-13)
