"""Identifying a velocity-commanded base's lag model from a log (docs/identification.md).

The model (Martins et al., model.md §1.8) is linear in theta = (theta_1 .. theta_6)::

    v*     = theta_1 v_dot     - theta_3 omega^2 + theta_4 v
    omega* = theta_2 omega_dot + theta_5 v omega + theta_6 omega

so an equation-error fit (linear least squares, derivatives from a Savitzky-Golay filter, never raw differences of
quantised speeds) gives a first estimate for each command delay tried. The output-error fit refines the best one:
the model is simulated under the logged commands (held between samples, as a base holds cmd_vel) from a free
initial speed, and theta minimises the mismatch with the measured speeds (Levenberg-Marquardt on the residuals'
exact Jacobian, ``jax.jacfwd`` through the simulation). The speeds are states the base measures directly, and the
lags are stable, so one simulation over the whole record stays well conditioned (no multiple shooting needed).
Uncertainty: the Gauss-Newton covariance s^2 (J^T J)^-1 of the weighted residuals (each channel divided by its
own residual spread).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
from scipy.signal import savgol_filter

from ..errors import ConfigError
from ..integrators import rk4_step
from ..model.lag import LagPlant

#: theta_1..theta_6 and their units
NAMES = ("theta_1", "theta_2", "theta_3", "theta_4", "theta_5", "theta_6")
UNITS = ("s", "s", "s m/rad^2", "1", "s/m", "1")
#: what each parameter means, for the report
MEANINGS = (
    "v's inertia (lag = theta_1 / theta_4)",
    "omega's inertia (lag = theta_2 / theta_6)",
    "omega^2 feeding v (centripetal coupling)",
    "v's damping (DC gain 1 / theta_4)",
    "v omega slowing omega (coupling)",
    "omega's damping (DC gain 1 / theta_6)",
)
HELD_OUT = 0.25  #: the last quarter of the log is not fitted: it tells how well the model predicts
SUBSTEPS = 4  #: RK4 steps per sample interval of the simulation (a lag of 5 samples is integrated to 1e-6)


@dataclass(frozen=True)
class SpeedLog:
    """A log of a velocity-commanded base: at each measurement time ``t`` [s] (increasing), the command in force
    until the next sample (v* [m/s], omega* [rad/s]) and the measured speeds (v [m/s], omega [rad/s])."""

    t: np.ndarray  #: (n,)
    command: np.ndarray  #: (n, 2)
    speed: np.ndarray  #: (n, 2)
    source: str = ""


@dataclass(frozen=True)
class LagFit:
    """An identified lag model: theta with its standard errors, the command delay, and the model's fit."""

    theta: np.ndarray  #: (6,) theta_1..theta_6
    std: np.ndarray  #: (6,) standard errors, from the output-error fit's covariance
    delay: float  #: [s] the command delay that fitted best (a whole number of samples)
    interval_mean: bool  #: the speeds fitted best as means over each sample interval (odometry), not instants
    noise: np.ndarray  #: (2,) residual spread of v [m/s] and omega [rad/s] on the fitted samples
    fit_percent: dict[str, float]  #: 100 (1 - |y - y_hat| / |y - mean y|) per speed, on the held-out quarter
    samples: tuple[int, int]  #: samples fitted, held out
    notes: tuple[str, ...] = field(default=())  #: what this log could not separate

    @property
    def time_constants(self) -> tuple[float, float]:
        """Lags of v and omega without the coupling terms [s]."""
        return float(self.theta[0] / self.theta[3]), float(self.theta[1] / self.theta[5])


def identify_lag(log: SpeedLog, *, max_delay: float = 0.3) -> LagFit:
    """Identify the lag model from ``log``, trying command delays of 0 to ``max_delay`` [s] in whole samples.

    Raises ConfigError for a log that cannot identify the model: too short, not increasing in time, never
    commanding or never moving one of the two speeds."""
    t, command, speed = _checked(log)
    dt = np.diff(t)
    n_fit = round(len(t) * (1.0 - HELD_OUT))
    fitted = slice(0, n_fit)
    steps = int(np.floor(max_delay / np.median(dt) + 1e-9))
    fits = {}
    for k in range(steps + 1):  # every delay, and both readings of the speeds: instantaneous or interval means
        delayed = _delayed(command, k)[fitted]
        start, _ = _equation_error(t[fitted], delayed, speed[fitted])
        for mean in (False, True):
            fits[k, mean] = _output_error(t[fitted], delayed, speed[fitted], start, interval_mean=mean)
    k, mean = min(fits, key=lambda key: fits[key][2])
    theta, std, _, noise = fits[k, mean]
    predicted = simulate_speeds(
        theta, t[n_fit - 1 :], _delayed(command, k)[n_fit - 1 :], speed[n_fit - 1], interval_mean=mean
    )[1:]
    held = speed[n_fit:]
    fit_percent = {
        name: float(
            100.0
            * (1.0 - np.linalg.norm(held[:, i] - predicted[:, i]) / np.linalg.norm(held[:, i] - held[:, i].mean()))
        )
        for i, name in enumerate(("v", "omega"))
    }
    return LagFit(
        theta=theta,
        std=std,
        delay=round(float(k * np.median(dt)), 9),
        interval_mean=mean,
        noise=noise,
        fit_percent=fit_percent,
        samples=(n_fit, len(t) - n_fit),
        notes=_unseparated(theta, std),
    )


def _checked(log: SpeedLog) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t, command, speed = (np.asarray(a, dtype=float) for a in (log.t, log.command, log.speed))
    if t.ndim != 1 or command.shape != (t.size, 2) or speed.shape != (t.size, 2):
        raise ValueError(f"t (n,), command and speed (n, 2) expected, got {t.shape}, {command.shape}, {speed.shape}")
    if t.size < 80:
        raise ConfigError("LOG", f"{log.source} has {t.size} samples", "a lag fit needs at least 80 (4 s at 20 Hz)")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(command)) and np.all(np.isfinite(speed))):
        raise ConfigError("LOG", f"{log.source} has NaN or infinite values", "drop those rows")
    if np.any(np.diff(t) <= 0):
        k = int(np.flatnonzero(np.diff(t) <= 0)[0]) + 1
        raise ConfigError("LOG", f"{log.source}: time does not increase at sample {k} (t = {t[k]:.9g} s)", "")
    for i, (name, unit) in enumerate((("v", "m/s"), ("omega", "rad/s"))):
        if np.ptp(command[:, i]) == 0.0:
            raise ConfigError(
                "LOG",
                f"{log.source}: the {name} command never changes ({command[0, i]:g} {unit}), so its lag cannot be seen",
                "drive an excitation plan (ddtrack excite) and record it",
            )
        if np.ptp(speed[:, i]) == 0.0:
            raise ConfigError("LOG", f"{log.source}: the measured {name} never changes", "check the odometry topic")
    return t, command, speed


def _delayed(command: np.ndarray, k: int) -> np.ndarray:
    """The command in force at each sample when it acts ``k`` samples after it was logged (the first held)."""
    return command if k == 0 else np.concatenate([np.repeat(command[:1], k, axis=0), command[:-k]])


def _equation_error(t: np.ndarray, command: np.ndarray, speed: np.ndarray) -> tuple[np.ndarray, float]:
    """theta by linear least squares on the two rows of the model, and the normalised residual cost."""
    dt = float(np.median(np.diff(t)))
    window = max(5, 2 * round(0.1 / dt) + 1)  # about 0.2 s: smooths quantisation, keeps a 0.25 s lag
    smooth = savgol_filter(speed, window, 2, axis=0)
    rate = savgol_filter(speed, window, 2, deriv=1, delta=dt, axis=0)
    v, w = smooth[:, 0], smooth[:, 1]
    rows_v = np.column_stack([rate[:, 0], -(w**2), v])
    rows_w = np.column_stack([rate[:, 1], v * w, w])
    theta_v, cost_v = _least_squares(rows_v, command[:, 0])
    theta_w, cost_w = _least_squares(rows_w, command[:, 1])
    theta = np.array([theta_v[0], theta_w[0], theta_v[1], theta_v[2], theta_w[1], theta_w[2]])
    return theta, cost_v + cost_w


def _least_squares(rows: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, float]:
    """Least squares of ``rows @ x = target``; a column the data does not excite (the coupling terms of a log that
    never turns while driving) is fixed at 0."""
    scale = np.linalg.norm(rows, axis=0)
    usable = scale > 1e-9 * max(scale.max(), 1e-300)
    solution = np.zeros(rows.shape[1])
    solution[usable] = np.linalg.lstsq(rows[:, usable], target, rcond=None)[0]
    residual = target - rows @ solution
    return solution, float(residual @ residual / max(target @ target, 1e-300))


def simulate_speeds(
    theta: np.ndarray, t: np.ndarray, command: np.ndarray, start: np.ndarray, *, interval_mean: bool = False
) -> np.ndarray:
    """(v, omega) at each of the times ``t`` [s] from ``start`` at t[0], each command held until the next time;
    with ``interval_mean``, each sample after the first is the mean over the interval ending at it (what odometry
    measures: wheel-angle increments over the interval)."""
    args = (jnp.asarray(theta), jnp.asarray(np.diff(t)), jnp.asarray(command[:-1]), jnp.asarray(start))
    return np.asarray(_simulate(*args, interval_mean))


@partial(jax.jit, static_argnums=4)
def _simulate(theta, dt, command, start, interval_mean):
    plant = LagPlant(theta=theta)

    def interval(speed, inputs):
        h, u = inputs
        rate = lambda s: plant.derivative(jnp.concatenate([jnp.zeros(3), s]), u, jnp.zeros(2))[3:]  # noqa: E731

        def substep(s, _):
            after = rk4_step(rate, s, h / SUBSTEPS)
            return after, after

        after, path = jax.lax.scan(substep, speed, None, length=SUBSTEPS)
        mean = (0.5 * speed + path[:-1].sum(axis=0) + 0.5 * after) / SUBSTEPS  # trapezoid over the substeps
        return after, mean if interval_mean else after

    _, speeds = jax.lax.scan(interval, start, (dt, command))
    return jnp.concatenate([start[None], speeds])


def _weighted_residuals(p, dt, held, measured, weights, interval_mean):
    """Simulated minus measured speeds over each channel's spread, for p = (theta, initial v, initial omega)."""
    return ((_simulate(p[:6], dt, held, p[6:], interval_mean) - measured) / weights).ravel()


_residuals = jax.jit(_weighted_residuals, static_argnums=5)
_jacobian = jax.jit(jax.jacfwd(_weighted_residuals), static_argnums=5)


def _output_error(
    t: np.ndarray,
    command: np.ndarray,
    speed: np.ndarray,
    theta0: np.ndarray,
    *,
    interval_mean: bool,
    iterations: int = 40,
) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """Levenberg-Marquardt on (theta, initial speeds); returns theta, its standard errors, the cost (each channel's
    mean squared residual over its signal's variance, summed: comparable between fits) and each channel's residual
    spread."""
    data = (jnp.asarray(np.diff(t)), jnp.asarray(command[:-1]), jnp.asarray(speed))
    spread = np.maximum(np.std(speed, axis=0) * 0.01, 1e-6)  # first weights; re-estimated from the residuals
    residual_fn = lambda p, weights: _residuals(p, *data, weights, interval_mean)  # noqa: E731
    jacobian = lambda p, weights: _jacobian(p, *data, weights, interval_mean)  # noqa: E731
    p = np.concatenate([np.where(theta0[:2] > 0, theta0[:2], 0.1), theta0[2:], speed[0]])
    p[[0, 1]] = np.maximum(p[[0, 1]], 1e-3)
    for _ in range(2):  # fit, re-weight each channel by its residual spread, fit again
        weights = jnp.asarray(spread)
        damping = 1e-3
        r = np.asarray(residual_fn(p, weights))
        for _ in range(iterations):
            j = np.asarray(jacobian(p, weights))
            gradient, normal = j.T @ r, j.T @ j
            step = np.linalg.solve(normal + damping * np.diag(np.diag(normal) + 1e-12), -gradient)
            trial = p + step
            if trial[0] > 0 and trial[1] > 0:
                r_trial = np.asarray(residual_fn(trial, weights))
                if np.all(np.abs(r_trial) < 1e150) and r_trial @ r_trial < r @ r:  # a diverged trial is no step
                    shrink = (r @ r - r_trial @ r_trial) / max(r @ r, 1e-300)
                    p, r, damping = trial, r_trial, max(damping / 3.0, 1e-9)
                    if shrink < 1e-12:
                        break
                    continue
            damping *= 4.0
            if damping > 1e9:
                break
        spread = np.maximum(np.std(r.reshape(-1, 2) * np.asarray(weights), axis=0), 1e-9)
    j = np.asarray(jacobian(p, jnp.asarray(spread)))
    r = np.asarray(residual_fn(p, jnp.asarray(spread)))
    dof = max(r.size - p.size, 1)
    covariance = np.linalg.pinv(j.T @ j) * float(r @ r) / dof
    std = np.sqrt(np.clip(np.diag(covariance)[:6], 0.0, None))
    cost = float(np.sum(spread**2 / np.var(speed, axis=0)))
    return p[:6], std, cost, spread


def _unseparated(theta: np.ndarray, std: np.ndarray) -> tuple[str, ...]:
    """The parameters this log leaves undetermined: a 95 % interval that holds zero and twice the estimate."""
    notes = []
    for name, meaning, value, sigma in zip(NAMES, MEANINGS, theta, std, strict=True):
        if 1.96 * sigma > max(abs(value), 1e-12):
            notes.append(
                f"{name} ({meaning}) = {value:.3g} +- {1.96 * sigma:.2g} (95 %): not separated from 0 by this log; "
                "drive turns at speed (ddtrack excite) to pin it down"
            )
    return tuple(notes)
