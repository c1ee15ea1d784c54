"""The fitting engine shared by every model ``ddtrack identify`` fits (docs/identification.md).

A model here maps a parameter vector, the body speeds (v, omega) and a two-channel input (velocity commands, or
wheel torques, or voltages) to the speeds' rates, and is linear in its parameters once the rates are known. The
inputs keep their own stamps (:mod:`ddtrack.sysid.schedule`): each acts from its stamp plus a delay until the next
one does, whatever the measurements' rate. The delay is first screened on a grid of half samples by the equation
error (linear least squares on the model's equations integrated over short spans), which also starts the parameters;
then an output-error fit (:mod:`ddtrack.sysid.output_error`) moves the model's parameters and the delay together,
a continuous quantity with its own standard error. The measured speeds are read either as instants or as means
over each sample interval (odometry's encoder increments); the reading with the smaller residual wins. The last
quarter of the log is held out and predicted by one simulation from the last fitted sample.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np

from ..errors import ConfigError
from .output_error import SUBSTEPS, WINDOW, OutputError, Record, output_error
from .schedule import held_at, program, schedule, simulate_jit, slots_for

HELD_OUT = 0.25  #: the last quarter of the log is not fitted: it tells how well the model predicts
MAX_SUBSTEPS = 64
#: the largest |rate Jacobian eigenvalue| x RK4 step allowed: Coulomb friction's tanh corner is stiff at rest (a
#: small robot's 1/eps_f slope reaches 1600 1/s), and beyond RK4's stability (2.79) the tangents of jacfwd blow up
STIFF_STEP = 0.5
MIN_SAMPLES = 80
#: intervals per call of the compiled simulation, the last call padded: every length of log shares one program
CHUNK = 1024
#: [s] how far the screening looks for speeds that answer their inputs before they were sent (clocks apart)
LEAD = 1.0
#: [s] the screening's coarse grid: a log faster than 100 Hz is screened on it first, then on half samples around
#: its minima (the equation error's dip at the delay is about as wide as its spans, SPAN)
SCREEN_STEP = 0.01
#: [s] the equation error's equations are integrated over spans this long (at least two samples)
SPAN = 0.05


@dataclass(frozen=True)
class SpeedLog:
    """A log of a robot: the measured speeds (v [m/s], omega [rad/s]) at the times ``t`` [s] (increasing), and the
    inputs (velocity commands (v* [m/s], omega* [rad/s]), or wheel torques (tau_r, tau_l) [N m], or voltages)
    either on their own stamps ``sent_t`` [s] (same clock as ``t``; each held until the next) as ``sent``, or,
    without ``sent_t``, one per measurement as ``command`` (the input sent at t_k, held until t_{k+1}).
    ``command`` is always the input in force at each t (the last sent at or before it)."""

    t: np.ndarray  #: (n,)
    command: np.ndarray  #: (n, 2) the input
    speed: np.ndarray  #: (n, 2)
    source: str = ""
    rows: tuple[str, ...] = ()  #: where each sample is in the file ("line 12", "/odom message 7"), for errors
    sent_t: np.ndarray | None = None  #: (m,) the inputs' own stamps [s], or None: they are ``t``
    sent: np.ndarray | None = None  #: (m, 2) the inputs as sent, with ``sent_t``
    notes: tuple[str, ...] = ()  #: what reading the log corrected (a clock offset between its streams)

    def where(self, k: int) -> str:
        """Where sample ``k`` is in the file the log was read from (else "sample k")."""
        return self.rows[k] if len(self.rows) > k else f"sample {k}"

    def inputs(self) -> tuple[np.ndarray, np.ndarray]:
        """The inputs on their own time base: (stamps (m,) [s], values (m, 2))."""
        if self.sent_t is None:
            return np.asarray(self.t, dtype=float), np.asarray(self.command, dtype=float)
        return np.asarray(self.sent_t, dtype=float), np.asarray(self.sent, dtype=float)


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
    delay: float  #: [s] the input delay, fitted as a continuous quantity
    interval_mean: bool  #: the speeds fitted best as means over each sample interval (odometry), not instants
    noise: np.ndarray  #: (2,) residual spread of v [m/s] and omega [rad/s] on the fitted samples
    fit_percent: dict[str, float]  #: 100 (1 - |y - y_hat| / |y - mean y|) per speed, on the held-out quarter
    samples: tuple[int, int]  #: samples fitted, held out
    windows: int  #: output-error windows the fitted samples were cut into, each simulated from its own start
    covariance: np.ndarray  #: (p, p) of the parameters (the windows' starts eliminated); std is its diagonal's root
    substeps: int = SUBSTEPS  #: RK4 steps per segment of the model's simulation (more where it is stiff)
    notes: tuple[str, ...] = field(default=())  #: what this log could not separate, and what reading it corrected
    delay_std: float = 0.0  #: [s] the delay's standard error (0 where it was held at 0 by max_delay = 0)


def identify(model: SpeedModel, log: SpeedLog, *, max_delay: float = 0.3, window: float = WINDOW) -> SpeedFit:
    """Fit ``model`` and the input delay (0 to ``max_delay`` [s], continuous) to ``log``, the output error over
    windows of ``window`` [s] (``np.inf``: one simulation of the whole fitted record).

    Raises ConfigError for a log that cannot identify the model: too short, not increasing in time, an input
    channel that never changes, a measured speed that never changes, speeds that answer their inputs before they
    were sent (the two streams' clocks apart)."""
    t, sent_t, sent, speed = checked(log, model.input_names)
    n_fit = round(len(t) * (1.0 - HELD_OUT))
    record = Record(t[:n_fit], speed[:n_fit], sent_t, sent, slots_for(t, sent_t))
    delay = screened_delay(model, record, max_delay, log.source)
    longest = float(np.diff(t).max())
    start = np.asarray(equation_error(model, record.t, held_at(record.t, sent_t, sent, delay), record.speed))
    fits: dict[bool, OutputError] = {}
    substeps = substeps_for(model, start, speed, longest)
    for mean in (False, True):  # both readings of the speeds: instantaneous or interval means
        params, at, steps = start, delay, substeps
        if mean and np.isfinite(fits[False].cost):  # from the instants' optimum: read as means, h/2 less delay
            first = fits[False]
            params, at, steps = first.params, max(first.delay - 0.5 * float(np.median(np.diff(t))), 0.0), first.substeps
        fit = output_error(model, record, params, at, max_delay=max_delay, interval_mean=mean, window=window,
                           substeps=steps)  # fmt: skip
        stiffer = substeps_for(model, fit.params, speed, longest) if np.isfinite(fit.cost) else steps
        if stiffer > steps:  # the fit went where the start's steps are too long: again, from there
            fit = output_error(model, record, fit.params, fit.delay, max_delay=max_delay, interval_mean=mean,
                               window=window, substeps=stiffer)  # fmt: skip
        fits[mean] = fit
    mean = min(fits, key=lambda key: fits[key].cost)
    best = fits[mean]
    if not np.isfinite(best.cost):
        raise ConfigError(
            "LOG",
            f"{log.source}: the {model.name} model's simulation diverges from every start tried",
            "check the log's units and columns, and that --model is the robot's",
        )
    predicted = simulate(
        model, best.params, t[n_fit - 1 :], None, speed[n_fit - 1], mean, best.substeps,
        sent=(sent_t, sent), delay=best.delay,
    )  # fmt: skip
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
        params=best.params,
        std=best.std,
        delay=best.delay,
        interval_mean=mean,
        noise=best.noise,
        fit_percent=fit_percent,
        samples=(n_fit, len(t) - n_fit),
        windows=best.windows,
        covariance=best.covariance,
        substeps=best.substeps,
        notes=(*log.notes, *unseparated(model, best.params, best.std), *ambiguous_reading(fits)),
        delay_std=best.delay_std,
    )


def checked(log: SpeedLog, input_names: tuple[str, str]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The log's measurement stamps, input stamps, inputs and speeds, or a ConfigError saying why it cannot
    identify anything."""
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
    sent_t, sent = log.inputs()
    if (
        sent_t.ndim != 1
        or sent.shape != (sent_t.size, 2)
        or not np.all(np.isfinite(sent_t))
        or np.any(np.diff(sent_t) < 0)
    ):
        raise ValueError("input stamps (m,), increasing, and inputs (m, 2) expected")
    if not np.all(np.isfinite(sent)):
        raise ConfigError("LOG", f"{log.source}: an input is not a number", "drop that input")
    for i, name in enumerate(input_names):
        if np.ptp(sent[:, i]) == 0.0:
            raise ConfigError(
                "LOG",
                f"{log.source}: {name} never changes ({sent[0, i]:g}), so its effect cannot be seen",
                "drive an excitation plan (ddtrack excite) and record it",
            )
    for i, name in enumerate(("v", "omega")):
        if np.ptp(speed[:, i]) == 0.0:
            raise ConfigError("LOG", f"{log.source}: the measured {name} never changes", "check the measured topic")
    return t, sent_t, sent, speed


def screened_delay(model: SpeedModel, record: Record, max_delay: float, source: str) -> float:
    """The delay [s] in 0 to ``max_delay`` whose held inputs give the smallest equation error, on a grid of half
    the shorter median interval of the two streams; the output error refines it. The grid also runs back
    ``LEAD`` s: speeds explained best by inputs sent after them mean the streams' clocks are apart, and the log
    is refused, since a delay cannot be told from a clock offset."""
    t, speed, sent_t, sent, _ = record
    step = 0.5 * min(float(np.median(np.diff(t))), float(np.median(np.diff(sent_t))) if sent_t.size > 1 else np.inf)
    delays = delay_grid(step, max_delay)
    ahead = delays < 0
    costs = np.full(delays.size, np.inf)

    def screen(indices: np.ndarray) -> None:
        for i in indices[~np.isfinite(costs[indices])]:
            costs[i] = equation_error(model, t, held_at(t, sent_t, sent, delays[i]), speed, cost=True)

    ratio = max(1, int(SCREEN_STEP / step))  # a fast log is screened coarsely first, then finely around the minima
    screen(np.flatnonzero((np.arange(delays.size) - ahead.sum()) % ratio == 0))
    for i in (int(np.argmin(costs)), int(np.argmin(np.where(ahead, np.inf, costs)))):
        screen(np.arange(max(0, i - ratio + 1), min(delays.size, i + ratio)))
    best = int(np.argmin(costs))
    behind = int(np.argmin(np.where(ahead, np.inf, costs)))
    interval = float(np.median(np.diff(t)))
    if delays[best] < -interval and costs[best] < 0.9 * costs[behind]:
        raise ConfigError(
            "LOG",
            f"{source}: the speeds answer the inputs {-delays[best]:.3g} s before they were sent, so the two "
            "streams' clocks are apart and no delay can be fitted",
            "record both topics on one clock: stamp the odometry on the recording machine's clock (synchronise the "
            "robot's with chrony or NTP), or record a bag, whose receive times let identify measure the offset",
        )
    return float(min(delays[behind], max_delay))


def delay_grid(step: float, max_delay: float) -> np.ndarray:
    """The delays the screening can choose [s]: multiples of ``step`` from -LEAD to ``max_delay``."""
    return np.concatenate([-np.arange(1, int(LEAD / step) + 1)[::-1] * step, np.arange(0.0, max_delay + 1e-12, step)])


def equation_error(
    model: SpeedModel, t: np.ndarray, inputs: np.ndarray, speed: np.ndarray, *, cost: bool = False
) -> np.ndarray | float:
    """Parameters by linear least squares on the model's equations integrated over every span of ``SPAN`` [s] (at
    least two samples): the rates' terms integrate to the speeds' changes, so no derivative of noisy, quantised
    speeds is taken (a smoothed derivative cannot follow a drive of a few milliseconds, and its start would be
    stiff). The speeds' terms are integrated by the trapezoid rule, the inputs (held from each sample) exactly. A
    parameter the data does not excite is 0. With ``cost``, the squared residual instead."""
    dt = float(np.median(np.diff(t)))
    m = min(len(t) - 1, max(2, round(SPAN / dt)))
    change = np.concatenate([speed[m:] - speed[:-m], np.zeros((m, 2))])
    still, target = model.regressors(speed, np.zeros_like(speed), inputs)
    moved, _ = model.regressors(speed, change, inputs)  # the rows are linear in the rate: their rate part
    steps = np.diff(t)[:, None]

    def spans(x: np.ndarray, trapezoid: bool) -> np.ndarray:
        """Integrals of each equation's samples ``x`` (2 n, ...) over [t_k, t_k+m]."""
        per = x.reshape(2, len(t), -1)
        areas = 0.5 * (per[:, 1:] + per[:, :-1]) * steps if trapezoid else per[:, :-1] * steps
        total = np.concatenate([np.zeros((2, 1, per.shape[2])), np.cumsum(areas, axis=1)], axis=1)
        return total[:, m:] - total[:, :-m]

    rate_part = (moved - still).reshape(2, len(t), -1)[:, :-m]
    rows = (rate_part + spans(still, trapezoid=True)).reshape(-1, still.shape[1])
    target = spans(target[:, None], trapezoid=False).ravel()
    scale = np.linalg.norm(rows, axis=0)
    usable = scale > 1e-9 * max(scale.max(), 1e-300)
    solution = np.zeros(rows.shape[1])
    solution[usable], residual, *_ = np.linalg.lstsq(rows[:, usable], target, rcond=None)
    if cost:
        return float(residual[0]) if residual.size else float(np.sum((rows @ solution - target) ** 2))
    return solution


def simulate(
    model: SpeedModel,
    params: np.ndarray,
    t: np.ndarray,
    inputs: np.ndarray | None,
    start: np.ndarray,
    interval_mean: bool,
    substeps: int = SUBSTEPS,
    *,
    sent: tuple[np.ndarray, np.ndarray] | None = None,
    delay: float = 0.0,
) -> np.ndarray:
    """(v, omega) at each of the times ``t`` [s] from ``start`` at t[0], by ``substeps`` RK4 steps per segment:
    each of ``inputs`` held from its time until the next, or each input of ``sent`` = (stamps, values) held from
    its stamp plus ``delay`` [s] until the next; with ``interval_mean``, each sample after the first is the mean
    over the interval ending at it."""
    t = np.asarray(t, dtype=float)
    sent_t, values = (t, np.asarray(inputs, dtype=float)) if sent is None else sent
    scheduled = schedule(t, sent_t, values, delay, slots_for(t, sent_t))
    n = len(scheduled.step)
    padded = [np.concatenate([a, np.zeros((-n % CHUNK, *a.shape[1:]), a.dtype)]) for a in scheduled]  # held: h = 0
    state, samples = jnp.asarray(start), [jnp.asarray(start)[None]]
    for i in range(0, n, CHUNK):  # the chunks one after another, each from the last one's state
        chunk = tuple(jnp.asarray(a[i : i + CHUNK]) for a in padded)
        state, speeds = simulate_jit(model.rate, jnp.asarray(params), delay, state, chunk, interval_mean, substeps)
        samples.append(speeds)
    return np.asarray(jnp.concatenate(samples))[: n + 1]


def substeps_for(model: SpeedModel, params: np.ndarray, speed: np.ndarray, step: float) -> int:
    """RK4 steps per segment of at most ``step`` [s] that keep |lambda| h <= STIFF_STEP for the model at
    ``params``, lambda the eigenvalues of d rate / d speed at rest and at up to 64 of the logged ``speed``s: a power
    of two (so that a few compiled simulations serve every fit) from SUBSTEPS to MAX_SUBSTEPS."""
    points = np.concatenate([np.zeros((1, 2)), speed[:: max(1, len(speed) // 64)]])
    jacobians = _speed_jacobians(model.rate, jnp.asarray(params), jnp.asarray(points))
    stiffness = float(np.nan_to_num(np.abs(np.linalg.eigvals(np.asarray(jacobians))).max(), nan=np.inf))
    needed = max(stiffness * step / STIFF_STEP, 1.0)
    return int(np.clip(2 ** np.ceil(np.log2(needed)), SUBSTEPS, MAX_SUBSTEPS))


@program(0)
def _speed_jacobians(rate, params, points):
    return jax.vmap(jax.jacfwd(lambda s: rate(params, s, jnp.zeros(2))))(points)


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


#: two readings whose costs are closer than this (relative) fit the log equally well
SAME_COST = 0.02


def ambiguous_reading(fits: dict[bool, OutputError]) -> tuple[str, ...]:
    """A note when the speeds fit as well read as instants as read as each interval's mean: a mean over an
    interval h is, to second order, the instant h/2 before its end, so the reading trades against h/2 of delay."""
    instants, means = fits[False], fits[True]
    if not (np.isfinite(instants.cost) and np.isfinite(means.cost)):
        return ()
    if abs(instants.cost - means.cost) > SAME_COST * min(instants.cost, means.cost):
        return ()
    return (
        f"the speeds fit as well read as instants (delay {instants.delay:.4f} s) as read as means over each sample "
        f"interval (delay {means.delay:.4f} s): this log cannot tell them apart; if the speeds are odometry's (wheel "
        "encoder increments over each interval) the second delay is the robot's",
    )


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
