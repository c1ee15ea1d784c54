"""Seeds and randomness, and a single run (DESIGN 3).

One seed is split, in a fixed order, into streams for the plant-parameter draw, the disturbance,
the measurement noise and the controller. So swapping the controller leaves the plant and its
disturbances unchanged (common random numbers).
"""
from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from .identification import Identification, identify
from .model import DynamicPlant, RobotParams
from .scenario import NNAdaptiveConfig, ParameterDraw, Scenario, Setup, build
from .sim import Draws, SimResult, simulate

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
    return float(value + draw.absolute * r)


def prepare(scenario: Scenario, *, seed: int | None = None,
            identification: Identification | None = None) -> tuple[Setup, Draws]:
    """Build the run's objects and draw all of its randomness from ``seed`` (default the scenario's).

    ``identification`` reuses an emulator identified for the same plant and seed (ablations that only
    change the gain law), instead of identifying again.
    """
    keys = streams(scenario.simulation.seed if seed is None else seed)
    k_build, k_identify, k_run = jax.random.split(keys["controller"], 3)
    setup = build(scenario, plant_params=draw_plant(scenario, keys["parameters"]), controller_key=k_build)
    config = scenario.controller
    if isinstance(config, NNAdaptiveConfig) and config.identification:
        setup = with_identification(scenario, setup, k_identify, identification)
    n = scenario.simulation.n_steps
    draws = Draws(
        disturbance=jax.random.normal(keys["disturbance"], (n, 2)),
        noise=jax.random.normal(keys["noise"], (n, 5)),
        controller_key=k_run,
    )
    return setup, draws


def with_identification(scenario: Scenario, setup: Setup, key: jax.Array,
                        result: Identification | None = None) -> Setup:
    """Pre-train the NN-adaptive controller's emulator on an identification run of the true plant
    (SPEC 3.7), with the scenario's disturbance and noise, and hand it the trained network."""
    config, sim = scenario.controller, scenario.simulation
    outer = setup.controller.outer
    result = result if result is not None else identify(
        setup.plant_params, setup.controller.inner, outer.emulator, key, duration=config.identification_duration,
        epochs=config.epochs, control_period=sim.control_period, substeps=sim.substeps, dither=config.dither,
        gains=config.gains, limits=(config.max_velocity, config.max_yaw_rate), learning_rate=config.learning_rate,
        momentum=config.momentum, clip_norm=config.gradient_clip, disturbance=setup.disturbance, noise=setup.noise,
    )
    controller = dataclasses.replace(setup.controller, outer=dataclasses.replace(outer, emulator=result.emulator))
    return dataclasses.replace(setup, controller=controller, identification=result)


def run(scenario: Scenario, *, seed: int | None = None) -> SimResult:
    """Simulate a scenario once. Deterministic: the same scenario and seed give the same bits."""
    return run_setup(scenario, *prepare(scenario, seed=seed))


def run_setup(scenario: Scenario, setup: Setup, draws: Draws) -> SimResult:
    """Simulate a prepared run (:func:`prepare`)."""
    sim = scenario.simulation
    return simulate(
        DynamicPlant(setup.plant_params), setup.controller, setup.trajectory, jnp.asarray(setup.x0), draws,
        n_steps=sim.n_steps, control_period=sim.control_period, substeps=sim.substeps,
        disturbance=setup.disturbance, noise=setup.noise, divergence_error=sim.divergence_error,
    )
