"""Seeds and randomness, single runs and batches, and what a run's metrics and warnings are (docs/architecture.md).

Studies of many runs that keep only their metrics are in :mod:`ddtrack.studies.batches`.

One seed is split, in a fixed order, into streams for the plant-parameter draw, the disturbance,
the measurement noise and the controller. So swapping the controller leaves the plant and its
disturbances unchanged (common random numbers).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from functools import partial
from typing import cast

import jax
import numpy as np
from jax import Array

from . import feasibility
from .adaptation import adaptation_warnings
from .compilations import bucketed_length, call_exported, padded_length
from .compilations import enable_compilation_cache as enable_compilation_cache  # its home before
from .controllers import Emulator, TorqueLaw
from .identification import Identification, identify
from .integrators import RK4
from .layout import BODY, WHEEL_TORQUES
from .metrics import lost_path_warnings, summarize
from .model import MeasurementNoise, RobotParams, WheelDisturbance
from .plausibility import motor_metrics, motor_warnings, speed_warnings, traction_columns, traction_warnings
from .scenario import NNAdaptiveConfig, ParameterDraw, Scenario, Setup, build
from .scenario.motor_configs import check_drive, motor_or_none
from .sim import ClosedLoop, Draws, SimResult, repeated, simulate_alone, simulate_batch, stack, timeseries, vmap_runs
from .sim.batch import Batched, in_shares
from .trajectories.switched import TrajectoryFrame

STREAMS = ("parameters", "disturbance", "noise", "controller")


def streams(seed: int) -> dict[str, jax.Array]:
    """The run's independent PRNG keys, by name."""
    return dict(zip(STREAMS, jax.random.split(jax.random.PRNGKey(seed), len(STREAMS)), strict=True))


def draw_plant(scenario: Scenario, key: jax.Array) -> RobotParams:
    """The true plant with the ``[randomize]`` draws applied. Each parameter has its own sub-key
    (folded in by field position), so adding a draw never changes another's value."""
    plant = scenario.plant_params()
    changes = {}
    for index, (field, draw) in enumerate(scenario.randomize):
        if draw is not None:
            changes[field] = _draw(getattr(plant, field), draw, jax.random.fold_in(key, index))
    return dataclasses.replace(plant, **changes)


def _draw(value: float, draw: ParameterDraw, key: jax.Array) -> float:
    if draw.distribution == "uniform":
        r = jax.random.uniform(key, minval=-1.0, maxval=1.0)
    else:
        r = jax.random.truncated_normal(key, -3.0, 3.0)
    if draw.relative is not None:
        return float(value * (1.0 + draw.relative * r))
    assert draw.absolute is not None  # ParameterDraw's validator requires exactly one of the two
    return float(value + draw.absolute * r)


@partial(jax.jit, static_argnames="n_steps")
def _seed_draws(seed: int, n_steps: int) -> tuple[dict, tuple, Array, Array]:
    """Every key and standard-normal draw of one run as one program: drawn one by one, each is a dispatch of
    its own, and together they cost an interactive run more than the simulation (same bits either way).
    ``n_steps`` is padded (:func:`~ddtrack.compilations.padded_length`): one program serves runs of many lengths.
    JAX's partitionable Threefry draws element i from the key and i alone, so the caller's first rows are the same
    bits as an array of exactly the run's length."""
    keys = streams(seed)
    disturbance = jax.random.normal(keys["disturbance"], (n_steps, len(WHEEL_TORQUES)))
    return (
        keys,
        tuple(jax.random.split(keys["controller"], 3)),
        disturbance,
        jax.random.normal(keys["noise"], (n_steps, len(BODY))),  # on what every plant reports
    )


def controller_keys(seed: int) -> tuple[jax.Array, jax.Array, jax.Array]:
    """The controller stream split into (construction, identification, run) keys."""
    k_build, k_identify, k_run = jax.random.split(streams(seed)["controller"], 3)
    return k_build, k_identify, k_run


def needs_identification(scenario: Scenario) -> bool:
    """True for an NN-adaptive controller whose emulator is pre-trained on an identification run (model.md §3.7)."""
    return isinstance(scenario.controller, NNAdaptiveConfig) and scenario.controller.identification


def prepare(
    scenario: Scenario, *, seed: int | None = None, identification: Identification | None = None, identify: bool = True
) -> tuple[Setup, Draws]:
    """Build the run's objects and draw all of its randomness from ``seed`` (default the scenario's).

    ``identification`` reuses an emulator identified for the same plant and seed (ablations that only
    change the gain law), instead of identifying again; ``identify=False`` skips it (a batch identifies
    all its runs at once).

    Parameters
    ----------
    scenario : Scenario
        A validated scenario (:func:`ddtrack.load_scenario`).
    seed : int, optional
        Replaces ``simulation.seed``; split into the parameters, disturbance, noise and controller streams.
    identification : Identification, optional
        An emulator already identified for this plant and seed (NN-adaptive controllers only).
    identify : bool
        Pre-train an NN-adaptive controller's emulator now (model.md §3.7).

    Returns
    -------
    setup : Setup
        The nominal model, the true plant (with its ``[randomize]`` draws), the controller, the trajectory,
        the initial state, the disturbance and the noise models.
    draws : Draws
        The run's standard-normal draws (disturbance, noise) and the controller's PRNG key.
    """
    seed = scenario.simulation.seed if seed is None else seed
    n_steps = scenario.simulation.n_steps
    keys, (k_build, k_identify, k_run), disturbance, noise = _seed_draws(seed, padded_length(n_steps))
    # the run's rows, cut on the host: a slice in JAX would compile a program per length
    disturbance, noise = (jax.device_put(np.asarray(d)[:n_steps]) for d in (disturbance, noise))
    setup = build(scenario, plant_params=draw_plant(scenario, keys["parameters"]), controller_key=k_build)
    if setup.sensing is not None and (setup.sensing.fix_period or setup.sensing.gyro):
        # the fix's and the gyro's noise: a key of their own off the run's noise stream, so each seed draws its own
        setup = dataclasses.replace(setup, sensing_key=jax.random.fold_in(keys["noise"], 1))
    if identify and needs_identification(scenario):
        setup = with_identification(scenario, setup, k_identify, identification)
    return setup, Draws(disturbance=disturbance, noise=noise, controller_key=k_run)


def with_identification(
    scenario: Scenario, setup: Setup, key: jax.Array, result: Identification | None = None
) -> Setup:
    """Pre-train the NN-adaptive controller's emulator on an identification run of the true plant
    (model.md §3.7), with the scenario's disturbance and noise, and hand it the trained network."""
    outer, inner = setup.controller.outer, getattr(setup.controller, "inner", None)
    if result is None:  # as a batch of one, so that its bits equal its row in any batch's identification
        inputs = (setup.plant_params, inner, outer.emulator, key, setup.disturbance, setup.noise)
        result = row(vmap_runs(_identifier(scenario, setup))(*stack([inputs])), 0)
    controller = dataclasses.replace(setup.controller, outer=dataclasses.replace(outer, emulator=result.emulator))
    return dataclasses.replace(setup, controller=controller, identification=result)


def _identifier(scenario: Scenario, setup: Setup) -> Callable[..., Identification]:
    """identify(plant parameters, inner, emulator, key, disturbance, noise) with the scenario's settings bound, on
    the plant the controller will drive (``setup.plant_for``: the scenario's plant behind its sensing)."""
    config, sim = scenario.controller, scenario.simulation
    assert isinstance(config, NNAdaptiveConfig), "only the NN-adaptive controller identifies its plant"

    def run_identification(
        plant: RobotParams,
        inner: TorqueLaw | None,
        emulator: Emulator,
        key: Array,
        disturbance: WheelDisturbance,
        noise: MeasurementNoise,
    ) -> Identification:
        return identify(
            setup.plant_for(plant, jax.random.fold_in(key, 1)),  # the fix's noise, if any: off the identification key
            inner,
            emulator,
            key,
            duration=config.identification_duration,
            epochs=config.epochs,
            control_period=sim.control_period,
            substeps=sim.substeps,
            dither=config.identification_dither(),
            gains=config.gains,
            limits=(config.max_velocity, config.max_yaw_rate),
            learning_rate=config.learning_rate,
            momentum=config.momentum,
            clip_norm=config.gradient_clip,
            disturbance=disturbance,
            noise=noise,
            reference_scale=config.identification_scale(),
        )

    return run_identification


def prepare_batch(
    scenario: Scenario,
    seeds: Sequence[int],
    *,
    identification: Identification | None = None,
    frame: TrajectoryFrame | None = None,
    identify: bool = True,
) -> tuple[Setup, Draws]:
    """:func:`prepare` for many seeds, stacked along a leading batch axis; NN emulators are identified
    for all the runs at once (``vmap``), or taken from ``identification``: a batch's emulators already identified
    for the same plants and seeds (ablations that only change the gain law). A study's ``frame`` puts the
    trajectory among the study's other kinds (:class:`~ddtrack.trajectories.switched.Switched`); ``identify=False``
    leaves an NN emulator untrained (a batch's structure is the same)."""
    pairs = [prepare(scenario, seed=seed, identify=False) for seed in seeds]
    fields = ("plant_params", "controller", "trajectory", "x0", "disturbance", "noise", "sensing_key")
    setup = dataclasses.replace(pairs[0][0], **{f: stack([getattr(p[0], f) for p in pairs]) for f in fields})
    if frame is not None:
        setup = dataclasses.replace(setup, trajectory=frame.place(setup.trajectory, len(seeds)))
    draws = stack([p[1] for p in pairs])
    if identify and needs_identification(scenario):
        keys = stack([controller_keys(seed)[1] for seed in seeds])
        if identification is None:
            identification = in_shares(
                vmap_runs(_identifier(scenario, setup)),
                setup.plant_params,
                getattr(setup.controller, "inner", None),
                setup.controller.outer.emulator,
                keys,
                setup.disturbance,
                setup.noise,
            )
        setup = with_identification(scenario, setup, keys, identification)
    return setup, draws


def run_batch(scenario: Scenario, seeds: Sequence[int]) -> SimResult:
    """Simulate one run per seed in one vmapped call; row i equals ``run(scenario, seed=seeds[i])``.

    Parameters
    ----------
    scenario : Scenario
        A validated scenario.
    seeds : sequence of int
        One run per seed.

    Returns
    -------
    SimResult
        Every array with a leading batch axis of ``len(seeds)`` (:func:`ddtrack.runner.row` takes one out).
    """
    return run_setup(scenario, *prepare_batch(scenario, seeds), batched=True)


def row(result: Batched, i: int) -> Batched:
    """Run i of a batch result (a :class:`SimResult`, or any pytree with a leading batch axis), as a single one."""
    return jax.tree_util.tree_map(lambda leaf: leaf[i], result)


def run(scenario: Scenario, *, seed: int | None = None) -> SimResult:
    """Simulate a scenario once. Deterministic: the same scenario and seed give the same bits.

    Parameters
    ----------
    scenario : Scenario
        A validated scenario (:func:`ddtrack.load_scenario`).
    seed : int, optional
        Replaces ``simulation.seed``.

    Returns
    -------
    SimResult
        The run's time series and status (:func:`ddtrack.timeseries` turns it into NumPy columns).
    """
    return run_setup(scenario, *prepare(scenario, seed=seed))


def run_setup(scenario: Scenario, setup: Setup, draws: Draws, *, batched: bool = False) -> SimResult:
    """Simulate a prepared run (:func:`prepare`), or a prepared batch (:func:`prepare_batch`, ``batched``), over its
    :func:`run_length` and cut to the scenario's periods (:func:`within_run`)."""
    loop, x0, draws = simulation_args(scenario, setup, draws, run_length(scenario))
    static = {"n_steps": run_length(scenario)}
    if batched:  # setup.plant: the true robot, or the unicycle for a kinematic controller on a torque-driven robot
        result = simulate_batch(loop, x0, draws, **static)
    else:  # as a batch's row, bit for bit
        result = call_exported("simulate_alone", simulate_alone, (loop, x0, draws), {}, static)
    return within_run(result, scenario.simulation.n_steps, batched=batched)


def run_length(scenario: Scenario) -> int:
    """The periods ``scenario``'s runs are simulated for: its own rounded up to a few lengths
    (:func:`~ddtrack.compilations.bucketed_length`), so that runs of different lengths share one compiled program."""
    return bucketed_length(scenario.simulation.n_steps)


def within_run(result: SimResult, n_steps: int, *, batched: bool = False) -> SimResult:
    """``result`` (simulated over :func:`run_length` periods) cut to its first ``n_steps``, on the host, its failure
    :func:`failure_within` them."""
    within = (slice(None),) * (1 if batched else 0) + (slice(None, n_steps),)
    timed = {
        name: jax.tree_util.tree_map(lambda leaf: np.asarray(leaf)[within], getattr(result, name))
        for name in result._fields
        if name not in ("status", "failure_index")
    }
    status, failure_index = failure_within(result.status, result.failure_index, n_steps)
    return SimResult(**timed, status=cast(Array, status), failure_index=cast(Array, failure_index))


def failure_within(
    status: Array | np.ndarray, failure_index: Array | np.ndarray, n_steps: int
) -> tuple[np.ndarray, np.ndarray]:
    """(status, failure index) of runs simulated past their ``n_steps`` periods: a failure in the periods past them
    (which only froze what came after it) is none, ``ok`` at index -1."""
    late = np.asarray(failure_index) >= n_steps
    return np.where(late, 0, status), np.where(late, -1, failure_index)


def loading_warnings(scenario: Scenario) -> list[dict]:
    """What loading the scenario found, run or not (:func:`ddtrack.feasibility.check`, the drive's checks): the same
    for every run of a scenario, so a batch computes it once."""
    return [*feasibility.check(scenario), *check_drive(scenario)]


def run_warnings(
    scenario: Scenario,
    columns: dict,
    metrics: dict,
    nmse: Array | Sequence[float] | None = None,
    loaded: list[dict] | None = None,
) -> list[dict]:
    """Why a finished run's numbers may not mean what they seem, each ``{"code", "message"}``: a reference near the
    clamps (``loaded``: :func:`loading_warnings`, computed if not given), grip no floor could give
    (:func:`traction_warnings`), and the NN-adaptive controller's adaptation that could not work
    (:func:`ddtrack.adaptation.adaptation_warnings`; ``nmse``, the emulator's identification NMSE per output, or
    None)."""
    return [
        *(loading_warnings(scenario) if loaded is None else loaded),
        *lost_path_warnings(metrics),
        *traction_warnings(scenario, metrics),
        *motor_warnings(scenario, metrics),
        *speed_warnings(scenario, columns, metrics),
        *adaptation_warnings(scenario.controller, columns, None if nmse is None else [float(v) for v in nmse]),
    ]


def run_metrics(
    scenario: Scenario,
    columns: dict,
    *,
    status: str,
    failure_time: float | None = None,
    nmse: Array | Sequence[float] | None = None,
    lost_path_error: float | None = None,
    loaded: list[dict] | None = None,
) -> dict:
    """``metrics.json`` of one run: :func:`ddtrack.summarize` over the scenario's window, with its warnings; the
    lost-path bound (:meth:`~ddtrack.scenario.Scenario.lost_path_distance`) and what loading found
    (:func:`loading_warnings`) are the scenario's unless given (a batch computes them once)."""
    sim = scenario.simulation
    metrics = summarize(
        columns,
        status=status,
        window=sim.window,
        control_period=sim.control_period,
        settling_threshold=sim.settling_threshold,
        failure_time=failure_time,
        floor_friction=scenario.plant.floor_friction,
        lost_path_error=scenario.lost_path_distance() if lost_path_error is None else lost_path_error,
    )
    motor = motor_or_none(scenario) if status == "ok" else None  # the preset's datasheet, [plant.motor] over it
    if motor is not None:  # a preset's datasheet motor: what the run asked of it, before the warnings
        metrics = {key: value for key, value in metrics.items() if key != "warnings"}
        metrics |= motor_metrics(motor, columns, sim.control_period)
    # a failed run's series say nothing about grip or adaptation; what loading found (e.g. an unstable sampled
    # inner loop) still holds, and names the cause
    loaded = loading_warnings(scenario) if loaded is None else loaded
    metrics["warnings"] = run_warnings(scenario, columns, metrics, nmse, loaded) if status == "ok" else list(loaded)
    return metrics


def run_record(scenario: Scenario, setup: Setup, result: SimResult) -> tuple[dict, dict]:
    """(columns, metrics) of a finished single run as ``ddtrack run`` writes them: the time series with the grip it
    needed (:func:`traction_columns`), and ``metrics.json`` (:func:`run_metrics`, the identification NMSE included)."""
    columns = timeseries(result)
    columns |= traction_columns(setup.plant_params, columns, scenario)
    nmse = None if setup.identification is None else setup.identification.nmse
    metrics = run_metrics(scenario, columns, status=result.status_name, failure_time=result.failure_time, nmse=nmse)
    return columns, metrics


def closed_loop(scenario: Scenario, setup: Setup) -> ClosedLoop:
    """The loop every simulation of a prepared run (:func:`prepare`) takes: its plant, controller, trajectory,
    disturbance and noise, with ``scenario``'s timing and divergence bound; for a prepared batch
    (:func:`prepare_batch`), the numbers repeated along the run axis (:func:`~ddtrack.sim.repeated`)."""
    sim = scenario.simulation
    loop = ClosedLoop(
        setup.plant,
        setup.controller,
        setup.trajectory,
        setup.disturbance,
        setup.noise,
        control_period=sim.control_period,
        divergence_error=scenario.divergence_distance(),
        solver=RK4(sim.substeps),
    )
    x0 = np.asarray(setup.x0)
    return loop if x0.ndim == 1 else repeated(loop, len(x0))


def simulation_args(
    scenario: Scenario, setup: Setup, draws: Draws, length: int | None = None
) -> tuple[ClosedLoop, Array, Draws]:
    """(loop, x0, draws) of a prepared run's or batch's simulation (:func:`closed_loop`). ``length``: the draws padded
    with zeros to that many periods (:func:`run_length`; the periods past the run's own are cut)."""
    if length is not None:
        draws = draws._replace(disturbance=_padded(draws.disturbance, length), noise=_padded(draws.noise, length))
    return closed_loop(scenario, setup), setup.x0, draws


def _padded(series: Array, length: int) -> Array:
    """``series`` (periods along its second-to-last axis) with zero rows appended up to ``length`` periods, on the
    host (a pad in JAX would compile a program per length; NumPy's array is a JAX argument as it is)."""
    host = np.asarray(series)
    missing = length - host.shape[-2]
    zeros = np.zeros((*host.shape[:-2], missing, host.shape[-1]))
    return cast(Array, np.concatenate([host, zeros], axis=-2) if missing else host)
