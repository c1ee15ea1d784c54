"""The ``[controller]`` section of the baseline controllers (registered with the others in ``registry``)."""

from __future__ import annotations

from collections.abc import Callable
from functools import cache
from typing import Any, Literal

import jax
from pydantic import model_validator

from ..controllers import (
    Backstepping,
    Cascade,
    HeldLoop,
    VelocityOutput,
)
from ..controllers.baselines import (
    MPPI,
    AdaptiveBacksteppingParameters,
    AdaptiveComputedTorque,
    AdaptiveDynamicCompensator,
    CompensatorParameters,
    LTVLQRParameters,
    LTVUnicycleLQR,
    MPPICost,
    MPPIParameters,
    PurePursuitParameters,
    RegulatedPurePursuit,
    SlidingModeParameters,
    SlidingModeTorque,
)
from ..model import RobotParams
from ..trajectories import Trajectory
from ._base import (
    FieldError,
)
from .controller_configs import _ControllerSection, _InnerLoopConfig, _KanayamaGains, _VelocityClamps, same_named


@cache  # one program for every LQR's gain (its tolerances and period are traced), kept by the persistent cache
def _lqr_gain() -> Callable[..., Any]:
    return jax.jit(lambda law, speed: law.gain(speed))


class LTVLQRConfig(LTVLQRParameters, _VelocityClamps, _InnerLoopConfig):
    """LTV/LQR unicycle tracker (WPILib's LTVUnicycleController) over a computed-torque or PD loop, or as cmd_vel."""

    kind: Literal["ltv_lqr"]

    @model_validator(mode="after")
    def _min_velocity_below_clamp(self) -> LTVLQRConfig:
        if self.min_velocity >= self.max_velocity:
            raise FieldError(
                "min_velocity",
                f"{self.min_velocity:g} m/s must be below max_velocity ({self.max_velocity:g} m/s); WPILib uses 1e-4",
            )
        return self

    def command_feedback(self, peak_speed: float, control_period: float) -> tuple[float, float]:
        """-d nu_c_dot / d nu of the law at zero error, at the reference's peak speed: (K[0, 0], K[1, 2]) [1/s] of
        its gain K(v_r), since nu_c_dot = K e_dot and e_dot = (-v, ., -omega) + ... (model.md §2.3; the gain is
        block-diagonal, so nothing crosses channels)."""
        gain = _lqr_gain()(same_named(self, LTVUnicycleLQR, control_period=control_period), peak_speed)
        return (float(gain[0, 0]), float(gain[1, 2]))

    def build(self, nominal: RobotParams, control_period: float, key: jax.Array) -> Cascade | VelocityOutput:
        """The controller; ``key`` is unused (nothing is drawn)."""
        outer = same_named(self, LTVUnicycleLQR, control_period=control_period)
        # the same inner loops as backstepping, so the comparison is fair (docs/architecture.md)
        return self.over_inner(outer, nominal, control_period)


class SlidingModeConfig(SlidingModeParameters, _VelocityClamps, _KanayamaGains):
    """Kanayama backstepping over a sliding-mode inner loop with a boundary layer (Slotine and Li 7.1-7.2)."""

    kind: Literal["sliding_mode_backstepping"]

    def held_loop(self, nominal: RobotParams, peak_speed: float, control_period: float) -> HeldLoop:
        """Computed torque with the switching term, whose K_s / phi adds to K_c inside the boundary layer
        (model.md §2.7)."""
        return HeldLoop(
            "sliding_mode",
            self.kc,
            gain=self.kc,
            derivative=(0.0, 0.0),
            feedforward=(1.0, 1.0),
            feedback=self.command_feedback(peak_speed, control_period),
            layer=(
                self.switching_gain[0] / self.boundary_layer[0],
                self.switching_gain[1] / self.boundary_layer[1],
            ),
        )

    def build(self, nominal: RobotParams, control_period: float, key: jax.Array) -> Cascade:
        """The controller; ``key`` is unused (nothing is drawn)."""
        kx, ky, ktheta = self.gains
        outer = same_named(self, Backstepping, kx=kx, ky=ky, ktheta=ktheta)
        return Cascade(
            outer,
            SlidingModeTorque(
                nominal, kc=self.kc, switching_gain=self.switching_gain, boundary_layer=self.boundary_layer
            ),
        )


class KinematicBacksteppingConfig(_VelocityClamps, _KanayamaGains):
    """Kanayama's law on the unicycle with ideal velocity tracking: a reference point (paper eq. 12, model.md §2.4)."""

    kind: Literal["kinematic_backstepping"]

    def build(self, nominal: RobotParams, control_period: float, key: jax.Array) -> Backstepping:
        """The velocity law alone, which drives the kinematic plant (:attr:`Setup.plant`); ``key`` is unused."""
        kx, ky, ktheta = self.gains
        return same_named(self, Backstepping, kx=kx, ky=ky, ktheta=ktheta)


class RegulatedPurePursuitConfig(PurePursuitParameters, _InnerLoopConfig):
    """Regulated pure pursuit (Macenski et al. 2023, Nav2) keeping pace with the reference, over an inner loop."""

    kind: Literal["regulated_pure_pursuit"]

    @model_validator(mode="after")
    def _consistent(self) -> RegulatedPurePursuitConfig:
        if self.min_lookahead > self.max_lookahead:
            raise FieldError(
                "min_lookahead", f"{self.min_lookahead:g} m exceeds max_lookahead ({self.max_lookahead:g} m)"
            )
        if self.rotate_yaw_rate > self.max_yaw_rate:
            raise FieldError(
                "rotate_yaw_rate", f"{self.rotate_yaw_rate:g} rad/s exceeds max_yaw_rate ({self.max_yaw_rate:g} rad/s)"
            )
        return self

    def build(
        self, nominal: RobotParams, control_period: float, key: jax.Array, *, trajectory: Trajectory
    ) -> Cascade | VelocityOutput:
        """The controller searching ``trajectory`` for its carrot; ``key`` is unused (nothing is drawn)."""
        outer = same_named(self, RegulatedPurePursuit, trajectory=trajectory)
        # the same inner loops as backstepping, so the comparison is fair (docs/architecture.md)
        return self.over_inner(outer, nominal, control_period)


class AdaptiveBacksteppingConfig(AdaptiveBacksteppingParameters, _VelocityClamps, _KanayamaGains):
    """Kanayama backstepping over computed torque that estimates m, I_C (and b_w) online (Fukao et al. 2000)."""

    kind: Literal["adaptive_backstepping"]

    @model_validator(mode="after")
    def _range_holds_the_nominal(self) -> AdaptiveBacksteppingConfig:
        low, high = self.estimate_range
        if not low <= 1.0 <= high or low == high:
            raise FieldError(
                "estimate_range",
                f"{list(self.estimate_range)} must satisfy low <= 1 <= high, "
                "low < high (the estimates start at the [robot] values); e.g. [0.5, 2.0]",
            )
        return self

    def held_loop(self, nominal: RobotParams, peak_speed: float, control_period: float) -> HeldLoop:
        """Computed torque whose damping is K_c on the nominal model, and whose feedforward of nu_c_dot weighs up to
        the top of the estimates' range (they reached it within one period of a 5 Hz Burger; model.md §2.7)."""
        high = self.estimate_range[1]
        return HeldLoop(
            "adaptive_computed_torque",
            self.kc,
            gain=self.kc,
            derivative=(0.0, 0.0),
            feedforward=(high, high),
            feedback=self.command_feedback(peak_speed, control_period),
        )

    def build(self, nominal: RobotParams, control_period: float, key: jax.Array) -> Cascade:
        """The controller; ``key`` is unused (nothing is drawn)."""
        kx, ky, ktheta = self.gains
        outer = same_named(self, Backstepping, kx=kx, ky=ky, ktheta=ktheta)
        low, high = self.estimate_range
        inner = AdaptiveComputedTorque(
            nominal,
            kc=self.kc,
            gamma=self.adaptation_gain,
            control_period=control_period,
            lower=(low * nominal.mass, low * nominal.inertia, 0.0),
            upper=(high * nominal.mass, high * nominal.inertia, max(self.max_friction, nominal.viscous_friction)),
        )
        return Cascade(outer, inner)


class AdaptiveCompensatorConfig(CompensatorParameters, _VelocityClamps, _KanayamaGains):
    """Kanayama's law over Martins et al.'s adaptive inverse of a velocity-commanded base's lag (model.md §2.8)."""

    kind: Literal["adaptive_compensator"]

    def build(self, nominal: RobotParams, control_period: float, key: jax.Array) -> AdaptiveDynamicCompensator:
        """The controller; ``nominal`` and ``key`` are unused (the lag model has no mass, nothing is drawn)."""
        kx, ky, ktheta = self.gains
        outer = same_named(self, Backstepping, kx=kx, ky=ky, ktheta=ktheta)
        return same_named(self, AdaptiveDynamicCompensator, outer=outer, control_period=control_period)


class MPPIConfig(MPPIParameters, _ControllerSection):
    """Model predictive path integral control of the wheel torques on the nominal model (Williams et al. 2017)."""

    kind: Literal["mppi"]

    def build(self, nominal: RobotParams, control_period: float, key: jax.Array, *, trajectory: Trajectory) -> MPPI:
        """The controller previewing ``trajectory``; it samples with the key the simulator hands to ``init``,
        so ``key`` is unused."""
        cost = MPPICost(
            position=self.position_weight,
            heading=self.heading_weight,
            velocity=self.velocity_weight,
            effort=self.effort_weight,
            terminal=self.terminal_weight,
            limit=self.limit_weight,
            max_velocity=self.max_velocity,
            max_yaw_rate=self.max_yaw_rate,
        )
        return same_named(self, MPPI, nominal=nominal, trajectory=trajectory, cost=cost, control_period=control_period)
