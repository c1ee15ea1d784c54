"""The output-error fit of a speed model and its input delay (docs/identification.md): Levenberg-Marquardt on the
simulated speeds' residuals, the record cut into windows each simulated from its own free start (multiple
shooting), the windows' starts eliminated from the normal equations (a Schur complement).

The inputs are held on their own time base (:mod:`ddtrack.sysid.schedule`), so the delay is a parameter like the
model's: its Jacobian column comes from the same forward-mode pass through each window's simulation.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .schedule import CORNER, Schedule, nearest_corner, program, schedule, simulate_schedule, used_segments

if TYPE_CHECKING:
    from .fit import SpeedModel

SUBSTEPS = 4  #: RK4 steps per segment at least (a lag of 5 samples is integrated to 1e-6)
#: [s] output-error window: 7 of the slowest lag we fit (0.3 s), so most of it answers commands, not its free start
WINDOW = 2.0
#: the fit ends where the Gauss-Newton step would move every parameter (and the delay) by less than this many of its
#: standard errors: the statistics cannot see what is left. The first pass only sets the channels' weights (their
#: residual spreads, which a tenth of a standard error leaves unchanged)
STILL, STILL_FIRST = 0.01, 0.1


class Windows(NamedTuple):
    """The fitted record cut into k consecutive windows of m samples, the last padded."""

    ending: np.ndarray  #: (k, m - 1) the sample each simulated interval ends at (n or more on padding)
    speed: np.ndarray  #: (k, m, 2) the measured speeds
    mask: np.ndarray  #: (k, m) 1 on a logged sample, 0 on padding


def cut(t: np.ndarray, speed: np.ndarray, window: float) -> Windows:
    """Windows of ``window`` [s] (m = window / median step samples, at least 2; one window if it exceeds the log)
    starting every m samples; the interval from a window's last sample to the next window's first is not
    simulated, since the next window starts from its own free speeds."""
    n = len(t)
    m = int(min(n, max(2.0, np.round(window / np.median(np.diff(t))))))
    k = -(-n // m)
    samples = np.arange(k * m).reshape(k, m)
    measured = np.concatenate([speed, np.zeros((k * m - n, 2))]).reshape(k, m, 2)
    return Windows(samples[:, 1:], measured, (samples < n).astype(float))


def unread_starts(windows: Windows) -> Windows:
    """Windows for speeds read as interval means: a window's first sample is the mean over the interval before its
    start, not its start's speeds, so it is not compared (the start is fitted from the window's later samples; a
    window with none is dropped). Compared with it, the starts lag by half a sample, and a longer delay and the
    instants' reading fit better than the truth."""
    mask = windows.mask.copy()
    mask[:, 0] = 0.0
    keep = mask.sum(axis=1) > 0
    return Windows(windows.ending[keep], windows.speed[keep], mask[keep])


def windowed(scheduled: Schedule, windows: Windows) -> tuple[jax.Array, ...]:
    """The schedule's intervals arranged as the windows simulate them, (k, m - 1, ...); a padded interval has zero
    length, so the simulation holds its state there."""
    n_intervals = len(scheduled.step)
    inside = windows.ending <= n_intervals
    index = np.minimum(windows.ending, n_intervals) - 1
    start, step, switch, valid, inputs = (np.asarray(a)[index] for a in scheduled)
    return tuple(
        jnp.asarray(a) for a in (start, np.where(inside, step, 0.0), switch, valid & inside[..., None], inputs)
    )


def _window_errors(rate, interval_mean, substeps, free, params, delay, start, scheduled, measured, mask, used):
    """One window simulated from its own start, minus the measured speeds: (2 m,), zero on padding. ``free``: the
    delay is ``params``' last entry (else ``delay`` is fixed). Unweighted: the fit divides by each channel's spread
    outside, so a re-weighting reuses the errors and their Jacobian."""
    model, delay = (params[:-1], params[-1]) if free else (params, delay)
    simulated = simulate_schedule(rate, model, delay, start, scheduled, interval_mean, substeps, used)
    return ((simulated - measured) * mask[:, None]).ravel()


@program(0, 2, 3)
def _residuals(rate, interval_mean, substeps, free, params, delay, starts, scheduled, measured, mask):
    """Every window's errors, (k, 2 m), the windows simulated side by side."""

    used = used_segments(scheduled[3])

    def one(start, window, speeds, logged):
        return _window_errors(rate, interval_mean, substeps, free, params, delay, start, window, speeds, logged, used)

    return jax.vmap(one)(starts, scheduled, measured, mask)


@program(0, 2, 3)
def _jacobians(rate, interval_mean, substeps, free, params, delay, starts, scheduled, measured, mask):
    """Each window's exact Jacobian of its errors (forward mode through its simulation) on the parameters (the
    delay last when free), (k, 2 m, p), and on its own start, (k, 2 m, 2): a window's errors depend on no other
    window's start."""

    used = used_segments(scheduled[3])

    def one(start, window, speeds, logged):
        def f(p, s):
            return _window_errors(rate, interval_mean, substeps, free, p, delay, s, window, speeds, logged, used)

        return jax.jacfwd(f, argnums=(0, 1))(params, start)

    return jax.vmap(one)(starts, scheduled, measured, mask)


Blocks = tuple[np.ndarray, np.ndarray, np.ndarray]  #: J^T J's blocks A, B, D (:func:`normal_blocks`)
Gradient = tuple[np.ndarray, np.ndarray]  #: J^T r on the parameters and on each window's start


def normal_blocks(j_params: np.ndarray, j_starts: np.ndarray) -> Blocks:
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


def lm_step(blocks: Blocks, g_params: np.ndarray, g_starts: np.ndarray, damping: float) -> np.ndarray:
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


def covariance(blocks: Blocks, r: np.ndarray, dof: int) -> np.ndarray:
    """The parameters' block of the Gauss-Newton covariance, S^-1 |r|^2 / dof (raises where S cannot be
    inverted)."""
    return np.linalg.pinv(schur(*blocks)[0]) * float(r @ r) / max(dof, 1)


def standard_errors(blocks: Blocks, r: np.ndarray, dof: int) -> np.ndarray:
    """The parameters' standard errors at the current linearisation, to judge a step by (inf where S is
    singular, so no step is judged small by them)."""
    try:
        return np.sqrt(np.clip(np.diag(covariance(blocks, r, dof)), 0.0, None))
    except np.linalg.LinAlgError:
        return np.full(len(blocks[0]), np.inf)


def negligible(linearised: tuple[Blocks, Gradient, np.ndarray], still: float, n_params: int) -> bool:
    """Whether the undamped (Gauss-Newton) step from this linearisation moves every parameter by at most ``still``
    of its standard error: converged. (A damped step is short for its damping, not for being near the minimum.)"""
    blocks, gradient, std = linearised
    try:
        step = lm_step(blocks, *gradient, 0.0)[:n_params]
    except np.linalg.LinAlgError:
        return False
    return bool(np.all(np.abs(step) <= still * std))


def crossing(t: np.ndarray, sent_t: np.ndarray, sent: np.ndarray, before: float, after: float) -> float | None:
    """The corner (:func:`ddtrack.sysid.schedule.nearest_corner` of ``before``) a step of the delay from ``before``
    to ``after`` [s] crossed or landed on, else None."""
    corner = nearest_corner(t, sent_t, sent, before)
    return corner if (before - corner) * (after - corner) <= 0.0 and before != corner else None


def holding(blocks: Blocks, gradient: Gradient, i: int) -> tuple[Blocks, Gradient]:
    """The normal equations with parameter ``i`` held where it is: its row and column of J^T J a unit's, its
    gradient 0, so the step leaves it and solves the others given it."""
    a, b, d = blocks
    a, b, g = a.copy(), b.copy(), gradient[0].copy()
    a[i, :], a[:, i], b[:, i, :], g[i] = 0.0, 0.0, 0.0, 0.0
    a[i, i] = 1.0
    return (a, b, d), (g, gradient[1])


class OutputError(NamedTuple):
    """An output-error fit of one reading of the speeds."""

    params: np.ndarray  #: (p,)
    std: np.ndarray  #: (p,) their standard errors
    cost: float  #: each channel's mean squared residual over its signal's variance, summed: comparable between fits
    noise: np.ndarray  #: (2,) each channel's residual spread
    windows: int  #: windows fitted, each with its own two start speeds
    substeps: int  #: RK4 steps per segment
    covariance: np.ndarray  #: (p, p) the parameters' block of the Gauss-Newton covariance
    delay: float  #: [s] the input delay
    delay_std: float  #: [s] its standard error (0 where it was held fixed)


class Record(NamedTuple):
    """The fitted part of a log: the measurements and the inputs on their own time base."""

    t: np.ndarray  #: (n,) measurement stamps [s]
    speed: np.ndarray  #: (n, 2)
    sent_t: np.ndarray  #: (m,) input stamps [s], on the measurements' clock
    sent: np.ndarray  #: (m, 2)
    slots: int  #: segments per measurement interval (:func:`ddtrack.sysid.schedule.slots_for`)


def output_error(
    model: SpeedModel,
    record: Record,
    start: np.ndarray,
    delay: float,
    *,
    max_delay: float,
    interval_mean: bool,
    window: float = WINDOW,
    substeps: int = SUBSTEPS,
    iterations: int = 40,
) -> OutputError:
    """Levenberg-Marquardt from ``start`` and ``delay`` [s] on the model's parameters, the delay (within 0 to
    ``max_delay``; fixed at ``delay`` when ``max_delay`` is 0) and, per window of ``window`` [s], the window's
    initial speeds (multiple shooting: no continuity between windows; each window starts from its measured first
    sample). The residuals of all windows are stacked; the standard errors are the parameters' block of the
    Gauss-Newton covariance s^2 (J^T J)^-1, s^2 = |r|^2 / (residuals - p - 2 k), the k windows' starts counted."""
    t, speed, sent_t, sent, slots = record
    windows = cut(t, speed, window)
    if interval_mean:
        windows = unread_starts(windows)
    measured, mask = jnp.asarray(windows.speed), jnp.asarray(windows.mask)
    count, n_model = len(windows.mask), start.size
    free = max_delay > 0
    n_params = n_model + int(free)

    held = None if free else windowed(schedule(t, sent_t, sent, delay, slots), windows)  # a fixed delay's, once

    def args(q: np.ndarray, nudge: float = 0.0) -> tuple:
        params = q[:n_params].copy()
        scheduled = held
        if free:  # the schedule and the simulation both see the nudged delay (else a switch clips to a corner)
            params[n_model] += nudge
            scheduled = windowed(schedule(t, sent_t, sent, params[n_model], slots), windows)
        starts = jnp.asarray(q[n_params:].reshape(count, 2))
        return jnp.asarray(params), delay, starts, scheduled, measured, mask

    last: dict[str, tuple[bytes, tuple[np.ndarray, ...]]] = {}  # "r" and "J": the q last evaluated at, its values

    def evaluated(kind: str, q: np.ndarray) -> tuple[np.ndarray, ...]:
        """The unweighted errors ("r") or their Jacobians ("J") at q, computed once: a pass's re-weighting and the
        covariance at the end are taken where the last linearisation stands."""
        if kind not in last or last[kind][0] != q.tobytes():
            if kind == "r":
                values: tuple = (_residuals(model.rate, interval_mean, substeps, free, *args(q)),)
            else:
                values = _jacobians(model.rate, interval_mean, substeps, free, *args(q, CORNER))
            last[kind] = q.tobytes(), tuple(np.asarray(v) for v in values)
        return last[kind][1]

    # each channel times the inverse of its spread: the very rounding of the division XLA made when it was inside
    def residual_fn(q: np.ndarray, w: np.ndarray) -> np.ndarray:  # q = (params, delay, each window's start speeds)
        return (evaluated("r", q)[0].reshape(count, -1, 2) * (1.0 / w)).ravel()

    def jacobian_fn(q: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rows = np.tile(1.0 / w, len(windows.mask[0]))[:, None]  # a window's rows alternate v, omega
        j_params, j_starts = evaluated("J", q)
        return j_params * rows, j_starts * rows

    positive = list(model.positive)
    q = np.concatenate([start, [delay] if free else [], windows.speed[:, 0].ravel()])
    q[positive] = np.maximum(q[positive], 1e-3 * np.maximum(np.abs(q[positive]).max(), 1e-6))
    spread = np.maximum(np.std(speed, axis=0) * 0.01, 1e-6)  # first weights; re-estimated from the residuals
    if not np.all(np.isfinite(residual_fn(q, spread))):  # noisy coupling terms can make it blow up
        q[list(model.couplings)] = 0.0
    if not np.all(np.isfinite(residual_fn(q, spread))):  # no fit from here
        return _failed(q[:n_model], count, substeps, delay)
    logged = windows.mask.ravel() > 0
    dof = 2 * int(logged.sum()) - q.size  # the windows' starts are fitted too
    for still in (STILL_FIRST, STILL):  # fit, re-weight each channel by its residual spread, fit again
        weights = spread  # this pass's; the pass ends with new spreads
        damping, r = 1e-3, residual_fn(q, weights)
        linearised: tuple[Blocks, Gradient, np.ndarray] | None = None  # J^T J, J^T r and the standard errors at q
        crossed = pinned = None  # the corner the last step crossed; the delay held at a corner it bounced across
        for _ in range(iterations):
            if linearised is None:  # a rejected step leaves q, so its Jacobian stands
                j_params, j_starts = jacobian_fn(q, weights)
                if not (np.all(np.isfinite(j_params)) and np.all(np.isfinite(j_starts))):
                    break  # the tangents blew up (a stiff model beyond MAX_SUBSTEPS): no step from here
                rows = r.reshape(count, -1)
                blocks = normal_blocks(j_params, j_starts)
                gradient = np.einsum("kri,kr->i", j_params, rows), np.einsum("kri,kr->ki", j_starts, rows)
                linearised = blocks, gradient, standard_errors(blocks, r, dof)
                if pinned is not None:
                    blocks, gradient = holding(blocks, gradient, n_model)
                    linearised = blocks, gradient, linearised[2]
                if negligible(linearised, still, n_params):
                    break
            blocks, gradient, _ = linearised
            try:
                trial = q + lm_step(blocks, *gradient, damping)
            except np.linalg.LinAlgError:  # a window's start no longer moves its samples: damp more
                trial = np.full_like(q, np.nan)
            if free and np.isfinite(trial[n_model]):
                trial[n_model] = np.clip(trial[n_model], 0.0, max_delay)
            if np.all(trial[positive] > 0):
                r_trial = residual_fn(trial, weights)
                if np.all(np.abs(r_trial) < 1e150) and r_trial @ r_trial < r @ r:  # a diverged trial is no step
                    shrink = (r @ r - r_trial @ r_trial) / max(r @ r, 1e-300)
                    corner = crossing(t, sent_t, sent, q[n_model], trial[n_model]) if free and pinned is None else None
                    bounced = corner is not None and crossed is not None and abs(corner - crossed) < CORNER
                    if bounced:  # back across the corner the last step crossed: try the corner itself
                        at = trial.copy()
                        at[n_model] = corner
                        r_at = residual_fn(at, weights)
                        if r_at @ r_at <= r_trial @ r_trial:
                            trial, r_trial, pinned = at, r_at, corner
                    q, r, damping, linearised, crossed = trial, r_trial, max(damping / 3.0, 1e-9), None, corner
                    if shrink < 1e-12:
                        break
                    continue
            damping *= 4.0
            if damping > 1e9:
                break
        spread = np.maximum(np.std((r.reshape(-1, 2) * np.asarray(weights))[logged], axis=0), 1e-9)
    r = residual_fn(q, spread)
    jacobians = jacobian_fn(q, spread)
    cost = float(np.sum(spread**2 / np.var(speed, axis=0)))
    fitted_delay = float(q[n_model]) if free else delay
    if not (np.all(np.isfinite(r)) and all(np.all(np.isfinite(j)) for j in jacobians)):
        return _failed(q[:n_model], count, substeps, fitted_delay)
    try:
        full = covariance(normal_blocks(*jacobians), r, dof)
    except np.linalg.LinAlgError:
        return _failed(q[:n_model], count, substeps, fitted_delay)
    std = np.sqrt(np.clip(np.diag(full), 0.0, None))
    delay_std = float(std[n_model]) if free else 0.0
    model_block = full[:n_model, :n_model]
    return OutputError(q[:n_model], std[:n_model], cost, spread, count, substeps, model_block, fitted_delay, delay_std)


def _failed(params: np.ndarray, count: int, substeps: int, delay: float) -> OutputError:
    """No fit from this start: infinite cost and uncertainty, so another start or reading wins."""
    infinite = np.full(params.size, np.inf)
    return OutputError(params, infinite, np.inf, np.full(2, np.inf), count, substeps, np.diag(infinite), delay, np.inf)
