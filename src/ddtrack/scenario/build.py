"""From a validated scenario to the simulator's objects (:class:`Setup`), and back to TOML."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp

from .._pytree import parts
from ..controllers import Controller
from ..errors import ConfigError
from ..model import DynamicPlant, KinematicPlant, MeasurementNoise, Plant, RobotParams, Sensing, WheelDisturbance
from ..sim import require_matching_input
from ..trajectories import Trajectory
from .document import Scenario
from .registry import controller_kind, controller_output, plant_kind

# --- runtime objects -------------------------------------------------------------------------------


class InputMismatch(ConfigError):
    """The plant does not take what the controller outputs (torques or velocities)."""


@dataclass(frozen=True)
class Setup:
    """Everything :func:`ddtrack.sim.simulate` needs, built from a scenario (randomness not yet drawn)."""

    nominal: RobotParams
    plant_params: RobotParams
    controller: Any
    trajectory: Trajectory
    x0: jax.Array
    disturbance: WheelDisturbance
    noise: MeasurementNoise
    identification: Any = None  #: the emulator's identification, for controllers that have one
    kinematic: bool = False  #: the controller outputs velocity commands (v, omega) to a torque-driven robot
    plant_model: Callable[[RobotParams], Plant] = DynamicPlant  #: the true robot's plant from its parameters
    sensing: Sensing | None = None  #: latency, encoders and odometry between robot and controller (None: none)
    sensing_key: Any = None  #: the PRNG key of the fix's and the gyro's noise (the run's noise stream; None: fixed)

    def __post_init__(self) -> None:
        try:  # a wrong pairing is named here, before anything is simulated
            require_matching_input(self.plant, self.controller)
        except ValueError as exc:
            raise InputMismatch("plant.model", str(exc), "`ddtrack list plants` shows each plant's input") from None

    @property
    def plant(self) -> Plant:
        """What the run simulates: the true robot, ``plant_model(plant_params)``; for a kinematic controller, the
        true robot if it takes velocity commands (e.g. :class:`~ddtrack.model.LagPlant`), else the unicycle that
        applies (v, omega) at once (then [plant], [randomize] and [disturbance] have no effect)."""
        return self.plant_for(self.plant_params, self.sensing_key)

    def plant_for(self, params: RobotParams, sensing_key: Any = None) -> Plant:
        """:attr:`plant` for the true robot's ``params`` and the fix's noise key ``sensing_key`` (e.g. the
        NN-adaptive controller's identification run, on the plant its controller will drive)."""
        robot = self.plant_model(params)
        if self.kinematic and robot.input_kind != "velocity":
            robot = KinematicPlant()
        if self.sensing is None:
            return robot
        return self.sensing.wrap(robot, self.nominal, params, sensing_key)  # type: ignore[return-value]

    def sensed(self, plant: Plant) -> Plant:
        """``plant`` behind the scenario's ``[sensing]`` chain (:class:`~ddtrack.model.SensedPlant`), or as it is
        when the chain is off."""
        if self.sensing is None:
            return plant
        return self.sensing.wrap(plant, self.nominal, self.plant_params, self.sensing_key)  # type: ignore[return-value]


def build(
    scenario: Scenario, plant_params: RobotParams | None = None, controller_key: jax.Array | None = None
) -> Setup:
    """Build the runtime objects; ``plant_params`` replaces the plant (e.g. a random draw) and
    ``controller_key`` seeds the controller's construction (e.g. the emulator's initial weights)."""
    nominal = scenario.robot.params()
    sim = scenario.simulation
    trajectory = scenario.trajectory.build()
    if scenario.initial.pose is None:
        ref0 = trajectory(0.0)
        pose = (float(ref0.x), float(ref0.y), float(ref0.theta))
    else:
        pose = scenario.initial.pose
    x0 = jnp.asarray([*pose, *scenario.initial.velocity], dtype=float)
    config, key = scenario.controller, controller_key if controller_key is not None else jax.random.PRNGKey(0)
    kind = controller_kind(config.kind)
    controller: Controller
    if kind.needs_reference:  # it looks ahead along the reference itself
        controller = config.build(nominal, sim.control_period, key, trajectory=trajectory)
    else:
        controller = config.build(nominal, sim.control_period, key)
    for part in parts(controller):  # each part that samples its own time must sample at the scenario's period
        period = getattr(part, "control_period", None)
        if period is not None and not isinstance(period, jax.core.Tracer) and float(period) != sim.control_period:
            raise TypeError(
                f"controller kind {kind.name!r} builds a {type(part).__name__} with control_period {period!r}, "
                f"but the scenario's is {sim.control_period!r}: pass build's control_period on"
            )
    output = controller_output(config)
    built_output = getattr(controller, "output_kind", output)
    if built_output != output:  # the registration (or the config) and the class must agree on what the plant receives
        raise TypeError(
            f"controller kind {kind.name!r} is declared to output {output!r} (registered output={kind.output!r}), "
            f"but builds a {type(controller).__name__} whose output_kind is {built_output!r}"
        )
    try:
        return Setup(
            nominal=nominal,
            plant_params=plant_params if plant_params is not None else scenario.plant_params(),
            controller=controller,
            trajectory=trajectory,
            x0=x0,
            disturbance=scenario.disturbance.build(),
            noise=scenario.noise.build(),
            # a velocity controller on the default torque plant drives the unicycle with ideal velocity tracking
            kinematic=output == "velocity" and scenario.plant.model == "dynamic",
            plant_model=plant_kind(scenario.plant.model).model(scenario),
            sensing=scenario.sensing.build(sim.control_period, scenario.robot.preset_robot()),
        )
    except InputMismatch as exc:  # a wrong pairing that the shared inner loop's key fixes names that key
        if "inner" not in getattr(type(config), "model_fields", {}):
            raise
        other = "none" if output == "torque" else "computed_torque"
        fix = f'set controller.inner = "{other}"' + (
            " to send (v_c, omega_c) as the velocity command (cmd_vel)" if other == "none" else " (wheel torques)"
        )
        raise ConfigError("controller.inner", exc.message, f"{fix}, or {exc.suggestion}") from None


def to_toml_dict(scenario: Scenario) -> dict[str, Any]:
    """The fully resolved scenario (defaults included, no None values) as a TOML-ready dict."""
    return _drop_none(scenario.model_dump(mode="json"))


def _drop_none(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _drop_none(v) for k, v in value.items() if v is not None}
    if isinstance(value, list):
        return [_drop_none(v) for v in value]
    return value
