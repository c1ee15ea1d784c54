"""The body model of a robot driven by wheel torques (model.md §1.3, §1.6), as ``ddtrack identify --model body``
fits it (docs/identification.md). With the wheel radius R and half axle L known, it is linear in
p = (M_v, m d, M_w, b_w, tau_c)::

    (tau_R + tau_L) / R   = M_v v_dot - m d omega^2   + (f_R + f_L) / R
    L (tau_R - tau_L) / R = M_w omega_dot + m d v omega + L (f_R - f_L) / R

with f_i = b_w phi_dot_i + tau_c tanh(phi_dot_i / eps_f) each wheel's friction, M_v = m + 2 J_w / R^2 the mass the
wheels drive and M_w = I_A + 2 J_w L^2 / R^2 the yaw inertia about the axle. A log of a robot that does not slip
fixes only these sums: the wheels' spin inertia J_w is folded into the mass and the yaw inertia.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import jax.numpy as jnp
import numpy as np
from jax import Array

from ..model.dynamics import body_acceleration
from ..model.params import RobotParams
from ..model.traction import wheel_speeds
from .fit import SpeedFit, SpeedLog, SpeedModel, identify, propagated
from .output_error import WINDOW

NAMES = ("M_v", "md", "M_w", "viscous_friction", "coulomb_friction")


@dataclass(frozen=True)
class BodyRate:
    """(v_dot, omega_dot) of the no-slip robot with p = (M_v, m d, M_w, b_w, tau_c), geometry fixed (hashable, so
    one compiled simulation serves a robot)."""

    wheel_radius: float
    half_axle: float
    smoothing: float  #: eps_f of the tanh Coulomb friction [rad/s]

    def params(self, p: Any) -> RobotParams:  # p is traced: RobotParams' floats hold arrays here, as under vmap
        """The equivalent robot: J_w = 0, mass M_v, centre of mass m d / M_v, I_C = M_w - (m d)^2 / M_v."""
        return RobotParams(
            mass=p[0],
            inertia=p[2] - p[1] ** 2 / p[0],
            com_offset=p[1] / p[0],
            wheel_radius=self.wheel_radius,
            half_axle=self.half_axle,
            viscous_friction=p[3],
            coulomb_friction=p[4],
            friction_smoothing=self.smoothing,
        )

    def __call__(self, p: Array, speed: Array, torque: Array) -> Array:
        return body_acceleration(self.params(p), speed, torque, jnp.zeros(2))


def body_model(*, wheel_radius: float, half_axle: float, friction_smoothing: float = 0.01) -> SpeedModel:
    """The body model of a robot of wheel radius R [m] and half axle L [m]."""
    radius, half = wheel_radius, half_axle

    def regressors(speed: np.ndarray, rate: np.ndarray, torque: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        v, w = speed[:, 0], speed[:, 1]
        right, left = wheel_speeds(v, w, wheel_radius=radius, half_axle=half)
        tanh_r, tanh_l = np.tanh(right / friction_smoothing), np.tanh(left / friction_smoothing)
        zero = np.zeros_like(v)
        rows_v = np.column_stack([rate[:, 0], -(w**2), zero, (right + left) / radius, (tanh_r + tanh_l) / radius])
        rows_w = np.column_stack(
            [zero, v * w, rate[:, 1], half * (right - left) / radius, half * (tanh_r - tanh_l) / radius]
        )
        target_v = (torque[:, 0] + torque[:, 1]) / radius
        target_w = half * (torque[:, 0] - torque[:, 1]) / radius
        scale_v, scale_w = max(np.std(target_v), 1e-300), max(np.std(target_w), 1e-300)  # N against N m
        rows = np.concatenate([rows_v / scale_v, rows_w / scale_w])
        return rows, np.concatenate([target_v / scale_v, target_w / scale_w])

    return SpeedModel(
        name="body",
        names=NAMES,
        units=("kg", "kg m", "kg m^2", "N m s/rad", "N m"),
        meanings=(
            "mass the wheels drive, m + 2 J_w / R^2",
            "mass times the centre of mass's offset ahead of the axle",
            "yaw inertia about the axle, I_A + 2 J_w L^2 / R^2",
            "viscous friction of each wheel",
            "Coulomb friction of each wheel",
        ),
        rate=BodyRate(wheel_radius, half_axle, friction_smoothing),
        regressors=regressors,
        positive=(0, 2),
        couplings=(1,),
        input_names=("tau_r", "tau_l"),
    )


def identify_body(
    log: SpeedLog,
    *,
    wheel_radius: float,
    half_axle: float,
    friction_smoothing: float = 0.01,
    max_delay: float = 0.3,
    window: float = WINDOW,
) -> SpeedFit:
    """The body model and torque delay of the robot that recorded ``log`` (its wheel torques as ``log.command``),
    the output error over windows of ``window`` [s]."""
    model = body_model(wheel_radius=wheel_radius, half_axle=half_axle, friction_smoothing=friction_smoothing)
    return identify(model, log, max_delay=max_delay, window=window)


def equivalent_robot(params: np.ndarray) -> dict[str, float]:
    """The ``[plant]`` keys of the equivalent robot of body parameters (M_v, m d, M_w, b_w, tau_c): J_w folded into
    mass and inertia."""
    mass, md, inertia_axle, viscous, coulomb = (float(value) for value in params)
    return {
        "mass": mass,
        "inertia": inertia_axle - md**2 / mass,
        "com_offset": md / mass,
        "viscous_friction": viscous,
        "coulomb_friction": coulomb,
        "wheel_inertia": 0.0,
    }


def plant_keys(fit: SpeedFit) -> dict[str, float]:
    """The ``[plant]`` keys of the equivalent robot (J_w folded into mass and inertia)."""
    return equivalent_robot(fit.params)


def plant_std(fit: SpeedFit) -> dict[str, float]:
    """The standard error of each of :func:`plant_keys`, from the fit's covariance (the delta method)."""
    return propagated(equivalent_robot, fit.params, fit.covariance)
