"""The fitting engine shared by every model ``ddtrack identify`` fits (docs/identification.md).

A model here maps a parameter vector, the body speeds (v, omega) and a two-channel input (velocity commands, or
wheel torques) to the speeds' rates, and is linear in its parameters once the rates are known. For each input
delay tried (whole samples), an equation-error fit (linear least squares on Savitzky-Golay smoothed speeds and
derivatives) starts an output-error fit: the fitted record cut into windows of ``WINDOW`` seconds, each simulated
under the logged inputs (held between samples, RK4) from its own free initial speeds (multiple shooting: a slowly
varying disturbance the model lacks cannot accumulate over the whole record), Levenberg-Marquardt on the
residuals' exact Jacobian (``jax.jacfwd`` through each window's simulation, the windows' starts eliminated from
the normal equations), each channel weighted by its own residual spread. The measured speeds are read either as
instants or as means over each sample interval (odometry's encoder increments); the delay and reading with the
smallest residual win. Standard errors come from the Gauss-Newton covariance s^2 (J^T J)^-1, the windows' starts
counted as fitted; the last quarter of the log is held out and predicted by one simulation from the last fitted sample.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from scipy.signal import savgol_filter

from ..errors import ConfigError
from ..integrators import rk4_step

HELD_OUT = 0.25  #: the last quarter of the log is not fitted: it tells how well the model predicts
SUBSTEPS = 4  #: RK4 steps per sample interval at least (a lag of 5 samples is integrated to 1e-6)
MAX_SUBSTEPS = 64
#: the largest |rate Jacobian eigenvalue| x RK4 step allowed: Coulomb friction's tanh corner is stiff at rest (a
#: small robot's 1/eps_f slope reaches 1600 1/s), and beyond RK4's stability (2.79) the tangents of jacfwd blow up
STIFF_STEP = 0.5
MIN_SAMPLES = 80
#: [s] output-error window: 7 of the slowest lag we fit (0.3 s), so most of it answers commands, not its free start
WINDOW = 2.0


@dataclass(frozen=True)
class SpeedLog:
    """A log of a robot: at each measurement time ``t`` [s] (increasing), the input in force until the next sample
    (velocity commands (v* [m/s], omega* [rad/s]), or wheel torques (tau_r, tau_l) [N m]) and the measured speeds
    (v [m/s], omega [rad/s])."""

    t: np.ndarray  #: (n,)
    command: np.ndarray  #: (n, 2) the input
    speed: np.ndarray  #: (n, 2)
    source: str = ""
    rows: tuple[str, ...] = ()  #: where each sample is in the file ("line 12", "/odom message 7"), for errors

    def where(self, k: int) -> str:
        """Where sample ``k`` is in the file the log was read from (else "sample k")."""
        return self.rows[k] if len(self.rows) > k else f"sample {k}"


@dataclass(frozen=True)
class SpeedModel:
    """A model of the body speeds, linear in its parameters.

    ``rate(params, speed, input)`` gives d(v, omega)/dt (a JAX function); ``regressors(speed, rate, input)`` gives,
    per sample, the rows ``A`` and targets ``b`` of the equation error A @ params = b (NumPy), stacked over the
    model's equations."""

    name: str
    names: tuple[str, ...]
    units: tuple[str, ...]
    meanings: tuple[str, ...]
    rate: Callable
    regressors: Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]
    positive: tuple[int, ...]  #: parameters that must stay > 0 (inertias)
    couplings: tuple[int, ...]  #: parameters set to 0 for a safe start when the equation error's start diverges
    input_names: tuple[str, str]  #: the input's two channels, for messages
    excitation: str = "drive turns at speed (ddtrack excite)"  #: what a log needs to pin a parameter down


@dataclass(frozen=True)
class SpeedFit:
    """An identified model: its parameters with standard errors, the input delay, and how well it predicts."""

    model: str
    params: np.ndarray  #: (p,)
    std: np.ndarray  #: (p,) standard errors, from the output-error fit's covariance
    delay: float  #: [s] the input delay that fitted best (a whole number of samples)
    interval_mean: bool  #: the speeds fitted best as means over each sample interval (odometry), not instants
    noise: np.ndarray  #: (2,) residual spread of v [m/s] and omega [rad/s] on the fitted samples
    fit_percent: dict[str, float]  #: 100 (1 - |y - y_hat| / |y - mean y|) per speed, on the held-out quarter
    samples: tuple[int, int]  #: samples fitted, held out
    windows: int  #: output-error windows the fitted samples were cut into, each simulated from its own start
    covariance: np.ndarray  #: (p, p) of the parameters (the windows' starts eliminated); std is its diagonal's root
    substeps: int = SUBSTEPS  #: RK4 steps per sample interval of the model's simulation (more where it is stiff)
    notes: tuple[str, ...] = field(default=())  #: what this log could not separate


def identify(model: SpeedModel, log: SpeedLog, *, max_delay: float = 0.3, window: float = WINDOW) -> SpeedFit:
    """Fit ``model`` to ``log``, trying input delays of 0 to ``max_delay`` [s] in whole samples, the output error
    over windows of ``window`` [s] (``np.inf``: one simulation of the whole fitted record).

    Raises ConfigError for a log that cannot identify the model: too short, not increasing in time, an input
    channel that never changes, a measured speed that never changes."""
    t, inputs, speed = checked(log, model.input_names)
    dt = np.diff(t)
    n_fit = round(len(t) * (1.0 - HELD_OUT))
    fitted = slice(0, n_fit)
    steps = int(np.floor(max_delay / np.median(dt) + 1e-9))
    fits = {}
    for k in range(steps + 1):  # every delay, and both readings of the speeds: instantaneous or interval means
        delayed = delayed_inputs(inputs, k)[fitted]
        start = equation_error(model, t[fitted], delayed, speed[fitted])
        for mean in (False, True):
            substeps = substeps_for(model, start, speed, float(dt.max()))
            fit = output_error(model, t[fitted], delayed, speed[fitted], start, interval_mean=mean, window=window,
                               substeps=substeps)  # fmt: skip
            stiffer = substeps_for(model, fit.params, speed, float(dt.max())) if np.isfinite(fit.cost) else substeps
            if stiffer > substeps:  # the fit went where the start's steps are too long: again, from there
                fit = output_error(model, t[fitted], delayed, speed[fitted], fit.params, interval_mean=mean,
                                   window=window, substeps=stiffer)  # fmt: skip
            fits[k, mean] = fit
    k, mean = min(fits, key=lambda key: fits[key].cost)
    if not np.isfinite(fits[k, mean].cost):
        raise ConfigError(
            "LOG",
            f"{log.source}: the {model.name} model's simulation diverges from every start tried",
            "check the log's units and columns, and that --model is the robot's",
        )
    params, std, _, noise, windows, substeps, covariance = fits[k, mean]
    held_inputs = delayed_inputs(inputs, k)[n_fit - 1 :]
    predicted = simulate(model, params, t[n_fit - 1 :], held_inputs, speed[n_fit - 1], mean, substeps)
    held = speed[n_fit:]
    fit_percent = {
        name: float(
            100.0
            * (1.0 - np.linalg.norm(held[:, i] - predicted[1:, i]) / np.linalg.norm(held[:, i] - held[:, i].mean()))
        )
        for i, name in enumerate(("v", "omega"))
    }
    return SpeedFit(
        model=model.name,
        params=params,
        std=std,
        delay=round(float(k * np.median(dt)), 9),
        interval_mean=mean,
        noise=noise,
        fit_percent=fit_percent,
        samples=(n_fit, len(t) - n_fit),
        windows=windows,
        covariance=covariance,
        substeps=substeps,
        notes=unseparated(model, params, std),
    )


def checked(log: SpeedLog, input_names: tuple[str, str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The log's arrays, or a ConfigError saying why it cannot identify anything."""
    t, inputs, speed = (np.asarray(a, dtype=float) for a in (log.t, log.command, log.speed))
    if t.ndim != 1 or inputs.shape != (t.size, 2) or speed.shape != (t.size, 2):
        raise ValueError(f"t (n,), input and speed (n, 2) expected, got {t.shape}, {inputs.shape}, {speed.shape}")
    if t.size < MIN_SAMPLES:
        raise ConfigError("LOG", f"{log.source} has {t.size} samples", f"a fit needs at least {MIN_SAMPLES}")
    values = np.column_stack([t, inputs, speed])
    if not np.all(np.isfinite(values)):
        k, column = (int(i) for i in np.argwhere(~np.isfinite(values))[0])
        name = ("t", *input_names, "v", "omega")[column]
        raise ConfigError(
            "LOG", f"{log.source}, {log.where(k)}: {name} is {values[k, column]}, not a number", "drop that sample"
        )
    if np.any(np.diff(t) <= 0):
        k = int(np.flatnonzero(np.diff(t) <= 0)[0]) + 1
        raise ConfigError(
            "LOG",
            f"{log.source}, {log.where(k)}: time does not increase (t = {t[k]:.9g} s after {t[k - 1]:.9g} s)",
            "sort the samples by time, and drop repeated ones",
        )
    for i, name in enumerate(input_names):
        if np.ptp(inputs[:, i]) == 0.0:
            raise ConfigError(
                "LOG",
                f"{log.source}: {name} never changes ({inputs[0, i]:g}), so its effect cannot be seen",
                "drive an excitation plan (ddtrack excite) and record it",
            )
    for i, name in enumerate(("v", "omega")):
        if np.ptp(speed[:, i]) == 0.0:
            raise ConfigError("LOG", f"{log.source}: the measured {name} never changes", "check the measured topic")
    return t, inputs, speed


def delayed_inputs(inputs: np.ndarray, k: int) -> np.ndarray:
    """The input in force at each sample when it acts ``k`` samples after it was logged (the first held)."""
    return inputs if k == 0 else np.concatenate([np.repeat(inputs[:1], k, axis=0), inputs[:-k]])


def equation_error(model: SpeedModel, t: np.ndarray, inputs: np.ndarray, speed: np.ndarray) -> np.ndarray:
    """Parameters by linear least squares on the model's equations, speeds and rates from a Savitzky-Golay filter
    over about 0.2 s (never raw differences of quantised speeds); a parameter the data does not excite is 0."""
    dt = float(np.median(np.diff(t)))
    window = max(5, 2 * round(0.1 / dt) + 1)
    smooth = savgol_filter(speed, window, 2, axis=0)
    rate = savgol_filter(speed, window, 2, deriv=1, delta=dt, axis=0)
    rows, target = model.regressors(smooth, rate, inputs)
    scale = np.linalg.norm(rows, axis=0)
    usable = scale > 1e-9 * max(scale.max(), 1e-300)
    solution = np.zeros(rows.shape[1])
    solution[usable] = np.linalg.lstsq(rows[:, usable], target, rcond=None)[0]
    return solution


def simulate(
    model: SpeedModel,
    params: np.ndarray,
    t: np.ndarray,
    inputs: np.ndarray,
    start: np.ndarray,
    interval_mean: bool,
    substeps: int = SUBSTEPS,
) -> np.ndarray:
    """(v, omega) at each of the times ``t`` [s] from ``start`` at t[0], each input held until the next time, by
    ``substeps`` RK4 steps per interval; with ``interval_mean``, each sample after the first is the mean over the
    interval ending at it."""
    args = (jnp.asarray(params), jnp.asarray(np.diff(t)), jnp.asarray(inputs[:-1]), jnp.asarray(start))
    return np.asarray(_simulate(model.rate, *args, interval_mean, substeps))


def substeps_for(model: SpeedModel, params: np.ndarray, speed: np.ndarray, step: float) -> int:
    """RK4 steps per sample interval of ``step`` [s] that keep |lambda| h <= STIFF_STEP for the model at
    ``params``, lambda the eigenvalues of d rate / d speed at rest and at up to 64 of the logged ``speed``s: a power
    of two (so that a few compiled simulations serve every fit) from SUBSTEPS to MAX_SUBSTEPS."""
    points = np.concatenate([np.zeros((1, 2)), speed[:: max(1, len(speed) // 64)]])
    jacobians = _speed_jacobians(model.rate, jnp.asarray(params), jnp.asarray(points))
    stiffness = float(np.nan_to_num(np.abs(np.linalg.eigvals(np.asarray(jacobians))).max(), nan=np.inf))
    needed = max(stiffness * step / STIFF_STEP, 1.0)
    return int(np.clip(2 ** np.ceil(np.log2(needed)), SUBSTEPS, MAX_SUBSTEPS))


@partial(jax.jit, static_argnums=0)
def _speed_jacobians(rate, params, points):
    return jax.vmap(jax.jacfwd(lambda s: rate(params, s, jnp.zeros(2))))(points)


@partial(jax.jit, static_argnums=(0, 5, 6))
def _simulate(rate, params, dt, inputs, start, interval_mean, substeps):
    def interval(speed, step_inputs):
        h, u = step_inputs
        f = lambda s: rate(params, s, u)  # noqa: E731

        def substep(s, _):
            after = rk4_step(f, s, h / substeps)
            return after, after

        after, path = jax.lax.scan(substep, speed, None, length=substeps)
        mean = (0.5 * speed + path[:-1].sum(axis=0) + 0.5 * after) / substeps  # trapezoid over the substeps
        return after, mean if interval_mean else after

    _, speeds = jax.lax.scan(interval, start, (dt, inputs))
    return jnp.concatenate([start[None], speeds])


class Windows(NamedTuple):
    """The fitted record cut into k consecutive windows of m samples, the last padded with zero-length intervals."""

    step: np.ndarray  #: (k, m - 1) the intervals between a window's samples [s]
    inputs: np.ndarray  #: (k, m - 1, 2) the input held over each interval
    speed: np.ndarray  #: (k, m, 2) the measured speeds
    mask: np.ndarray  #: (k, m) 1 on a logged sample, 0 on padding


def cut(t: np.ndarray, inputs: np.ndarray, speed: np.ndarray, window: float) -> Windows:
    """Windows of ``window`` [s] (m = window / median step samples, at least 2; one window if it exceeds the log)
    starting every m samples; the interval from a window's last sample to the next window's first is not
    simulated, since the next window starts from its own free speeds."""
    n = len(t)
    m = int(min(n, max(2.0, np.round(window / np.median(np.diff(t))))))
    k = -(-n // m)
    pad = k * m - n
    step = np.concatenate([[0.0], np.diff(t), np.zeros(pad)]).reshape(k, m)[:, 1:]  # the interval ending at each
    held = np.concatenate([inputs[:1], inputs[:-1], np.zeros((pad, 2))]).reshape(k, m, 2)[:, 1:]
    measured = np.concatenate([speed, np.zeros((pad, 2))]).reshape(k, m, 2)
    return Windows(step, held, measured, (np.arange(k * m) < n).astype(float).reshape(k, m))


def _window_residuals(rate, interval_mean, substeps, params, weights, start, step, inputs, measured, mask):
    """One window simulated from its own start, minus the measured speeds, over each channel's spread: (2 m,), zero
    on padding (a padded interval has zero length, so the simulation just holds its state there)."""
    simulated = _simulate(rate, params, step, inputs, start, interval_mean, substeps)
    return ((simulated - measured) / weights * mask[:, None]).ravel()


@partial(jax.jit, static_argnums=(0, 1, 2))
def _residuals(rate, interval_mean, substeps, params, starts, windows, weights):
    """Every window's residuals, (k, 2 m), the windows simulated side by side."""
    residuals = lambda s, *w: _window_residuals(rate, interval_mean, substeps, params, weights, s, *w)  # noqa: E731
    return jax.vmap(residuals)(starts, *windows)


@partial(jax.jit, static_argnums=(0, 1, 2))
def _jacobians(rate, interval_mean, substeps, params, starts, windows, weights):
    """Each window's exact Jacobian (forward mode through its simulation) on the model's parameters, (k, 2 m, p),
    and on its own start, (k, 2 m, 2): a window's residuals depend on no other window's start."""

    def one(start, *window):
        f = lambda p, s: _window_residuals(rate, interval_mean, substeps, p, weights, s, *window)  # noqa: E731
        return jax.jacfwd(f, argnums=(0, 1))(params, start)

    return jax.vmap(one)(starts, *windows)


def normal_blocks(j_params: np.ndarray, j_starts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """J^T J of all windows stacked, in its blocks [[A, B], [B^T, diag(D_1 .. D_k)]]: A = sum_i Jp_i^T Jp_i (p, p),
    B_i = Jp_i^T Js_i (k, p, 2), D_i = Js_i^T Js_i (k, 2, 2); the starts of two windows never meet."""
    a = np.einsum("kri,krj->ij", j_params, j_params)
    return a, np.einsum("kri,krj->kij", j_params, j_starts), np.einsum("kri,krj->kij", j_starts, j_starts)


def schur(a: np.ndarray, b: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The window starts eliminated: S = A - sum_i B_i D_i^-1 B_i^T, the normal matrix of the model's parameters
    alone (S^-1 is the parameters' block of (J^T J)^-1), and B_i D_i^-1. Each D_i is invertible: a window's start
    sets its first simulated sample."""
    bd = b @ np.linalg.inv(d)
    return a - np.einsum("kij,klj->il", bd, b), bd


def lm_step(
    blocks: tuple[np.ndarray, np.ndarray, np.ndarray], g_params: np.ndarray, g_starts: np.ndarray, damping: float
) -> np.ndarray:
    """The Levenberg-Marquardt step (J^T J + damping diag(J^T J)) delta = -J^T r, solved in blocks: for
    the parameters (S delta_p = -g_p + sum_i B_i D_i^-1 g_i, S of the damped blocks), then each window's start,
    delta_i = -D_i^-1 (g_i + B_i^T delta_p); g = J^T r split the same way."""
    a, b, d = blocks
    a = a + damping * np.diag(np.diag(a) + 1e-12)
    d = d + damping * np.eye(2) * (np.diagonal(d, axis1=1, axis2=2)[:, None, :] + 1e-12)
    s, bd = schur(a, b, d)
    delta = np.linalg.solve(s, -g_params + np.einsum("kij,kj->i", bd, g_starts))
    starts = -np.linalg.solve(d, (g_starts + np.einsum("kji,j->ki", b, delta))[..., None])[..., 0]
    return np.concatenate([delta, starts.ravel()])


class OutputError(NamedTuple):
    """An output-error fit of one delay and reading."""

    params: np.ndarray  #: (p,)
    std: np.ndarray  #: (p,) their standard errors
    cost: float  #: each channel's mean squared residual over its signal's variance, summed: comparable between fits
    noise: np.ndarray  #: (2,) each channel's residual spread
    windows: int  #: windows fitted, each with its own two start speeds
    substeps: int  #: RK4 steps per sample interval
    covariance: np.ndarray  #: (p, p) the parameters' block of the Gauss-Newton covariance


def output_error(
    model: SpeedModel,
    t: np.ndarray,
    inputs: np.ndarray,
    speed: np.ndarray,
    start: np.ndarray,
    *,
    interval_mean: bool,
    window: float = WINDOW,
    substeps: int = SUBSTEPS,
    iterations: int = 40,
) -> OutputError:
    """Levenberg-Marquardt from ``start`` on the model's parameters and, per window of ``window`` [s], the window's
    initial speeds (multiple shooting: no continuity between windows; each window starts from its measured first
    sample). The residuals of all windows are stacked; the standard errors are the parameters' block of the
    Gauss-Newton covariance s^2 (J^T J)^-1, s^2 = |r|^2 / (residuals - p - 2 k), the k windows' starts counted."""
    windows = cut(t, inputs, speed, window)
    data = tuple(jnp.asarray(a) for a in windows)
    count, n_params = len(windows.mask), start.size

    def residual_fn(q: np.ndarray, w: jax.Array) -> np.ndarray:  # q = (params, each window's start v and omega)
        return np.asarray(
            _residuals(model.rate, interval_mean, substeps, q[:n_params], q[n_params:].reshape(count, 2), data, w)
        ).ravel()

    def jacobian_fn(q: np.ndarray, w: jax.Array) -> tuple[np.ndarray, np.ndarray]:
        j = _jacobians(model.rate, interval_mean, substeps, q[:n_params], q[n_params:].reshape(count, 2), data, w)
        return np.asarray(j[0]), np.asarray(j[1])

    positive = list(model.positive)
    q = np.concatenate([start, windows.speed[:, 0].ravel()])
    q[positive] = np.maximum(q[positive], 1e-3 * np.maximum(np.abs(q[positive]).max(), 1e-6))
    spread = np.maximum(np.std(speed, axis=0) * 0.01, 1e-6)  # first weights; re-estimated from the residuals
    if not np.all(np.isfinite(residual_fn(q, jnp.asarray(spread)))):  # noisy coupling terms can make it blow up
        q[list(model.couplings)] = 0.0
    if not np.all(np.isfinite(residual_fn(q, jnp.asarray(spread)))):  # no fit from here: another delay wins
        return _failed(q[:n_params], count, substeps)
    logged = windows.mask.ravel() > 0
    for _ in range(2):  # fit, re-weight each channel by its residual spread, fit again
        weights = jnp.asarray(spread)
        damping, r = 1e-3, residual_fn(q, weights)
        for _ in range(iterations):
            j_params, j_starts = jacobian_fn(q, weights)
            if not (np.all(np.isfinite(j_params)) and np.all(np.isfinite(j_starts))):
                break  # the tangents blew up (a stiff model beyond MAX_SUBSTEPS): no step from here
            rows = r.reshape(count, -1)
            gradient = np.einsum("kri,kr->i", j_params, rows), np.einsum("kri,kr->ki", j_starts, rows)
            try:
                trial = q + lm_step(normal_blocks(j_params, j_starts), *gradient, damping)
            except np.linalg.LinAlgError:  # a window's start no longer moves its samples: damp more
                trial = np.full_like(q, np.nan)
            if np.all(trial[positive] > 0):
                r_trial = residual_fn(trial, weights)
                if np.all(np.abs(r_trial) < 1e150) and r_trial @ r_trial < r @ r:  # a diverged trial is no step
                    shrink = (r @ r - r_trial @ r_trial) / max(r @ r, 1e-300)
                    q, r, damping = trial, r_trial, max(damping / 3.0, 1e-9)
                    if shrink < 1e-12:
                        break
                    continue
            damping *= 4.0
            if damping > 1e9:
                break
        spread = np.maximum(np.std((r.reshape(-1, 2) * np.asarray(weights))[logged], axis=0), 1e-9)
    r = residual_fn(q, jnp.asarray(spread))
    jacobians = jacobian_fn(q, jnp.asarray(spread))
    cost = float(np.sum(spread**2 / np.var(speed, axis=0)))
    if not (np.all(np.isfinite(r)) and all(np.all(np.isfinite(j)) for j in jacobians)):
        return _failed(q[:n_params], count, substeps)
    dof = 2 * int(logged.sum()) - q.size  # the windows' starts are fitted too
    try:
        s, _ = schur(*normal_blocks(*jacobians))
        covariance = np.linalg.pinv(s) * float(r @ r) / max(dof, 1)
    except np.linalg.LinAlgError:
        return _failed(q[:n_params], count, substeps)
    std = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    return OutputError(q[:n_params], std, cost, spread, count, substeps, covariance)


def _failed(params: np.ndarray, count: int, substeps: int) -> OutputError:
    """No fit from this start: infinite cost and uncertainty, so another delay or reading wins."""
    infinite = np.full(params.size, np.inf)
    return OutputError(params, infinite, np.inf, np.full(2, np.inf), count, substeps, np.diag(infinite))


def propagated(
    mapping: Callable[[np.ndarray], dict[str, float]], values: np.ndarray, covariance: np.ndarray
) -> dict[str, float]:
    """Standard errors of each value of ``mapping(values)`` by the delta method: J C J^T with J by central
    differences (steps of 1e-6 of each value's scale), C the values' ``covariance``."""
    scale = np.maximum(np.abs(values), np.sqrt(np.abs(np.diag(covariance))))
    steps = 1e-6 * np.where(np.isfinite(scale) & (scale > 0), scale, 1.0)
    keys = list(mapping(values))
    columns = []
    for i, h in enumerate(steps):
        up, down = values.copy(), values.copy()
        up[i] += h
        down[i] -= h
        high, low = mapping(up), mapping(down)
        columns.append([(high[k] - low[k]) / (2 * h) for k in keys])
    jacobian = np.array(columns).T
    variance = np.einsum("ki,ij,kj->k", jacobian, covariance, jacobian)
    return {k: float(np.sqrt(max(v, 0.0))) if np.isfinite(v) else np.inf for k, v in zip(keys, variance, strict=True)}


def unseparated(model: SpeedModel, params: np.ndarray, std: np.ndarray) -> tuple[str, ...]:
    """The parameters this log leaves undetermined: a 95 % interval that holds zero and twice the estimate."""
    notes = []
    for name, meaning, value, sigma in zip(model.names, model.meanings, params, std, strict=True):
        if 1.96 * sigma > max(abs(value), 1e-12):
            notes.append(
                f"{name} ({meaning}) = {value:.3g} +- {1.96 * sigma:.2g} (95 %): not separated from 0 by this log; "
                f"{model.excitation} to pin it down"
            )
    return tuple(notes)
