"""Scenarios that cannot mean what they say, caught when they are loaded.

:func:`check` refuses (with :class:`ConfigError`, exit code 2) a reference the robot cannot follow because it asks
for at least the controller's clamp on speed or yaw rate (a 1 m/s line for a robot clamped at 0.22 m/s ran "ok" with
1.89 m of error), an angle beyond 2 pi (``heading = 45`` is almost surely degrees; it ran as a 58.3 deg line), and
masses and inertias whose radius of gyration cannot belong to a robot of that size (a mass in grams), and an
open-loop plan beyond the top speed or yaw rate of the ``robot.preset``. It returns
warnings, each ``{"code", "message"}``, for a reference within 10 % of a clamp or beyond the top speed or yaw rate
of the ``robot.preset``, an inner loop that the control period makes unstable (or a sliding-mode boundary layer it
makes chatter), and what loading the trajectory changed (repeated waypoints dropped).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from functools import cache
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from .compilations import keep, ledger_entry, padded_length
from .errors import ConfigError
from .precision import require_float64

NEAR_LIMIT = 0.9  #: a reference above this fraction of a clamp leaves the feedback no room: warned
MAX_SAMPLES = 20_001
#: radius of gyration sqrt(I / m) against the half axle L: a robot's body lies within about 0.2 to 2 L; outside
#: [1/20, 20] L the units are wrong (a mass in grams makes it 30 times too small)
GYRATION_RANGE = (0.05, 20.0)


_FACTS: dict[str, ReferenceFacts] = {}  # this process's: loading checks them, a run's bounds read them again
FACTS = "ddtrack-references"  #: beside JAX's cache: each reference's facts, one small JSON file per key


class ReferenceFacts(NamedTuple):
    """What loading needs to know of a reference, from its samples every control period over the run."""

    peak_speed: float  #: largest |v_r| [m/s]
    peak_yaw_rate: float  #: largest |omega_r| [rad/s]
    start: tuple[float, float]  #: (x_r, y_r) at t = 0 [m]
    extent: float  #: the farthest the reference goes from its start [m]
    width: float  #: the larger side of the samples' bounding box [m]


@cache  # one jitted function: a new one per scenario compiled again each time (its cache is its own)
def _sampler() -> Callable[..., Any]:  # (trajectory, times) -> Reference; this layer sits below both
    import jax

    return jax.jit(lambda trajectory, t: jax.vmap(trajectory)(t))  # one program, kept by the persistent cache


def sample_reference(scenario: Any) -> Any:
    """The scenario's reference every control period over the run (at most 20,001 samples), as NumPy arrays."""
    require_float64()  # the reference is sampled in JAX
    import jax

    sim = scenario.simulation
    samples = min(MAX_SAMPLES, int(sim.duration / sim.control_period) + 1)
    times = np.linspace(0.0, sim.duration, samples)
    padded = np.concatenate([times, np.full(padded_length(samples) - samples, sim.duration)])
    reference = _sampler()(scenario.trajectory.build(), padded)  # each sample is its own time's alone
    return jax.tree_util.tree_map(lambda column: np.asarray(column)[:samples], reference)


def reference_facts(scenario: Any) -> ReferenceFacts:
    """The :class:`ReferenceFacts` of ``scenario``'s reference. Kept beside the persistent compilation cache where
    this process has it on (the ``ddtrack`` command does), keyed by the trajectory's every value, the run's duration
    and control period, and this package's source and JAX's version: loading a scenario whose reference was seen
    before then compiles and runs nothing (issue: validation compiled the sampler, 0.1 to 0.3 s a scenario)."""
    import jax

    sim = scenario.simulation
    key = ledger_entry(f"reference {scenario.trajectory.model_dump_json()} {sim.duration!r} {sim.control_period!r}")
    if key in _FACTS:
        return _FACTS[key]
    folder = jax.config.jax_compilation_cache_dir  # type: ignore[attr-defined]  # read(), refused for this flag
    path = Path(folder) / FACTS / f"{key}.json" if folder else None
    try:
        facts = ReferenceFacts(**json.loads(path.read_text())) if path else None
    except (OSError, ValueError, TypeError):  # absent, cut short or of an older layout: sampled again
        facts = None
    if facts is None:
        reference = sample_reference(scenario)
        x, y = reference.x, reference.y
        facts = ReferenceFacts(
            peak_speed=float(np.max(np.abs(reference.v))),
            peak_yaw_rate=float(np.max(np.abs(reference.omega))),
            start=(float(x[0]), float(y[0])),
            extent=float(np.max(np.hypot(x - x[0], y - y[0]))),
            width=float(max(np.ptp(x), np.ptp(y))),
        )
        if path:
            keep(path, json.dumps(facts._asdict()).encode())
    facts = facts._replace(start=(facts.start[0], facts.start[1]))  # JSON gives a list
    if len(_FACTS) >= 64:
        _FACTS.pop(next(iter(_FACTS)))
    _FACTS[key] = facts
    return facts


def reference_peaks(scenario: Any) -> tuple[float, float]:
    """Largest |v_r| [m/s] and |omega_r| [rad/s] of the scenario's reference, sampled every control period."""
    facts = reference_facts(scenario)
    return facts.peak_speed, facts.peak_yaw_rate


def divergence_bound(scenario: Any) -> float:
    """The tracking error [m] beyond which a run has diverged, scaled with the scenario: 3 (e_0 + extent + 2 L),
    e_0 the initial distance to the reference, extent the farthest the reference goes from its start, L the half
    axle. A fixed 50 m let a Burger on a 0.5 m circle wander 50 m before it counted as lost."""
    facts = reference_facts(scenario)
    start = scenario.initial.pose if scenario.initial.pose is not None else facts.start
    initial = math.hypot(start[0] - facts.start[0], start[1] - facts.start[1])
    return 3.0 * (initial + facts.extent + 2.0 * scenario.plant_params().half_axle)


def reference_width(scenario: Any) -> float:
    """The larger side [m] of the bounding box of the reference's samples."""
    return reference_facts(scenario).width


def _speed_field(scenario: Any) -> str:
    return "trajectory.speed" if "speed" in type(scenario.trajectory).model_fields else "trajectory"


def check_clamps(scenario: Any, peaks: tuple[float, float]) -> list[dict]:
    """Refuse a reference at or above the controller's clamps; warn within 10 % of them."""
    controller, warnings = scenario.controller, []
    limits = (getattr(controller, "max_velocity", None), getattr(controller, "max_yaw_rate", None))
    names = (
        ("speed", "m/s", "controller.max_velocity", _speed_field(scenario)),
        ("yaw rate", "rad/s", "controller.max_yaw_rate", "trajectory"),
    )
    for peak, limit, (what, unit, clamp, field) in zip(peaks, limits, names, strict=True):
        if limit is None:
            continue
        if peak >= limit:
            hint = (
                f"slow the reference below {NEAR_LIMIT * limit:.3g} {unit}, or raise {clamp} to what your robot "
                "can really do"
            )
            if what == "speed" and peak / 3.6 < limit:
                hint += f" (if {peak:g} was meant in km/h, that is {peak / 3.6:.3g} m/s)"
            raise ConfigError(
                field,
                f"the reference's {what} reaches {peak:.3g} {unit}, at or above {clamp} = "
                f"{limit:g} {unit}: the robot cannot follow it and would run saturated, off the path",
                hint,
            )
        if peak > NEAR_LIMIT * limit:
            warnings.append(
                {
                    "code": "reference_near_limit",
                    "message": (
                        f"the reference's {what} reaches {peak:.3g} {unit}, {100 * peak / limit:.3g} % of {clamp} = "
                        f"{limit:g} {unit}: little is left for the feedback to correct errors"
                    ),
                }
            )
    return warnings


def check_robot_limits(scenario: Any, peaks: tuple[float, float]) -> list[dict]:
    """Warn where the reference exceeds the true robot's top speed or yaw rate (``Scenario.top_speeds``: the
    ``robot.preset``'s, its motors' at their supply voltage); the simulated plant may follow it, the real robot could
    not. Nothing is changed: the controller's clamps stay as the file sets them."""
    top_speed, top_yaw_rate, what = scenario.top_speeds()
    warnings = []
    for quantity, unit, top, peak in (
        ("speed", "m/s", top_speed, peaks[0]),
        ("yaw rate", "rad/s", top_yaw_rate, peaks[1]),
    ):
        if top is not None and peak > top:
            warnings.append(
                {
                    "code": "reference_beyond_robot",
                    "message": f"the reference's {quantity} reaches {peak:.3g} {unit}, above the top {quantity} of "
                    f"{what}, {top:.3g} {unit}: the real robot could not follow it",
                }
            )
    return warnings


def check_open_loop(scenario: Any) -> None:
    """Refuse an open-loop controller's plan (``[controller] kind = "replay"``, through its ``check_within``) that
    commands more than the true robot's top speed or yaw rate (``Scenario.top_speeds``): unlike a reference, no clamp
    stands between the plan and the plant, and a log of it would describe a robot that does not exist."""
    within = getattr(scenario.controller, "check_within", None)
    if callable(within):
        top_speed, top_yaw_rate, what = scenario.top_speeds()
        if top_speed is not None or top_yaw_rate is not None:
            within(top_speed, top_yaw_rate, what)


def check_angles(scenario: Any) -> None:
    """Refuse an angle beyond 2 pi, naming it in degrees and radians."""
    angles = []
    if "heading" in type(scenario.trajectory).model_fields:
        angles.append(("trajectory.heading", scenario.trajectory.heading))
    if scenario.initial.pose is not None:
        angles.append(("initial.pose[2]", scenario.initial.pose[2]))
    for field, angle in angles:
        if abs(angle) > 2.0 * math.pi:
            raise ConfigError(
                field,
                f"{angle:g} rad is more than a full turn: angles are in radians",
                f"if you meant {angle:g} degrees, write {math.radians(angle):.10g}",
            )


def check_units(scenario: Any) -> None:
    """Refuse a mass and inertia whose radius of gyration is far off the robot's size (units mixed up)."""
    for section, params in (("robot", scenario.robot.params()), ("plant", scenario.plant_params())):
        gyration = math.sqrt(params.inertia / params.mass) / params.half_axle
        if not GYRATION_RANGE[0] <= gyration <= GYRATION_RANGE[1]:
            raise ConfigError(
                f"{section}.mass, {section}.inertia, {section}.half_axle",
                (
                    f"{params.mass:g} kg with inertia {params.inertia:g} kg m^2 gives a radius of gyration "
                    f"{math.sqrt(params.inertia / params.mass):.3g} m, {gyration:.3g} times the half axle "
                    f"{params.half_axle:g} m; a robot's lies within about 0.2 to 2 times"
                ),
                "masses are in kg (not g), inertias in kg m^2 (about m (0.5 L)^2 for a compact robot), lengths in m",
            )


def sampled_growth(rate: float, derivative: float, period: float) -> float:
    """How many times a velocity error grows per period in an inner loop of ``rate`` k [1/s] whose torque is held
    over ``period`` T [s], with ``derivative`` a = k K_D / K_P for the wheel PD's backward difference (0 for computed
    torque): the spectral radius of e_{k+1} = (1 - T k - a) e_k + a e_{k-1} (model.md §2.7). Below 1 the loop is
    stable, which holds when a < 1 and T k < 2 (1 - a)."""
    roots = np.roots([1.0, -(1.0 - period * rate - derivative), -derivative])
    return float(np.max(np.abs(roots)))


class Channel(NamedTuple):
    """One channel of a held inner loop on the true robot (model.md §2.7), rates in 1/s."""

    name: str  #: "v" or "omega"
    rate: float  #: k: the velocity error's decay rate in continuous time, the outer law's share included
    derivative: float  #: a: the wheel PD's backward-difference coefficient (0 for the other loops)
    per_gain: float  #: the rate per unit of the loop's gain (K_c of this channel, or K_P)
    feedback: float  #: the outer law's share of ``rate``: its nu_c_dot feeding back the measured velocity
    layer: float  #: the sliding term's share of the rate inside its boundary layer (0 for the other loops)


def inner_loop_channels(scenario: Any) -> list[Channel]:
    """The held inner loop's two channels on the true robot; [] for a controller without one (its config has no
    ``held_loop``, or inner = "none") or a robot too extreme for floating point (model.md §2.5-2.7)."""
    return _held_loop(scenario)[1]


def _held_loop(scenario: Any) -> tuple[str, list[Channel]]:
    controller = scenario.controller
    if not hasattr(controller, "held_loop"):
        return "", []
    nominal = scenario.robot.params()
    loop = controller.held_loop(nominal, reference_peaks(scenario)[0], scenario.simulation.control_period)
    if loop is None:
        return "", []
    try:
        channels = _channels(loop, nominal, scenario.plant_params())
    except (ZeroDivisionError, OverflowError):  # a robot too extreme for floating point has no rate to judge
        return "", []
    judged = all(
        math.isfinite(c.rate) and math.isfinite(c.derivative) and 0.0 < c.per_gain < math.inf for c in channels
    )
    return (loop.kind, channels) if judged else ("", [])


def _channels(loop: Any, nominal: Any, true: Any) -> list[Channel]:
    # the loop acts through the nominal model's M_hat and B_hat, i.e. on the true robot times m_hat / m and R_hat / R,
    # and L / L_hat for the yaw: c per channel
    forward = nominal.wheel_radius / true.wheel_radius
    scales = (
        forward * nominal.effective_mass / true.effective_mass,
        forward * true.half_axle / nominal.half_axle * nominal.effective_inertia_axle / true.effective_inertia_axle,
    )
    channels = []
    for i, (name, c) in enumerate(zip(("v", "omega"), scales, strict=True)):
        feedback = c * loop.feedforward[i] * loop.feedback[i]
        rate = c * loop.design[i] + feedback
        channels.append(
            Channel(name, rate, c * loop.derivative[i], c * loop.design[i] / loop.gain[i], feedback, c * loop.layer[i])
        )
    return channels


def _limit(channel: Channel, period: float) -> float:
    """The largest value of the loop's gain (K_c of the channel, or K_P) at half the channel's stability limit,
    T k <= 1 - a (model.md §2.7); the outer law's share stays."""
    return ((1.0 - channel.derivative) / period - channel.feedback) / channel.per_gain


def check_sampled_inner_loop(scenario: Any) -> list[dict]:
    """Warn when the inner velocity loop, its torque held over each control period, is unstable on the true robot
    (a run then diverges, or runs saturated, whatever the gains of the law above it: a 4 Hz loop on a Burger with
    K_c = 10 1/s diverged in 2.5 s, and the remedy named the gains), or, for sliding mode, when it is stable but
    its boundary layer is not (the torque then flips sign every period: a 20 Hz Burger chattered, reported fine)."""
    period = scenario.simulation.control_period
    kind, channels = _held_loop(scenario)
    unstable = [c for c in channels if sampled_growth(c.rate, c.derivative, period) >= 1.0]
    if unstable:
        return [_unstable(scenario, kind, channels, unstable)]
    chattering = [c for c in channels if c.layer and sampled_growth(c.rate + c.layer, 0.0, period) >= 1.0]
    return [_chattering(scenario, channels, chattering)] if chattering else []


def _growth(rate: float, derivative: float, period: float) -> str:
    growth = sampled_growth(rate, derivative, period)
    return f"grows {growth:.3g}-fold per period" if growth >= 1.005 else "does not decay (at the stability limit)"


def _rate(channel: Channel, rate: float) -> str:
    outer = f", {channel.feedback:.3g} 1/s of it from the outer law's command rate" if channel.feedback else ""
    return f"rate {rate:.3g} 1/s on the true robot{outer}"


def _unstable(scenario: Any, kind: str, channels: list[Channel], unstable: list[Channel]) -> dict:
    period = scenario.simulation.control_period
    controller = scenario.controller
    causes = [
        f"its {c.name} channel's velocity error ({_rate(c, c.rate)}) {_growth(c.rate, c.derivative, period)}"
        for c in unstable
    ]
    # advised at half the stability limit on every channel (T k <= 1 - a), as the linearisation holds only near the
    # reference; without a derivative the error then also decays without flipping sign each period
    fixes = []
    if all(c.derivative < 1.0 for c in channels):
        fixes.append(f"simulation.control_period to {min((1 - c.derivative) / c.rate for c in channels):.3g} s or less")
    limits = [_limit(c, period) for c in channels]
    if kind == "pd" and any(c.derivative >= 1.0 for c in channels):  # the PD's derivative alone, at any period
        per_kd = [c.derivative / controller.kd for c in channels]
        fixes.append(f"controller.kd to {min(0.5 / d for d in per_kd):.3g} N m s^2/rad or less, then validate again")
    elif kind == "pd" and min(limits) > 0.0:
        fixes.append(f"controller.kp to {min(limits):.3g} N m s/rad or less")
    elif kind != "pd" and all(limit > 0.0 for limit in limits):  # one K_c per channel
        advised = [min(kc, limit) for kc, limit in zip(controller.kc, limits, strict=True)]
        fixes.append(f"controller.kc to [{advised[0]:.3g}, {advised[1]:.3g}] 1/s or less")
    elif kind != "pd" and hasattr(controller, "gains"):  # Kanayama's law alone, through nu_c_dot, is too fast
        fixes.append("lower controller.gains")
    return {
        "code": "sampled_inner_loop_unstable",
        "message": (
            f"the inner loop ({kind}) is unstable with its torques held over "
            f"simulation.control_period = {period:g} s: {'; '.join(causes)} until the torque limit "
            f"bounds it (the run diverges or runs saturated); set {', or '.join(fixes)} (half the stability limit "
            "on each channel, for a margin)"
        ),
    }


def stable_boundary_layer(scenario: Any) -> tuple[float, float] | None:
    """The sliding-mode boundary layer phi [m/s, rad/s] at half the stability limit of the held loop inside it,
    T (k + c K_s / phi) <= 1 on each channel, and never narrower than the scenario's (model.md §2.7); None for a
    controller without a layer, or where no width is enough (T k >= 1 outside the layer already)."""
    period = scenario.simulation.control_period
    channels = inner_loop_channels(scenario)
    if not any(c.layer for c in channels) or any(c.rate * period >= 1.0 for c in channels):
        return None
    phi = scenario.controller.boundary_layer
    width = [
        p if not c.layer else max(p, p * c.layer / (1.0 / period - c.rate)) for p, c in zip(phi, channels, strict=True)
    ]
    return (width[0], width[1])


def _chattering(scenario: Any, channels: list[Channel], chattering: list[Channel]) -> dict:
    period = scenario.simulation.control_period
    causes = [
        f"its {c.name} channel's velocity error inside the layer ({_rate(c, c.rate + c.layer)}) "
        f"{_growth(c.rate + c.layer, 0.0, period)}"
        for c in chattering
    ]
    fixes = [f"simulation.control_period to {min(1.0 / (c.rate + c.layer) for c in channels):.3g} s or less"]
    width = stable_boundary_layer(scenario)
    if width is not None:
        fixes.append(f"controller.boundary_layer to [{width[0]:.3g}, {width[1]:.3g}] or wider")
    return {
        "code": "sampled_inner_loop_chatters",
        "message": (
            f"the sliding-mode loop's boundary layer is unstable with its torques held over "
            f"simulation.control_period = {period:g} s: {'; '.join(causes)}, so the torque flips sign every period "
            f"(chattering, which the layer is there to prevent); set {', or '.join(fixes)} (half the stability "
            "limit on each channel, for a margin)"
        ),
    }


def check(scenario: Any) -> list[dict]:
    """Run every check on a validated scenario; return the warnings (raise :class:`ConfigError` on a refusal)."""
    check_angles(scenario)
    check_units(scenario)
    check_open_loop(scenario)
    peaks = reference_peaks(scenario)
    loading = list(getattr(scenario.trajectory, "load_warnings", []))  # e.g. repeated waypoints dropped
    return [
        *loading,
        *check_clamps(scenario, peaks),
        *check_robot_limits(scenario, peaks),
        *check_sampled_inner_loop(scenario),
    ]
