"""``[plant] model = "slip"`` and ``"slip_velocity"``: the scenario's true robot on a floor of finite grip (model.md
§1.10).

The floor's friction coefficient is ``plant.floor_friction``, its slip speed ``plant.slip_speed``; the caster is
``plant.caster_position`` or the ``[robot] preset``'s, the centre of mass's height ``plant.com_height`` or the
preset's (0 without either: no load transfer). A preset with a motor drives the wheels through its
current-controlled driver (back-EMF bounds their spin); otherwise the torques apply as commanded, within
max_torque. ``slip_velocity`` drives the preset's motors with the ``plant.velocity_pi`` wheel-speed loop instead, so
it takes (v, omega) commands and needs a preset with a motor. The integration scheme and sub-steps are chosen once
from the nominal true robot.
"""

from __future__ import annotations

from typing import Any

from ..errors import ConfigError
from ..model import RobotParams, VelocityDriver
from ..model.slip import SlipPlant, slip_plant_model
from ..model.slip_velocity import SlipVelocityPlant, slip_velocity_model
from .motor_configs import motor_or_none, pwm_model, scenario_motor


def _preset(scenario: Any) -> Any:
    from ..robots import PRESETS  # robots sits above the scenario layer

    name = scenario.robot.preset
    return PRESETS.get(name) if name is not None else None


def slip_options(scenario: Any) -> dict[str, Any]:
    """The slip plant's floor, caster and motor from the scenario, checked; a ConfigError naming the field."""
    robot = _preset(scenario)
    nominal = scenario.plant_params()
    if nominal.wheel_inertia <= 0.0:
        raise ConfigError(
            "plant.wheel_inertia",
            f"model '{scenario.plant.model}' needs wheels with spin inertia J_w > 0: a massless wheel beyond grip "
            "spins up without bound",
            "set plant.wheel_inertia (or robot.wheel_inertia) > 0 [kg m^2], e.g. the wheel plus N^2 J_rotor",
        )
    caster = scenario.plant.caster_position
    if caster is None and robot is not None:
        caster = robot.caster_position
    if caster is not None and not 0.0 <= nominal.com_offset / caster < 1.0:
        raise ConfigError(
            "plant.caster_position",
            f"the caster at {caster} m must lie beyond the centre of mass (d = {nominal.com_offset} m), on its side",
            "give a caster position with 0 <= d / caster_position < 1, or leave it out (no caster load)",
        )
    height = scenario.plant.com_height
    if height is None:
        height = 0.0 if robot is None or robot.com_height is None else robot.com_height
    motor = motor_or_none(scenario)
    sim = scenario.simulation
    return {
        "friction": scenario.plant.floor_friction,
        "slip_speed": scenario.plant.slip_speed,
        "caster": caster,
        "com_height": height,
        "motor": motor,
        "pwm_model": None if motor is None else pwm_model(scenario),
        "period": sim.control_period,
        "substeps": sim.substeps,
    }


def slip_plant_config(params: RobotParams, scenario: Any) -> SlipPlant:
    """The drawn robot ``params`` (alone or a batch) on the scenario's floor (model.md §1.10)."""
    model = slip_plant_model(scenario.plant_params(), **slip_options(scenario))
    try:
        return model(params)
    except ValueError as exc:  # the nominal robot passed: a random draw crossed the line
        raise ConfigError("randomize", f"a drawn robot: {exc}", "narrow the [randomize] draws") from None


def slip_velocity_plant_config(params: RobotParams, scenario: Any) -> SlipVelocityPlant:
    """The drawn robot ``params`` on the scenario's floor, its preset's motors under the ``plant.velocity_pi`` loop
    (model.md §1.10); a ConfigError naming ``plant.model`` if the preset has no motor."""
    driver = VelocityDriver(scenario_motor(scenario), *scenario.plant.velocity_pi)
    options = slip_options(scenario)
    del options["motor"], options["pwm_model"]  # the loop drives the preset's motor
    model = slip_velocity_model(scenario.plant_params(), driver, **options)
    try:
        return model(params)
    except ValueError as exc:  # the nominal robot passed: a random draw crossed the line
        raise ConfigError("randomize", f"a drawn robot: {exc}", "narrow the [randomize] draws") from None
