"""The ``[controller]`` section of the velocity-level controllers over the shared inner loop: Kanayama backstepping
and the paper's NN-adaptive backstepping.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Literal

import jax
import jax.numpy as jnp
from pydantic import model_validator

from ..controllers import (
    Backstepping,
    Cascade,
    ComputedTorque,
    Emulator,
    HeldLoop,
    InnerLoopParameters,
    KanayamaGains,
    NNAdaptiveBackstepping,
    NNAdaptiveParameters,
    StrictTerm,
    VelocityClamps,
    VelocityOutput,
    WheelPD,
    emulator_scales,
    init_mlp,
    one_step_coefficient,
)
from ..identification import identification_scale
from ..model import DynamicPlant, RobotParams
from ..sim import NominalPeriod
from ._base import (
    FieldError,
    _Section,
)

# --- [controller] -------------------------------------------------------------------------------


class _ControllerSection(_Section):
    """The root of every built-in ``[controller]`` model: its parts below are each declared once, and a kind
    combines the parts it has (listed in the order its keys should appear after ``kind``)."""

    kind: str  # each controller narrows it to its Literal; declared here so that it stays the first key


class _KanayamaGains(KanayamaGains, _ControllerSection):
    """Kanayama's gains (paper eq. 12)."""

    def command_feedback(self, peak_speed: float, control_period: float) -> tuple[float, float]:
        """-d nu_c_dot / d nu of Kanayama's analytic command rate at zero error (model.md §2.5, 2.7): (Kx, v_r
        Ktheta) [1/s], at the reference's peak speed ``peak_speed`` [m/s]; the rate at which nu_c_dot, computed
        from the measured velocity, feeds it back through the inner loop."""
        kx, _, ktheta = self.gains
        return (kx, peak_speed * ktheta)


class _VelocityClamps(VelocityClamps, _ControllerSection):
    """The clamps on the velocity command (v_c, omega_c)."""


def same_named(config: _Section, cls: Any, **derived: Any) -> Any:
    """``cls`` (a controller dataclass) built from ``config``'s keys of the same names, and ``derived`` for the rest:
    each parameter is declared once, in the config, and cannot drift on its way to the controller (a renamed key
    is a missing argument, not a silent default)."""
    names = {field.name for field in dataclasses.fields(cls)} & set(type(config).model_fields)
    return cls(**{name: getattr(config, name) for name in names - set(derived)}, **derived)


class _InnerLoopConfig(InnerLoopParameters, _ControllerSection):
    """The keys of a controller that outputs (v_c, omega_c) over the shared inner loop (docs/architecture.md).

    The inner loop is computed torque (eq. 11) or wheel-space PD (model.md §2.6), so every velocity-level
    controller meets the same dynamics layer; or none, the outer law's command going to a velocity-commanded
    base as its cmd_vel (model.md §2.7).
    """

    def build_inner(self, nominal: RobotParams, control_period: float) -> ComputedTorque | WheelPD:
        """The inner loop on the ``nominal`` model, sampled every ``control_period`` [s] (not for inner = "none")."""
        if self.inner == "computed_torque":
            return ComputedTorque(nominal, kc=self.kc)
        return WheelPD(nominal, kp=self.kp, kd=self.kd, control_period=control_period)

    def controller_output(self) -> Literal["torque", "velocity"]:
        """What the built controller hands the plant: wheel torques, or (v, omega) without an inner loop."""
        return "velocity" if self.inner == "none" else "torque"

    def over_inner(self, outer: Any, nominal: RobotParams, control_period: float) -> Cascade | VelocityOutput:
        """``outer`` over the inner loop, or alone as a velocity command (inner = "none", model.md §2.7)."""
        if self.inner == "none":
            return VelocityOutput(outer)
        return Cascade(outer, self.build_inner(nominal, control_period))

    def command_feedback(self, peak_speed: float, control_period: float) -> tuple[float, float]:
        """-d nu_c_dot / d nu of the outer law at zero error [1/s]: none for a law whose nu_c_dot does not read the
        measured velocity (a law that does overrides this; model.md §2.7)."""
        return (0.0, 0.0)

    def held_loop(self, nominal: RobotParams, peak_speed: float, control_period: float) -> HeldLoop | None:
        """The inner loop as its sampling check sees it (model.md §2.7); None without one (inner = "none")."""
        if self.inner == "none":
            return None
        design = self.inner_bandwidth(nominal)
        # the PD's derivative acts on the backward difference and on W nu_c_dot alike, with K_D / K_P of its rate
        ratio = self.kd / self.kp if self.inner == "pd" else 0.0
        weight = (design[0] * ratio, design[1] * ratio)
        return HeldLoop(
            self.inner,
            design,
            gain=self.kc if self.inner == "computed_torque" else (self.kp, self.kp),
            derivative=weight,
            feedforward=weight if self.inner == "pd" else (1.0, 1.0),
            feedback=self.command_feedback(peak_speed, control_period),
        )

    def inner_bandwidth(self, nominal: RobotParams) -> tuple[float, float]:
        """(k_v, k_omega) [1/s] of the inner loop on the nominal model (model.md §2.5, 2.6); inner = "none"
        has no loop and so no bandwidth (a ValueError)."""
        if self.inner == "none":
            raise ValueError('inner = "none" has no inner loop and so no bandwidth')
        if self.inner == "computed_torque":
            return self.kc
        r2 = nominal.wheel_radius**2
        return (
            2 * self.kp / (nominal.effective_mass * r2),
            2 * self.kp * nominal.half_axle**2 / (nominal.effective_inertia_axle * r2),
        )


class _KanayamaConfig(StrictTerm, _VelocityClamps, _KanayamaGains, _InnerLoopConfig):
    """The keys of Kanayama's law (paper eq. 12) over the inner loop, shared by backstepping and its NN-adaptive
    form."""

    @model_validator(mode="after")
    def _strict_needs_computed_torque(self) -> _KanayamaConfig:
        if self.strict and self.inner != "computed_torque":
            raise FieldError(
                "strict",
                f'strict = true needs inner = "computed_torque" (the cross term enters eq. 11), not "{self.inner}"',
                'set strict = false, or inner = "computed_torque"',
            )
        return self


class BacksteppingConfig(_KanayamaConfig):
    """Kanayama backstepping over a computed-torque or PD inner loop (paper eqs. 7, 11, 12, 21), or as cmd_vel."""

    kind: Literal["backstepping"]

    def build(self, nominal: RobotParams, control_period: float, key: jax.Array) -> Cascade | VelocityOutput:
        """The controller; ``key`` seeds whatever it draws at construction (nothing, for backstepping)."""
        kx, ky, ktheta = self.gains
        outer = same_named(self, Backstepping, kx=kx, ky=ky, ktheta=ktheta)
        return self.over_inner(outer, nominal, control_period)


InnerLoopConfig = _InnerLoopConfig  #: public name, for a plugin's config over the shared inner loop (docs/plugins.md)


class NNAdaptiveConfig(NNAdaptiveParameters, _KanayamaConfig):
    """The paper's NN-adaptive backstepping: gains tuned online through an emulator network (model.md §3)."""

    kind: Literal["nn_adaptive_backstepping"] = "nn_adaptive_backstepping"

    @model_validator(mode="after")
    def _gains_inside_bounds(self) -> NNAdaptiveConfig:
        if self.inner == "none" and self.jacobian != "network":  # they are the inner loop's, through its bandwidth
            raise FieldError(
                "jacobian",
                f'jacobian = "{self.jacobian}" needs an inner loop (its bandwidth or its model of the robot), but '
                'inner = "none"',
                'use jacobian = "network" (the emulator\'s, eq. 34), or an inner loop',
            )
        for name, low, gain, high in zip(("Kx", "Ky", "Ktheta"), self.gain_min, self.gains, self.gain_max, strict=True):
            if not low <= gain <= high:
                raise FieldError("gains", f"{name} = {gain:g} lies outside [gain_min, gain_max] = [{low:g}, {high:g}]")
        if self.identification_speed is not None:  # identification data taken against a clamp teaches nothing
            (v, w), (v_max, w_max) = self.identification_speed, (self.max_velocity, self.max_yaw_rate)
            if v > v_max or w > w_max:
                raise FieldError(
                    "identification_speed",
                    f"[{v:g}, {w:g}] exceeds the clamps max_velocity = "
                    f"{v_max:g} m/s, max_yaw_rate = {w_max:g} rad/s; keep each below about 80 % "
                    "of its clamp",
                )
        return self

    def identification_scale(self) -> tuple[float, float]:
        """(k_v, k_omega) of the identification reference, dither and emulator scales; (1, 1) for the paper's robot."""
        return identification_scale(self.max_velocity, self.max_yaw_rate, self.identification_speed)

    def identification_dither(self) -> tuple[float, float]:
        """The dither's (sigma_v, sigma_omega): given, or the paper's (0.05, 0.1) scaled like the reference."""
        k_v, k_w = self.identification_scale()
        return self.dither if self.dither is not None else (0.05 * k_v, 0.1 * k_w)

    def _nominal_period(self, nominal: RobotParams, control_period: float) -> NominalPeriod | None:
        """One period of the nominal model under the inner loop, RK4 steps of at most 1 ms (the "model" Jacobians)."""
        if not self.jacobian.startswith("model"):
            return None
        return NominalPeriod(
            DynamicPlant(nominal),
            self.build_inner(nominal, control_period),
            control_period,
            substeps=max(1, math.ceil(control_period / 1e-3 - 1e-9)),
        )

    def build(self, nominal: RobotParams, control_period: float, key: jax.Array) -> Cascade | VelocityOutput:
        """The controller with a freshly initialised emulator (its identification is done by the runner)."""
        uses_velocity = self.emulator == "E1"
        k_v, k_w = self.identification_scale()  # the emulator's range is the identification's
        emulator = Emulator(
            init_mlp(key, 4 if uses_velocity else 2, self.hidden_units, 3),
            emulator_scales(
                control_period, uses_velocity=uses_velocity, max_velocity=k_v * 1.0, max_yaw_rate=k_w * 2.0
            ),
            uses_velocity,
        )
        # without an inner loop only the network's Jacobian is defined (the validator refuses the others); the
        # analytic coefficients are then unused, kept at a finite placeholder so the outer law's fields stay alike
        bandwidth = jnp.asarray(self.inner_bandwidth(nominal) if self.inner != "none" else (1.0, 1.0), float)
        freeze = self.freeze_time if self.freeze_time is not None else (0.0 if self.identification else 2.0)
        outer = same_named(
            self,
            NNAdaptiveBackstepping,
            emulator=emulator,
            control_period=control_period,
            analytic_coefficients=one_step_coefficient(bandwidth, control_period),
            freeze_time=freeze,
            nominal_period=self._nominal_period(nominal, control_period),
        )
        return self.over_inner(outer, nominal, control_period)
