"""Could a real robot have done this run? What it asked of the floor and of the motors (model.md §1.5, §1.7).

A no-slip plant never slips and a torque source never runs out of voltage, so a run can ask for things no robot
can give. After the fact, from the recorded motion and torques, this module says what was asked:

* the **grip**: the friction coefficient the contact forces needed (:mod:`ddtrack.model.traction`), against the
  floor's (``plant.floor_friction``) and against any real floor; on a plant that models grip (a slip plant), the
  friction its own contact forces used and the time its wheels slid instead (:func:`grip_used`);
* the **motors**, when the robot is a preset with a datasheet motor: the wheel speed against the motor's no-load
  speed, and the torque against its torque-speed curve at the wheel's speed of the moment.

Each excess becomes a metric in ``metrics.json`` and a warning that names the number and its remedy.
"""

from __future__ import annotations

from typing import Any

import jax.numpy as jnp
import numpy as np

from ._format import significant
from .model import DCMotor, RobotParams, traction
from .model.motors import torque_envelope

#: torque [N m] outside the envelope below this fraction of the stall torque is rounding, not excess
ENVELOPE_SLACK = 1e-6


#: the plant models whose wheels can slip on a floor of finite grip (model.md §1.10): their contact forces are their own
GRIP_MODELS = ("slip", "slip_velocity")


def grip_used(columns: dict, friction: float, slip_speed: float) -> dict[str, np.ndarray]:
    """What a slip plant's contact forces used of the floor, from its logged slips (model.md §1.10): ``mu_used``,
    the larger wheel's |F_i| / N_i = mu |s_i| / sqrt(|s_i|^2 + eps_s^2) each period, s_i = (``slip_i``,
    ``slip_lateral``), never above the floor's mu; and ``sliding`` (1.0 where either wheel's contact slid faster than
    eps_s, the friction fully developed, else 0.0)."""
    lateral = np.asarray(columns["slip_lateral"], dtype=float)
    speeds = np.hypot([columns["slip_r"], columns["slip_l"]], lateral)
    used = friction * speeds / np.sqrt(speeds**2 + slip_speed**2)
    return {"mu_used": np.max(used, axis=0), "sliding": np.any(speeds > slip_speed, axis=0).astype(float)}


def traction_columns(params: RobotParams, columns: dict, scenario: Any = None) -> dict[str, np.ndarray]:
    """The grip a torque-driven run on the true plant ``params`` needed, and its wheel speeds ``wheel_speed_r``,
    ``wheel_speed_l`` [rad/s]; none for a velocity-input plant, whose speeds jump by command and whose contact forces
    mean nothing. On a plant that models grip (``scenario``'s :func:`slip_floor`, and slips in the columns) the grip
    its own contact forces used (:func:`grip_used`); on any other, ``mu_required``, what rolling
    without slip needed (:mod:`ddtrack.model.traction`)."""
    if "tau_r" not in columns or np.all(np.isnan(columns["tau_r"])):
        return {}
    geometry = {
        "mass": float(params.mass),
        "inertia_axle": float(params.inertia_axle),
        "com_offset": float(params.com_offset),
        "half_axle": float(params.half_axle),
    }
    if "phidot_r" in columns:  # a slip plant's wheels spin at their own speed, not at the body's rolling speed
        right, left = np.asarray(columns["phidot_r"]), np.asarray(columns["phidot_l"])
    else:
        right, left = traction.wheel_speeds(
            columns["v"], columns["omega"], wheel_radius=float(params.wheel_radius), half_axle=float(params.half_axle)
        )
    floor = None if scenario is None else slip_floor(scenario)
    if floor is not None and "slip_r" in columns:
        return grip_used(columns, *floor) | {"wheel_speed_r": right, "wheel_speed_l": left}
    return {
        "mu_required": traction.required_friction(columns["t"], columns["v"], columns["omega"], **geometry),
        "wheel_speed_r": right,
        "wheel_speed_l": left,
    }


def slip_floor(scenario: Any) -> tuple[float, float] | None:
    """(mu, eps_s) of the scenario's floor where its plant models grip (:data:`GRIP_MODELS`), else None."""
    plant = scenario.plant
    return (plant.floor_friction, plant.slip_speed) if plant.model in GRIP_MODELS else None


def motor_metrics(motor: DCMotor, columns: dict, control_period: float) -> dict[str, float]:
    """What a run asked of the motor at each wheel, from the columns of :func:`traction_columns` and the torques.

    Returns ``motor_no_load_speed`` [rad/s] (V_s / k_e), ``time_beyond_no_load_speed`` [s] (either wheel faster),
    ``torque_beyond_envelope_max`` [N m] (the most either wheel's torque lay outside the torque-speed curve at
    its speed) and ``time_outside_torque_envelope`` [s]; {} without wheel speeds (a velocity-input plant).
    """
    if "wheel_speed_r" not in columns:
        return {}
    signed = jnp.asarray([columns["wheel_speed_r"], columns["wheel_speed_l"]], dtype=float)
    speeds = np.abs(np.asarray(signed))
    torques = np.asarray([columns["tau_r"], columns["tau_l"]], dtype=float)
    low, high = (np.asarray(end) for end in torque_envelope(motor, signed))
    excess = np.maximum(np.maximum(torques - high, low - torques), 0.0)
    outside = excess > ENVELOPE_SLACK * float(motor.stall_torque)
    no_load = float(motor.no_load_speed)
    return {
        "motor_no_load_speed": no_load,
        "time_beyond_no_load_speed": float(np.count_nonzero(np.any(speeds > no_load, axis=0)) * control_period),
        "torque_beyond_envelope_max": float(np.max(excess, initial=0.0)),
        "time_outside_torque_envelope": float(np.count_nonzero(np.any(outside, axis=0)) * control_period),
    }


def traction_warnings(scenario: Any, metrics: dict) -> list[dict]:
    """Say when no floor, or not the scenario's (``plant.floor_friction``), could give the grip the run needed."""
    needed, floor = metrics.get("mu_required_max"), scenario.plant.floor_friction
    if needed is None or needed <= floor:
        return []
    above = (
        f"above the floor's mu = {floor:g} (plant.floor_friction) for {significant(metrics['time_above_floor_mu'])} s"
    )
    if needed > traction.MAX_FLOOR_FRICTION:
        return [
            {
                "code": "friction_beyond_any_floor",
                "message": (
                    f"the run needed a friction coefficient of {significant(needed)} ({above}); robot wheels get at "
                    "most about "
                    f"{traction.MAX_FLOOR_FRICTION:g} from real floors, so a real robot would slip: this result is not "
                    "physically possible; lower robot.max_torque, the gains, or the initial error"
                ),
            }
        ]
    return [
        {
            "code": "friction_exceeds_floor",
            "message": (
                f"the run needed a friction coefficient of {significant(needed)}, {above}: on that floor the wheels "
                "would slip; lower robot.max_torque or the gains, or set plant.floor_friction to your floor's"
            ),
        }
    ]


def speed_warnings(scenario: Any, columns: dict, metrics: dict) -> list[dict]:
    """Say when the wheels' rims moved faster than the robot's top speed lets them (``Scenario.top_speeds``: a
    preset's, its motors', or ``[robot] top_speed``), max |v +- L omega| over the run on the true robot's axle; not
    where a motor model judged the wheels' speeds (:func:`motor_warnings` does)."""
    top, _, what = scenario.top_speeds()
    if top is None or "motor_no_load_speed" in metrics or not len(columns["v"]):
        return []
    turn = scenario.plant_params().half_axle * np.abs(columns["omega"])
    rim = float(np.max(np.abs(columns["v"]) + turn))
    if rim <= top:
        return []
    return [
        {
            "code": "speed_beyond_robot",
            "message": (
                f"the wheels' rims reached {significant(rim)} m/s (|v| + L |omega|), beyond the top speed of {what}, "
                f"{significant(top)} m/s: the real robot could not move so; slow the reference or lower the gains"
            ),
        }
    ]


def motor_warnings(scenario: Any, metrics: dict) -> list[dict]:
    """Say when the run's wheels turned faster than the preset's motor can, or took torques it cannot give."""
    warnings = []
    motor_name = f"the motor of robot.preset '{scenario.robot.preset}'"
    if metrics.get("time_beyond_no_load_speed"):
        warnings.append(
            {
                "code": "wheel_speed_beyond_motor",
                "message": (
                    f"the wheels reached {significant(metrics['wheel_speed_max'])} rad/s, beyond the no-load speed "
                    f"{significant(metrics['motor_no_load_speed'])} rad/s of {motor_name}, for "
                    f"{significant(metrics['time_beyond_no_load_speed'])} s: no voltage could turn them that fast; "
                    "slow the reference, or simulate the motors with plant.model = 'motor_torque'"
                ),
            }
        )
    if metrics.get("time_outside_torque_envelope"):
        warnings.append(
            {
                "code": "torque_beyond_motor",
                "message": (
                    f"the wheel torques left the torque-speed curve of {motor_name} by up to "
                    f"{significant(metrics['torque_beyond_envelope_max'])} N m, for "
                    f"{significant(metrics['time_outside_torque_envelope'])} s: the motors cannot give them at "
                    "those speeds; lower robot.max_torque or the gains, or simulate the motors with "
                    "plant.model = 'motor_torque'"
                ),
            }
        )
    return warnings
