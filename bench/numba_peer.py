"""A Numba peer of ddtrack's batch engine: the same closed loop, batched over robots, timed against ddtrack's.

    python bench/numba_peer.py [--quick] [--sizes 256,1024] [--repeats 3] [--threads 2] [--json]

Both engines simulate the same robots: the paper's line case (``scenarios/paper_line.toml``) with the true plant's
mass, inertia and centre-of-mass offset drawn per seed (``RANDOMIZE``, the spreads of ``scenarios/training.toml``),
through ddtrack's own ``runner.prepare_batch``: the Numba loop takes its per-robot plant parameters, nominal model,
gains, disturbance, initial state and standard-normal draws from ddtrack's prepared batch, and for the NN-adaptive
controller the emulator's initial weights, scales and c_bar too (so both start from the same network). The NN runs
skip identification (``controller.identification=false``), as ``bench/batch.py`` does: each robot starts from its
seed's initial weights, and what is timed is the control loop itself, online training and gain law included.

The loop (docs/model.md §2.7), per robot and control period k, t_k = k T_c:

* reference: the line at constant speed (docs/model.md §2.1);
* measurement y_k = x_k + noise_std * xi_k (docs/model.md §2.7);
* (a) backstepping: posture error (§2.2), Kanayama law (§2.4), its analytic rate and the velocity clamps (§2.5),
  computed torque on the nominal model with the torque limit (§2.5);
  (b) NN-adaptive backstepping (§3, pseudo-code §3.8): one momentum-SGD step of the emulator on the last
  transition with the global gradient-norm clip (§3.7), the Jacobian-driven gain law with its gate, clip and box
  (§3.4 to §3.6), then the same Kanayama command and computed torque;
* plant: the torque saturated at the true robot's limit, the wheel disturbance
  bias + amplitude sin(frequency t + phase) + std xi (§1.2), then ``substeps`` RK4 steps of the reduced
  Lagrangian dynamics with friction (§1.3) under the held torque (zero-order hold);
* status: the divergence and non-finite checks of ``ddtrack.sim.simulate``; a failed robot stops there.

Per robot the Numba loop keeps the final state, the mean tracking error over the metric window (the ``e_tr_mean``
of ``ddtrack.summarize``, paper eq. 35), the status and the failing period; the NN loop also the final gains.

Checks, before any timing: the final states (x_{N-1}, the last recorded row of ``SimResult.state``) and
``e_tr_mean`` must agree with ddtrack's to ``BS_TOLERANCE`` (backstepping) and ``NN_TOLERANCE`` (NN-adaptive)
relative; the script exits with status 1 otherwise.

Timing, all in this one process: ddtrack's ``studies.batches.batch_metrics`` (the path of ``ddtrack mc`` and
``bench/batch.py``: the vmapped simulation sharded over ``--threads`` JAX CPU devices, then the metrics on the host)
and, separately, its jitted simulation alone (the same sharded call without the host metrics); the Numba loop with
``prange`` over robots on ``--threads`` threads. Compile excluded for both (one warm-up call; Numba's JIT compile
time is reported on its own); the median of ``--repeats`` calls. ``--quick`` runs a 10 s horizon on a batch of 16.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from functools import partial
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "scenarios" / "paper_line.toml"
RANDOMIZE = [  # per-robot plant draws, the spreads of scenarios/training.toml
    'randomize.mass = { distribution = "uniform", relative = 0.2 }',
    'randomize.inertia = { distribution = "uniform", relative = 0.25 }',
    'randomize.com_offset = { distribution = "uniform", absolute = 0.04 }',
]
KINDS = {"backstepping": [], "nn_adaptive_backstepping": ["controller.identification=false"]}
QUICK = ["simulation.duration = 10.0", "simulation.metric_window = [5.0, 10.0]"]
BS_TOLERANCE = 1e-9
NN_TOLERANCE = 1e-9

# columns of the per-robot parameter matrix handed to the Numba kernels
ROBOT_FIELDS = (
    "mass",
    "inertia",
    "com_offset",
    "wheel_radius",
    "half_axle",
    "viscous_friction",
    "coulomb_friction",
    "friction_smoothing",
    "max_torque",
)
P0 = 0  # true plant: columns P0 .. P0 + 8 in ROBOT_FIELDS order
N0 = 9  # nominal model: columns N0 .. N0 + 8
KX, KY, KTH, KCV, KCW, VMAX, WMAX = 18, 19, 20, 21, 22, 23, 24
D_BIAS, D_AMP, D_FREQ, D_PHASE, D_STD = 25, 27, 29, 30, 32  # disturbance: (2,), (2,), scalar, (2,), (2,)
NOISE = 34  # (5,) measurement noise std
L_SX, L_SY, L_HEADING, L_SPEED = 39, 40, 41, 42  # the line
N_COLUMNS = 43
# the NN-adaptive law's settings (a second matrix, same per-robot layout)
A_GAINS0, A_RATES, A_MAX_STEP, A_GMIN, A_GMAX, A_GAMMA = 0, 3, 6, 9, 12, 15  # each (3,)
A_SZ, A_SY = 18, 22  # emulator scales s_z (4,), s_y (3,)
A_MOMENTUM_K, A_GATE, A_LEAK, A_LR, A_MOMENTUM, A_CLIP, A_FREEZE, A_CBAR = 25, 26, 27, 28, 29, 30, 31, 32
N_ADAPTIVE = 33


# --- the kernels (Numba) ------------------------------------------------------------------------------------------


def build_kernels():
    """Compile-on-first-call kernels; imported here so that ``--help`` needs no Numba."""
    import numba
    from numba import njit, prange

    @njit(error_model="numpy")
    def wrap(angle):
        """(-pi, pi], as ddtrack.geometry.wrap_angle (docs/model.md §0)."""
        w = (angle + np.pi) % (2.0 * np.pi) - np.pi
        return np.pi if w == -np.pi else w

    @njit(error_model="numpy")
    def posture_error(x, y, th, xr, yr, thr):
        """Kanayama e_p = T_e(theta) (q_r - q), e_theta wrapped (docs/model.md §2.2)."""
        c, s = np.cos(th), np.sin(th)
        dx, dy = xr - x, yr - y
        return c * dx + s * dy, -s * dx + c * dy, wrap(thr - th)

    @njit(error_model="numpy")
    def friction(bw, tc, eps, phi_dot):
        """tau_f = b_w phi_dot + tau_c tanh(phi_dot / eps_f) (docs/model.md §1.2)."""
        return bw * phi_dot + tc * np.tanh(phi_dot / eps)

    @njit(error_model="numpy")
    def derivative(th, v, w, held):
        """X_dot of the reduced Lagrangian dynamics in (v, omega) (docs/model.md §1.3). ``held`` = (tau_R, tau_L,
        d_R, d_L, m, I_A, m d, R, L, b_w, tau_c, eps_f): torques held over the period, disturbance torques
        opposing the drive, and the true plant."""
        tau_r, tau_l, d_r, d_l, m, ia, md, r, half, bw, tc, eps = held
        net_r = tau_r - friction(bw, tc, eps, (v + half * w) / r) - d_r
        net_l = tau_l - friction(bw, tc, eps, (v - half * w) / r) - d_l
        inv_r, l_r = 1.0 / r, half / r
        drive_v = inv_r * net_r + inv_r * net_l
        drive_w = l_r * net_r + (-l_r) * net_l
        v_dot = (drive_v - (-md * (w * w))) / m
        w_dot = (drive_w - md * w * v) / ia
        return v * np.cos(th), v * np.sin(th), w, v_dot, w_dot

    @njit(error_model="numpy")
    def plant_period(p, x, tau_r, tau_l, d_r, d_l, period, substeps):
        """``substeps`` RK4 steps over one control period under the held torque and disturbance (§2.7)."""
        m, inertia, d, r, half = p[P0], p[P0 + 1], p[P0 + 2], p[P0 + 3], p[P0 + 4]
        held = (tau_r, tau_l, d_r, d_l, m, inertia + m * d**2, m * d, r, half, p[P0 + 5], p[P0 + 6], p[P0 + 7])
        x0, x1, x2, x3, x4 = x[0], x[1], x[2], x[3], x[4]
        h = period / substeps
        for _ in range(substeps):
            a0, a1, a2, a3, a4 = derivative(x2, x3, x4, held)
            b0, b1, b2, b3, b4 = derivative(x2 + 0.5 * h * a2, x3 + 0.5 * h * a3, x4 + 0.5 * h * a4, held)
            c0, c1, c2, c3, c4 = derivative(x2 + 0.5 * h * b2, x3 + 0.5 * h * b3, x4 + 0.5 * h * b4, held)
            e0, e1, e2, e3, e4 = derivative(x2 + h * c2, x3 + h * c3, x4 + h * c4, held)
            g = h / 6.0
            x0 = x0 + g * (a0 + 2.0 * b0 + 2.0 * c0 + e0)
            x1 = x1 + g * (a1 + 2.0 * b1 + 2.0 * c1 + e1)
            x2 = x2 + g * (a2 + 2.0 * b2 + 2.0 * c2 + e2)
            x3 = x3 + g * (a3 + 2.0 * b3 + 2.0 * c3 + e3)
            x4 = x4 + g * (a4 + 2.0 * b4 + 2.0 * c4 + e4)
        return x0, x1, x2, x3, x4

    @njit(error_model="numpy")
    def reference(p, t):
        """The line's reference at t: position, heading, speed; omega_r and the rates are 0 (docs/model.md §2.1)."""
        ch, sh, speed = np.cos(p[L_HEADING]), np.sin(p[L_HEADING]), p[L_SPEED]
        st = speed * t
        vx, vy = speed * ch, speed * sh
        return p[L_SX] + st * ch, p[L_SY] + st * sh, wrap(np.arctan2(vy, vx)), np.hypot(vx, vy)

    @njit(error_model="numpy")
    def kanayama(e_x, e_y, e_th, v, w, v_r, kx, ky, kth, vmax, wmax):
        """Kanayama command (docs/model.md §2.4), its analytic rate with the measured nu and the clamps (§2.5);
        omega_r, v_r_dot and omega_r_dot are 0 on the line. Returns v_c, w_c, v_c_dot, w_c_dot, saturated."""
        ce, se = np.cos(e_th), np.sin(e_th)
        v_c = v_r * ce + kx * e_x
        w_c = 0.0 + v_r * (ky * e_y + kth * se)
        de_x = w * e_y - v + v_r * ce  # error dynamics, docs/model.md §2.3
        de_y = -w * e_x + v_r * se
        de_th = 0.0 - w
        v_c_dot = 0.0 * ce - v_r * se * de_th + kx * de_x
        w_c_dot = 0.0 + 0.0 * (ky * e_y + kth * se) + v_r * (ky * de_y + kth * ce * de_th)
        saturated = 0.0
        if abs(v_c) > vmax:
            v_c, v_c_dot, saturated = min(max(v_c, -vmax), vmax), 0.0, 1.0
        if abs(w_c) > wmax:
            w_c, w_c_dot, saturated = min(max(w_c, -wmax), wmax), 0.0, 1.0
        return v_c, w_c, v_c_dot, w_c_dot, saturated

    @njit(error_model="numpy")
    def computed_torque(p, v, w, v_c, w_c, v_c_dot, w_c_dot):
        """tau = B_bar^-1 (M_hat u + V_hat(nu) nu) + tau_f_hat, u = nu_c_dot + K_c (nu_c - nu), saturated at the
        nominal limit (docs/model.md §2.5). Returns tau_r, tau_l, saturated."""
        m, inertia, d, r, half = p[N0], p[N0 + 1], p[N0 + 2], p[N0 + 3], p[N0 + 4]
        bw, tc, eps, limit = p[N0 + 5], p[N0 + 6], p[N0 + 7], p[N0 + 8]
        ia, md = inertia + m * d**2, m * d
        u_v = v_c_dot + p[KCV] * (v_c - v) + 0.0
        u_w = w_c_dot + p[KCW] * (w_c - w) + 0.0
        force = m * u_v + (-md * (w * w))
        moment = ia * u_w + md * w * v
        a, b = r / 2.0, r / 2.0 * (1.0 / half)
        tau_r = a * force + b * moment + friction(bw, tc, eps, (v + half * w) / r)
        tau_l = a * force + (-b) * moment + friction(bw, tc, eps, (v - half * w) / r)
        saturated = 1.0 if (abs(tau_r) > limit or abs(tau_l) > limit) else 0.0
        return min(max(tau_r, -limit), limit), min(max(tau_l, -limit), limit), saturated

    @njit(error_model="numpy")
    def close_period(p, x, k, t, tau_r, tau_l, xi_d, period, substeps, e_tr, div_err, div_speed):
        """Plant saturation, disturbance and RK4 (docs/model.md §2.7), then the status of the period as
        ddtrack.sim.period_status gives it (0 ok, 1 diverged, 2 non-finite). Advances ``x`` in place when ok."""
        limit = p[P0 + 8]
        tau_r, tau_l = min(max(tau_r, -limit), limit), min(max(tau_l, -limit), limit)
        d_r = p[D_BIAS] + p[D_AMP] * np.sin(p[D_FREQ] * t + p[D_PHASE]) + p[D_STD] * xi_d[k, 0]
        d_l = p[D_BIAS + 1] + p[D_AMP + 1] * np.sin(p[D_FREQ] * t + p[D_PHASE + 1]) + p[D_STD + 1] * xi_d[k, 1]
        n0, n1, n2, n3, n4 = plant_period(p, x, tau_r, tau_l, d_r, d_l, period, substeps)
        finite = np.isfinite(n0) and np.isfinite(n1) and np.isfinite(n2) and np.isfinite(n3) and np.isfinite(n4)
        finite = finite and np.isfinite(tau_r) and np.isfinite(tau_l)
        if not finite:
            return 2
        if e_tr > div_err or abs(x[3]) > div_speed or abs(x[4]) > div_speed:
            return 1
        x[0], x[1], x[2], x[3], x[4] = n0, n1, n2, n3, n4
        return 0

    @njit(error_model="numpy")
    def backstepping_robot(p, x, xi_d, xi_n, n_steps, period, substeps, k0, k1, div_err, div_speed, out):
        """One robot's run of backstepping over computed torque; ``x`` (5,) starts at x_0 and ends at the final
        state. ``out`` (8,): final state, e_tr_mean over periods k0 .. k1 - 1, status, failing period (-1: none)."""
        total, status, failure = 0.0, 0, -1
        for k in range(n_steps):
            t = k * period
            xr, yr, thr, v_r = reference(p, t)
            e_x, e_y, _ = posture_error(x[0], x[1], x[2], xr, yr, thr)  # true error (metrics, status)
            e_tr = np.hypot(e_x, e_y)
            if k0 <= k < k1:
                total += e_tr
            y0 = x[0] + p[NOISE] * xi_n[k, 0]
            y1 = x[1] + p[NOISE + 1] * xi_n[k, 1]
            y2 = x[2] + p[NOISE + 2] * xi_n[k, 2]
            y3 = x[3] + p[NOISE + 3] * xi_n[k, 3]
            y4 = x[4] + p[NOISE + 4] * xi_n[k, 4]
            m_x, m_y, m_th = posture_error(y0, y1, y2, xr, yr, thr)
            v_c, w_c, v_c_dot, w_c_dot, _ = kanayama(
                m_x, m_y, m_th, y3, y4, v_r, p[KX], p[KY], p[KTH], p[VMAX], p[WMAX]
            )
            tau_r, tau_l, _ = computed_torque(p, y3, y4, v_c, w_c, v_c_dot, w_c_dot)
            status = close_period(p, x, k, t, tau_r, tau_l, xi_d, period, substeps, e_tr, div_err, div_speed)
            if status != 0:
                failure = k
                break
        out[0:5] = x
        out[5] = total / max(k1 - k0, 1)
        out[6] = status
        out[7] = failure

    @njit(parallel=True, error_model="numpy")
    def run_backstepping(robots, x0, xi_d, xi_n, n_steps, period, substeps, k0, k1, div_err, div_speed, out):
        """Backstepping for every robot, robots split over the threads (prange); ``out`` (N, 8)."""
        for i in prange(robots.shape[0]):
            x = x0[i].copy()
            backstepping_robot(
                robots[i], x, xi_d[i], xi_n[i], n_steps, period, substeps, k0, k1, div_err, div_speed, out[i]
            )

    @njit(error_model="numpy")
    def pairwise_total(buffer, n):
        """Sum of buffer[:n] by halves added elementwise, an odd last term carried up: ddtrack._ordered.total's
        order, so that the gradient norm rounds as ddtrack's does. Overwrites the buffer."""
        while n > 1:
            half = n // 2
            for j in range(half):
                buffer[j] = buffer[j] + buffer[half + j]
            if n % 2 == 1:
                buffer[half] = buffer[2 * half]
            n = half + n % 2
        return buffer[0]

    @njit(error_model="numpy")
    def emulator_step(a, w1, b1, w2, b2, v1, c1, v2, c2, z, target, hidden, delta1, delta2, squares):
        """One backpropagation step on |y~ - y~*|^2 / 2 with the global gradient-norm clip and momentum, in place
        (docs/model.md §3.7): delta_2 = y~ - y~*, delta_1 = (W2^T delta_2)(1 - h^2), dW = -eta clip(grad) + beta dW."""
        n_h, n_in = w1.shape
        for j in range(n_h):
            s = 0.0
            for q in range(n_in):
                s += w1[j, q] * z[q]
            hidden[j] = np.tanh(s + b1[j])
        for o in range(3):
            s = 0.0
            for j in range(n_h):
                s += w2[o, j] * hidden[j]
            delta2[o] = s + b2[o] - target[o]
        for j in range(n_h):
            s = 0.0
            for o in range(3):
                s += w2[o, j] * delta2[o]
            delta1[j] = s * (1.0 - hidden[j] ** 2)
        n = 0  # the squared gradient, leaves in the MLP's field order w1, b1, w2, b2, each row-major
        for j in range(n_h):
            for q in range(n_in):
                squares[n] = (delta1[j] * z[q]) ** 2
                n += 1
        for j in range(n_h):
            squares[n] = delta1[j] ** 2
            n += 1
        for o in range(3):
            for j in range(n_h):
                squares[n] = (delta2[o] * hidden[j]) ** 2
                n += 1
        for o in range(3):
            squares[n] = delta2[o] ** 2
            n += 1
        norm = np.sqrt(pairwise_total(squares, n))
        coefficient = -a[A_LR] * min(1.0, a[A_CLIP] / max(norm, 1e-300))
        beta = a[A_MOMENTUM]
        for j in range(n_h):
            for q in range(n_in):
                v1[j, q] = coefficient * (delta1[j] * z[q]) + beta * v1[j, q]
                w1[j, q] += v1[j, q]
            c1[j] = coefficient * delta1[j] + beta * c1[j]
            b1[j] += c1[j]
        for o in range(3):
            for j in range(n_h):
                v2[o, j] = coefficient * (delta2[o] * hidden[j]) + beta * v2[o, j]
                w2[o, j] += v2[o, j]
            c2[o] = coefficient * delta2[o] + beta * c2[o]
            b2[o] += c2[o]

    @njit(error_model="numpy")
    def emulator_jacobian(a, w1, b1, w2, z, hidden, jac):
        """J_b^n = d y / d(v_c, omega_c) / c_bar = diag(s_y) W2 diag(1 - h^2) W1 diag(1/s_z), first two columns,
        over c_bar (paper eq. 34 corrected, docs/model.md §3.4, §3.7). ``z`` is normalised; ``jac`` (3, 2)."""
        n_h, n_in = w1.shape
        for j in range(n_h):
            s = 0.0
            for q in range(n_in):
                s += w1[j, q] * z[q]
            h = np.tanh(s + b1[j])
            hidden[j] = 1.0 - h**2
        for o in range(3):
            for q in range(2):
                s = 0.0
                for j in range(n_h):
                    s += (a[A_SY + o] * w2[o, j]) * (hidden[j] * w1[j, q])
                jac[o, q] = s / a[A_SZ + q] / a[A_CBAR]

    @njit(error_model="numpy")
    def nn_adaptive_robot(
        p, a, x, xi_d, xi_n, W1, B1, W2, B2, n_steps, period, substeps, k0, k1, div_err, div_speed, out
    ):
        """One robot's run of NN-adaptive backstepping over computed torque (docs/model.md §3.8). The weights
        (W1, B1, W2, B2) start as the initial network and are trained in place. ``out`` (11,): final state,
        e_tr_mean, status, failing period, final gains."""
        n_h, n_in = W1.shape
        V1, C1, V2, C2 = np.zeros_like(W1), np.zeros_like(B1), np.zeros_like(W2), np.zeros_like(B2)
        hidden, delta1 = np.empty(n_h), np.empty(n_h)
        delta2, target, z = np.empty(3), np.empty(3), np.empty(n_in)
        squares = np.empty(n_h * n_in + n_h + 3 * n_h + 3)
        jac = np.empty((3, 2))
        gains = a[A_GAINS0 : A_GAINS0 + 3].copy()
        last_step, grad = np.zeros(3), np.zeros(3)
        prev_pose, prev_input = np.zeros(3), np.zeros(n_in)
        prev_saturated, started = 0.0, False
        total, status, failure = 0.0, 0, -1
        for k in range(n_steps):
            t = k * period
            xr, yr, thr, v_r = reference(p, t)
            e_x, e_y, _ = posture_error(x[0], x[1], x[2], xr, yr, thr)
            e_tr = np.hypot(e_x, e_y)
            if k0 <= k < k1:
                total += e_tr
            y0 = x[0] + p[NOISE] * xi_n[k, 0]
            y1 = x[1] + p[NOISE + 1] * xi_n[k, 1]
            y2 = x[2] + p[NOISE + 2] * xi_n[k, 2]
            y3 = x[3] + p[NOISE + 3] * xi_n[k, 3]
            y4 = x[4] + p[NOISE + 4] * xi_n[k, 4]
            m_x, m_y, m_th = posture_error(y0, y1, y2, xr, yr, thr)
            usable = started and prev_saturated < 0.5
            if usable:  # learn the last transition (model.md §3.7): target is the body-frame increment
                for q in range(n_in):
                    z[q] = prev_input[q] / a[A_SZ + q]
                b_x, b_y, b_th = posture_error(prev_pose[0], prev_pose[1], prev_pose[2], y0, y1, y2)
                target[0], target[1], target[2] = b_x / a[A_SY], b_y / a[A_SY + 1], b_th / a[A_SY + 2]
                emulator_step(a, W1, B1, W2, B2, V1, C1, V2, C2, z, target, hidden, delta1, delta2, squares)
            gate = usable and np.hypot(m_x, m_y) < a[A_GATE] and t >= a[A_FREEZE]
            if gate:  # the gain law (eqs. 22-26, model.md §3.5, §3.6) with the current gains' clamped command
                v_c0 = v_r * np.cos(m_th) + gains[0] * m_x
                w_c0 = 0.0 + v_r * (gains[1] * m_y + gains[2] * np.sin(m_th))
                z[0] = min(max(v_c0, -p[VMAX]), p[VMAX]) / a[A_SZ]
                z[1] = min(max(w_c0, -p[WMAX]), p[WMAX]) / a[A_SZ + 1]
                z[2], z[3] = y3 / a[A_SZ + 2], y4 / a[A_SZ + 3]
                emulator_jacobian(a, W1, B1, W2, z, hidden, jac)
                g_x, g_y, g_th = a[A_GAMMA] * m_x, a[A_GAMMA + 1] * m_y, a[A_GAMMA + 2] * m_th
                r0, r1, r2 = -g_x, -g_y, g_x * m_y + g_y * (-m_x) + g_th * (-1.0)  # e^T Gamma D_b (§3.3)
                along_v = r0 * jac[0, 0] + r1 * jac[1, 0] + r2 * jac[2, 0]
                along_w = r0 * jac[0, 1] + r1 * jac[1, 1] + r2 * jac[2, 1]
                grad[0] = along_v * m_x  # ... J_b^n Phi, Phi = [[e_x, 0, 0], [0, v_r e_y, v_r sin e_th]]
                grad[1] = along_w * (v_r * m_y)
                grad[2] = along_w * (v_r * np.sin(m_th))
                for j in range(3):
                    change = (
                        -period * a[A_RATES + j] * grad[j]
                        + a[A_MOMENTUM_K] * last_step[j]
                        - period * a[A_LEAK] * (gains[j] - a[A_GAINS0 + j])
                    )
                    last_step[j] = min(max(change, -a[A_MAX_STEP + j]), a[A_MAX_STEP + j])
            else:
                last_step[0], last_step[1], last_step[2] = 0.0, 0.0, 0.0
            for j in range(3):
                gains[j] = min(max(gains[j] + last_step[j], a[A_GMIN + j]), a[A_GMAX + j])
            v_c, w_c, v_c_dot, w_c_dot, clamped = kanayama(
                m_x, m_y, m_th, y3, y4, v_r, gains[0], gains[1], gains[2], p[VMAX], p[WMAX]
            )
            tau_r, tau_l, torque_saturated = computed_torque(p, y3, y4, v_c, w_c, v_c_dot, w_c_dot)
            prev_pose[0], prev_pose[1], prev_pose[2] = y0, y1, y2
            prev_input[0], prev_input[1], prev_input[2], prev_input[3] = v_c, w_c, y3, y4
            prev_saturated, started = max(clamped, torque_saturated), True
            status = close_period(p, x, k, t, tau_r, tau_l, xi_d, period, substeps, e_tr, div_err, div_speed)
            if status != 0:
                failure = k
                break
        out[0:5] = x
        out[5] = total / max(k1 - k0, 1)
        out[6] = status
        out[7] = failure
        out[8:11] = gains

    @njit(parallel=True, error_model="numpy")
    def run_nn_adaptive(
        robots, adaptive, x0, xi_d, xi_n, w1, b1, w2, b2, n_steps, period, substeps, k0, k1, div_err, div_speed, out
    ):
        """NN-adaptive backstepping for every robot, robots split over the threads (prange); ``out`` (N, 11)."""
        for i in prange(robots.shape[0]):
            x = x0[i].copy()
            nn_adaptive_robot(
                robots[i], adaptive[i], x, xi_d[i], xi_n[i], w1[i], b1[i], w2[i], b2[i],
                n_steps, period, substeps, k0, k1, div_err, div_speed, out[i],
            )  # fmt: skip

    return numba, run_backstepping, run_nn_adaptive


# --- ddtrack's batch, as arrays ---------------------------------------------------------------------------------


def load(kind: str, quick: bool):
    import ddtrack

    overrides = RANDOMIZE + KINDS[kind] + (QUICK if quick else [])
    return ddtrack.load_scenario(SCENARIO, overrides=overrides, controller=kind)


def refuse_unsupported(scenario) -> None:
    """The peer implements the line, the computed-torque inner loop and the NN law's default choices only."""
    control = scenario.controller
    problems = []
    if scenario.trajectory.kind != "line":
        problems.append("trajectory.kind other than line")
    if control.inner != "computed_torque" or getattr(control, "strict", False):
        problems.append("an inner loop other than computed_torque, or strict")
    defaults = {"jacobian": "network", "error_jacobian": "exact", "emulator": "E1", "online_learning": True}
    defaults |= {"learn_saturated": False, "structured_jacobian": False}
    problems += [f"controller.{k}" for k, v in defaults.items() if getattr(control, k, v) != v]
    if problems:
        sys.exit("bench/numba_peer.py does not implement: " + ", ".join(problems))


def per_robot(value, n: int, width: int) -> np.ndarray:
    """A batched pytree leaf as (n, width) floats, or (n,) for width 1: a stacked tuple is a tuple of (n,) arrays,
    a stacked array (n, width); a leaf the batch did not stack is broadcast."""
    if isinstance(value, tuple | list):
        return np.stack([np.broadcast_to(np.asarray(v, float), (n,)) for v in value], axis=1)
    a = np.asarray(value, float)
    if width == 1:
        return np.broadcast_to(a, (n,))
    return a if a.ndim == 2 else np.broadcast_to(a, (n, width))


def batch_arrays(scenario, setup, draws) -> dict:
    """ddtrack's prepared batch as the Numba kernels' float64 arrays (one row per robot)."""
    n = int(np.asarray(setup.x0).shape[0])
    robots = np.zeros((n, N_COLUMNS))
    nominal = setup.controller.inner.nominal
    for j, name in enumerate(ROBOT_FIELDS):
        robots[:, P0 + j] = per_robot(getattr(setup.plant_params, name), n, 1)
        robots[:, N0 + j] = per_robot(getattr(nominal, name), n, 1)
    outer = setup.controller.outer
    if hasattr(outer, "kx"):
        robots[:, KX : KX + 3] = np.stack([per_robot(getattr(outer, g), n, 1) for g in ("kx", "ky", "ktheta")], 1)
    else:
        robots[:, KX : KX + 3] = per_robot(outer.gains, n, 3)
    robots[:, KCV : KCV + 2] = per_robot(setup.controller.inner.kc, n, 2)
    robots[:, VMAX] = per_robot(outer.max_velocity, n, 1)
    robots[:, WMAX] = per_robot(outer.max_yaw_rate, n, 1)
    wheel = setup.disturbance
    robots[:, D_BIAS : D_BIAS + 2] = per_robot(wheel.bias, n, 2)
    robots[:, D_AMP : D_AMP + 2] = per_robot(wheel.amplitude, n, 2)
    robots[:, D_FREQ] = per_robot(wheel.frequency, n, 1)
    robots[:, D_PHASE : D_PHASE + 2] = per_robot(wheel.phase, n, 2)
    robots[:, D_STD : D_STD + 2] = per_robot(wheel.std, n, 2)
    robots[:, NOISE : NOISE + 5] = per_robot(setup.noise.std, n, 5)
    line = setup.trajectory
    robots[:, L_SX : L_SX + 2] = per_robot(line.start, n, 2)
    robots[:, L_HEADING] = per_robot(line.heading, n, 1)
    robots[:, L_SPEED] = per_robot(line.speed, n, 1)
    sim = scenario.simulation
    from ddtrack.metrics import window_mask
    from ddtrack.sim.simulate import DIVERGENCE_SPEED

    inside = np.flatnonzero(window_mask(np.arange(sim.n_steps) * sim.control_period, sim.window))
    arrays = {
        "robots": robots,
        "x0": np.ascontiguousarray(np.asarray(setup.x0, float)),
        "xi_d": np.ascontiguousarray(np.asarray(draws.disturbance, float)),
        "xi_n": np.ascontiguousarray(np.asarray(draws.noise, float)),
        "n_steps": sim.n_steps,
        "period": float(sim.control_period),
        "substeps": int(sim.substeps),
        "k0": int(inside[0]),
        "k1": int(inside[-1]) + 1,
        "div_err": float(scenario.divergence_distance()),
        "div_speed": float(DIVERGENCE_SPEED),
    }
    if hasattr(outer, "emulator"):
        adaptive = np.zeros((n, N_ADAPTIVE))
        for column, name in [
            (A_GAINS0, "gains"),
            (A_RATES, "rates"),
            (A_MAX_STEP, "max_step"),
            (A_GMIN, "gain_min"),
            (A_GMAX, "gain_max"),
            (A_GAMMA, "gamma"),
        ]:
            adaptive[:, column : column + 3] = per_robot(getattr(outer, name), n, 3)
        adaptive[:, A_SZ : A_SZ + 4] = per_robot(outer.emulator.scales.inputs, n, 4)
        adaptive[:, A_SY : A_SY + 3] = per_robot(outer.emulator.scales.outputs, n, 3)
        for column, name in [
            (A_MOMENTUM_K, "gain_momentum"),
            (A_GATE, "gate_error"),
            (A_LEAK, "leakage"),
            (A_LR, "learning_rate"),
            (A_MOMENTUM, "momentum"),
            (A_CLIP, "gradient_clip"),
            (A_FREEZE, "freeze_time"),
        ]:
            adaptive[:, column] = per_robot(getattr(outer, name), n, 1)
        adaptive[:, A_CBAR] = per_robot(outer.analytic_coefficients, n, 2)[:, 0]
        mlp = outer.emulator.mlp
        arrays["adaptive"] = adaptive
        arrays["weights"] = tuple(np.ascontiguousarray(np.asarray(w, float)) for w in (mlp.w1, mlp.b1, mlp.w2, mlp.b2))
    return arrays


def numba_call(kernel, kind: str, arrays: dict) -> np.ndarray:
    """One batch through the Numba kernel; a fresh copy of the initial weights each call (they train in place)."""
    a = arrays
    tail = (a["n_steps"], a["period"], a["substeps"], a["k0"], a["k1"], a["div_err"], a["div_speed"])
    if kind == "backstepping":
        out = np.empty((len(a["robots"]), 8))
        kernel(a["robots"], a["x0"], a["xi_d"], a["xi_n"], *tail, out)
        return out
    out = np.empty((len(a["robots"]), 11))
    weights = tuple(w.copy() for w in a["weights"])
    kernel(a["robots"], a["adaptive"], a["x0"], a["xi_d"], a["xi_n"], *weights, *tail, out)
    return out


# --- correctness ----------------------------------------------------------------------------------------------


def relative_difference(a: np.ndarray, b: np.ndarray) -> float:
    """max |a - b| / max(|b|, 1), elementwise over everything compared."""
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1.0)))


def check(kind: str, kernel, scenario, setup, draws, arrays: dict) -> dict:
    """Run both engines on the same robots; compare final states, e_tr_mean, status (and the NN's final gains)."""
    from ddtrack.runner import run_setup
    from ddtrack.studies.batches import batch_metrics

    result = run_setup(scenario, setup, draws, batched=True)
    metrics = batch_metrics(scenario, setup, draws)
    failure = np.asarray(result.failure_index)
    last = np.where(failure < 0, scenario.simulation.n_steps - 1, failure)
    state = np.asarray(result.state)
    rows = np.arange(len(last))
    ours = numba_call(kernel, kind, arrays)
    ddtrack_status = np.asarray(result.status)
    # ddtrack records x_k for k = 0 .. N-1 and freezes a failed run at its failing period: that row is compared
    # with the Numba loop's final x; an ok run's x_N is not recorded by ddtrack, so both compare x_{N-1}.
    report = {"robots": len(last), "statuses_equal": bool(np.array_equal(ours[:, 6], ddtrack_status))}
    ok = ddtrack_status == 0
    if np.any(ok):
        # x_{N-1}: rerun the Numba loop one period short
        shorter = dict(arrays, n_steps=arrays["n_steps"] - 1)
        ours_short = numba_call(kernel, kind, shorter)
        report["final_state_rel"] = relative_difference(ours_short[ok, :5], state[rows[ok], last[ok]])
    mean = np.array([m["e_tr_mean"] if m["e_tr_mean"] is not None else np.nan for m in metrics])
    report["e_tr_mean_rel"] = relative_difference(ours[ok, 5], mean[ok])
    report["e_tr_mean_range"] = [float(np.min(mean[ok])), float(np.max(mean[ok]))]
    if kind != "backstepping":
        gains = np.stack([np.asarray(result.logs[g])[rows, -1] for g in ("kx", "ky", "ktheta")], axis=1)
        report["final_gains_rel"] = relative_difference(ours[ok, 8:11], gains[ok])  # logged after period N-1's law
    tolerance = BS_TOLERANCE if kind == "backstepping" else NN_TOLERANCE
    worst = max(report.get("final_state_rel", 0.0), report["e_tr_mean_rel"], report.get("final_gains_rel", 0.0))
    report["tolerance"] = tolerance
    report["passed"] = bool(report["statuses_equal"] and worst <= tolerance)
    return report


# --- timing ---------------------------------------------------------------------------------------------------


def median_time(call, repeats: int) -> tuple[float, list[float]]:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    return statistics.median(times), times


def time_ddtrack(scenario, setup, draws, repeats: int) -> dict:
    """``studies.batches.batch_metrics`` (simulation split over the devices + host metrics) and the split simulation
    alone."""
    import jax

    from ddtrack.runner import run_length, simulation_args
    from ddtrack.sim.batch import in_shares
    from ddtrack.studies.batches import _metric_series, batch_metrics

    runs = simulation_args(scenario, setup, draws, run_length(scenario))  # padded to the run length, as batch_metrics
    series = partial(_metric_series, n_steps=run_length(scenario))
    simulate_only = lambda: jax.block_until_ready(in_shares(series, *runs))  # noqa: E731  # as batch_metrics
    metrics = lambda: batch_metrics(scenario, setup, draws)  # noqa: E731
    start = time.perf_counter()
    metrics()
    simulate_only()
    first = time.perf_counter() - start
    metrics_s, metrics_all = median_time(metrics, repeats)
    sim_s, sim_all = median_time(simulate_only, repeats)
    return {"first_s": first, "metrics_s": metrics_s, "metrics_all": metrics_all, "sim_s": sim_s, "sim_all": sim_all}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="10 s horizon, a batch of 16, 2 repeats")
    parser.add_argument("--sizes", default=None, help="batch sizes (default 256,1024; --quick 16)")
    parser.add_argument("--repeats", type=int, default=None, help="timed calls per figure (default 3; --quick 2)")
    parser.add_argument("--threads", type=int, default=len(os.sched_getaffinity(0)))
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    sizes = [int(s) for s in (args.sizes or ("16" if args.quick else "256,1024")).split(",")]
    repeats = args.repeats or (2 if args.quick else 3)

    import jax

    jax.config.update("jax_num_cpu_devices", args.threads)  # before JAX's first operation
    import ddtrack

    ddtrack.enable_float64()
    from ddtrack.runner import prepare_batch

    start = time.perf_counter()
    numba, run_backstepping, run_nn_adaptive = build_kernels()
    numba.set_num_threads(args.threads)
    kernels = {"backstepping": run_backstepping, "nn_adaptive_backstepping": run_nn_adaptive}
    report: dict = {
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "python": platform.python_version(),
        "jax": jax.__version__,
        "numba": numba.__version__,
        "numpy": np.__version__,
        "cores": len(os.sched_getaffinity(0)),
        "jax_devices": len(jax.devices()),
        "numba_threads": numba.get_num_threads(),
        "numba_threading_layer": None,
        "load_average_start": list(os.getloadavg()),
        "checks": {},
        "rows": [],
    }
    failed = False
    for kind, kernel in kernels.items():
        scenario = load(kind, args.quick)
        refuse_unsupported(scenario)
        n_steps = scenario.simulation.n_steps
        for size in sizes:
            setup, draws = prepare_batch(scenario, list(range(size)))
            arrays = batch_arrays(scenario, setup, draws)
            start = time.perf_counter()
            numba_call(kernel, kind, arrays)  # the first call compiles (once per kernel)
            first = time.perf_counter() - start
            if size == sizes[0]:
                report[f"numba_compile_and_first_{kind}_s"] = first
                report["numba_threading_layer"] = numba.threading_layer()
                report["checks"][kind] = check(kind, kernel, scenario, setup, draws, arrays)
                failed |= not report["checks"][kind]["passed"]
            call = lambda kernel=kernel, kind=kind, arrays=arrays: numba_call(kernel, kind, arrays)  # noqa: E731
            ours_s, ours_all = median_time(call, repeats)
            theirs = time_ddtrack(scenario, setup, draws, repeats)
            steps = size * n_steps
            report["rows"].append(
                {
                    "controller": kind,
                    "batch": size,
                    "n_steps": n_steps,
                    "numba_s": ours_s,
                    "numba_all": ours_all,
                    "ddtrack_metrics_s": theirs["metrics_s"],
                    "ddtrack_metrics_all": theirs["metrics_all"],
                    "ddtrack_sim_s": theirs["sim_s"],
                    "ddtrack_sim_all": theirs["sim_all"],
                    "ddtrack_compile_and_first_s": theirs["first_s"],
                    "numba_msteps": steps / ours_s / 1e6,
                    "ddtrack_metrics_msteps": steps / theirs["metrics_s"] / 1e6,
                    "ddtrack_sim_msteps": steps / theirs["sim_s"] / 1e6,
                    "ratio_metrics": theirs["metrics_s"] / ours_s,
                    "ratio_sim": theirs["sim_s"] / ours_s,
                }
            )
            print(f"done {kind} batch {size}", file=sys.stderr, flush=True)
    report["load_average_end"] = list(os.getloadavg())
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(
            f"{report['date']}: {report['cores']} cores, JAX {report['jax']} on {report['jax_devices']} CPU devices, "
            f"Numba {report['numba']} on {report['numba_threads']} threads ({report['numba_threading_layer']}); "
            f"load average {report['load_average_start'][0]:.2f} -> {report['load_average_end'][0]:.2f}"
        )
        for kind, result in report["checks"].items():
            figures = ", ".join(f"{k} {v:.2e}" for k, v in result.items() if k.endswith("_rel"))
            print(
                f"check {kind}: {result['robots']} robots, statuses equal {result['statuses_equal']}, {figures} "
                f"(tolerance {result['tolerance']:g}): {'ok' if result['passed'] else 'FAILED'}"
            )
            print(f"  Numba compile + first call: {report[f'numba_compile_and_first_{kind}_s']:.2f} s")
        print(
            "| controller | batch | periods | ddtrack batch_metrics | ddtrack simulation only | Numba "
            "| ratio ddtrack/Numba (batch_metrics) | ratio (simulation only) |"
        )
        print("|---|---|---|---|---|---|---|---|")
        for r in report["rows"]:
            print(
                f"| {r['controller']} | {r['batch']} | {r['n_steps']} "
                f"| {r['ddtrack_metrics_s']:.3f} s ({r['ddtrack_metrics_msteps']:.2f} M/s) "
                f"| {r['ddtrack_sim_s']:.3f} s ({r['ddtrack_sim_msteps']:.2f} M/s) "
                f"| {r['numba_s']:.3f} s ({r['numba_msteps']:.2f} M/s) "
                f"| {r['ratio_metrics']:.2f}x | {r['ratio_sim']:.2f}x |"
            )
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
