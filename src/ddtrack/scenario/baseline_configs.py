"""The ``[controller]`` section of the baseline controllers (registered with the others in ``registry``)."""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import cache
from typing import Annotated, Any, Literal

import jax
from pydantic import Field, model_validator

from ..controllers import (
    Backstepping,
    Cascade,
    HeldLoop,
    VelocityOutput,
)
from ..controllers.baselines import (
    MPPI,
    AdaptiveComputedTorque,
    AdaptiveDynamicCompensator,
    LTVUnicycleLQR,
    MPPICost,
    RegulatedPurePursuit,
    SlidingModeTorque,
)
from ..model import RobotParams
from ..model.lag import PIONEER_3DX_WITH_LASER
from ..trajectories import Trajectory
from ._base import (
    FieldError,
    NonNegative,
    Positive,
    _Section,
)
from .controller_configs import PositiveTriple, _InnerLoopConfig, _KanayamaGains, _VelocityClamps, same_named


@cache  # one program for every LQR's gain (its tolerances and period are traced), kept by the persistent cache
def _lqr_gain() -> Callable[..., Any]:
    return jax.jit(lambda law, speed: law.gain(speed))


class LTVLQRConfig(_VelocityClamps, _InnerLoopConfig):
    """LTV/LQR unicycle tracker (WPILib's LTVUnicycleController) over a computed-torque or PD loop, or as cmd_vel."""

    kind: Literal["ltv_lqr"]
    q_tolerance: PositiveTriple = Field(
        (0.0625, 0.125, 2.0),
        description=(
            "Tolerated (e_x [m], e_y [m], e_theta [rad]); Q = diag(1/q^2) (Bryson's rule, WPILib's defaults)."
        ),
    )
    r_tolerance: tuple[Positive, Positive] = Field(
        (1.0, 2.0), description=("Tolerated velocity correction (v [m/s], omega [rad/s]); R = diag(1/r^2).")
    )
    min_velocity: Positive = Field(
        1e-4, description=("|v_r| below this is linearised at this speed, where e_y stays controllable [m/s].")
    )
    dare_iterations: int = Field(
        32,
        ge=1,
        le=64,
        description=("Doubling steps of the Riccati solver; 20 converge at min_velocity 1e-4 m/s and T_c 10 ms."),
    )

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


class SlidingModeConfig(_VelocityClamps, _KanayamaGains):
    """Kanayama backstepping over a sliding-mode inner loop with a boundary layer (Slotine and Li 7.1-7.2)."""

    kind: Literal["sliding_mode_backstepping"]
    kc: tuple[Positive, Positive] = Field((10.0, 10.0), description="K_c of eq. 11, the linear part [1/s].")
    switching_gain: tuple[NonNegative, NonNegative] = Field(
        (1.0, 2.0),
        description=(
            "K_s (v [m/s^2], omega [rad/s^2]): must exceed the matched disturbance as an acceleration; 0 gives "
            "computed torque."
        ),
    )
    boundary_layer: tuple[Positive, Positive] = Field(
        (0.02, 0.04),
        description=(
            "phi, half-width of the boundary layer (v [m/s], omega [rad/s]): wider chatters less, tracks looser."
        ),
    )

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


class RegulatedPurePursuitConfig(_InnerLoopConfig):
    """Regulated pure pursuit (Macenski et al. 2023, Nav2) keeping pace with the reference, over an inner loop."""

    kind: Literal["regulated_pure_pursuit"]
    lookahead_time: NonNegative = Field(
        1.5, description=("Lookahead L = |v| * lookahead_time, clipped to [min_lookahead, max_lookahead] [s].")
    )
    min_lookahead: Positive = Field(0.3, description="Smallest lookahead distance [m].")
    max_lookahead: Positive = Field(0.9, description="Largest lookahead distance [m]; equal to min_lookahead: fixed.")
    pace_gain: NonNegative = Field(
        1.0, description=("k_s: desired speed v_r + k_s e_x, so the along-track error e_x decays at this rate [1/s].")
    )
    min_radius: NonNegative = Field(
        0.9,
        description=(
            "Arcs tighter than this radius slow the robot by radius / min_radius; 0 turns the regulation off [m]."
        ),
    )
    min_regulated_speed: NonNegative = Field(
        0.25, description=("The curvature regulation never slows below this (nor above the desired speed) [m/s].")
    )
    approach_distance: Positive = Field(
        0.6,
        description=("Slow down in proportion to the distance to where the reference comes to rest, within this [m]."),
    )
    min_approach_speed: NonNegative = Field(0.05, description="Floor of the approach slow-down [m/s].")
    rotate_to_heading: bool = Field(True, description="Rotate in place while the carrot is far off the heading.")
    rotate_min_angle: Annotated[float, Field(gt=0.0, le=math.pi)] = Field(
        0.785, description=("Bearing of the carrot beyond which the robot rotates in place [rad].")
    )
    rotate_yaw_rate: Positive = Field(1.8, description="Yaw rate of the rotation in place [rad/s].")
    search_horizon: Positive = Field(
        5.0,
        description=(
            "The carrot is searched on the reference over [t, t + search_horizon] [s]; must cover the lookahead."
        ),
    )
    search_samples: int = Field(50, ge=2, le=1000, description="Segments of that search (linear between samples).")
    max_velocity: Positive = Field(2.0, description="Clamp on v_c [m/s].")
    max_yaw_rate: Positive = Field(4.0, description="Clamp on |omega_c|, by slowing down on the same arc [rad/s].")

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


class AdaptiveBacksteppingConfig(_VelocityClamps, _KanayamaGains):
    """Kanayama backstepping over computed torque that estimates m, I_C (and b_w) online (Fukao et al. 2000)."""

    kind: Literal["adaptive_backstepping"]
    kc: tuple[Positive, Positive] = Field(
        (10.0, 10.0),
        description=("K_c of eq. 11: the inner loop's bandwidth on the nominal model, K_D = M_bar K_c [1/s]."),
    )
    adaptation_gain: tuple[NonNegative, NonNegative, NonNegative] = Field(
        (500.0, 5.0, 1e-4),
        description=(
            "Gamma of the estimates of (m [kg s^2/m^2], I_C [kg m^2 s^2], viscous friction b_w [kg m^2]); "
            "0 freezes that estimate at the [robot] value."
        ),
    )
    estimate_range: tuple[Positive, Positive] = Field(
        (0.5, 2.0), description=("Projection bounds of the m and I_C estimates, as multiples of the [robot] values.")
    )
    max_friction: NonNegative = Field(
        0.05,
        description=(
            "Upper projection bound of the b_w estimate (the lower is 0), at least the [robot] value [N m s/rad]."
        ),
    )
    strict: bool = Field(False, description="Add the strict-backstepping cross term to the torque law.")

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


class AdaptiveCompensatorConfig(_VelocityClamps, _KanayamaGains):
    """Kanayama's law over Martins et al.'s adaptive inverse of a velocity-commanded base's lag (model.md §2.8)."""

    kind: Literal["adaptive_compensator"]
    compensator_gain: tuple[Positive, Positive] = Field(
        (4.0, 4.0),
        description=(
            "K (k_v, k_omega): the velocity error nu_c - nu decays at this rate on an exactly known base [1/s]."
        ),
    )
    adaptation_rate: tuple[NonNegative, NonNegative, NonNegative, NonNegative, NonNegative, NonNegative] = Field(
        (0.05, 0.05, 0.0, 0.05, 0.0, 0.05),
        description=(
            "Gamma, one rate per theta_1..theta_6 (0 freezes that estimate at theta0); the coupling terms "
            "theta_3, theta_5 are frozen by default."
        ),
    )
    leakage: NonNegative = Field(
        0.01, description="lambda: the estimates leak back toward theta0 at this rate (sigma-modification) [1/s]."
    )
    theta0: tuple[Positive, Positive, float, float, float, float] = Field(
        PIONEER_3DX_WITH_LASER,
        description=(
            "The prior and initial estimate of theta_1..theta_6 [s, s, s m/rad^2, 1, s/m, 1]; the default is the "
            "Pioneer 3-DX's identified set (with laser)."
        ),
    )
    command_rate: Literal["analytic", "difference"] = Field(
        "analytic",
        description=(
            "nu_c_dot from the kinematic law's analytic derivative, or as (nu_c - previous nu_c) / T_c from memory."
        ),
    )

    def build(self, nominal: RobotParams, control_period: float, key: jax.Array) -> AdaptiveDynamicCompensator:
        """The controller; ``nominal`` and ``key`` are unused (the lag model has no mass, nothing is drawn)."""
        kx, ky, ktheta = self.gains
        outer = same_named(self, Backstepping, kx=kx, ky=ky, ktheta=ktheta)
        return same_named(self, AdaptiveDynamicCompensator, outer=outer, control_period=control_period)


class MPPIConfig(_Section):
    """Model predictive path integral control of the wheel torques on the nominal model (Williams et al. 2017)."""

    kind: Literal["mppi"]
    samples: int = Field(64, ge=1, le=10_000, description="K: torque sequences sampled per control period.")
    horizon: int = Field(20, ge=1, le=500, description="H: steps per sequence.")
    model_step: Positive = Field(
        0.05,
        le=10.0,
        description=("dt: how long each step of a sequence holds its torque, and the rollout's Euler step [s]."),
    )
    temperature: Positive = Field(
        1.0,
        description=(
            "lambda of the weights exp(-(S - min S) / lambda), in cost units: lower trusts the best samples more."
        ),
    )
    noise_std: tuple[Positive, Positive] = Field(
        (0.2, 0.2), description=("sigma of the sampled torque perturbations, [right, left] wheel [N m].")
    )
    position_weight: NonNegative = Field(100.0, description="q_p of the squared position error, per step [1/m^2].")
    heading_weight: NonNegative = Field(1.0, description="q_th of the squared heading error, per step [1/rad^2].")
    velocity_weight: NonNegative = Field(1.0, description=("q_nu of |nu - nu_r|^2, per step [s^2/m^2 and s^2/rad^2]."))
    effort_weight: NonNegative = Field(0.01, description="r of the squared wheel torques, per step [1/(N m)^2].")
    terminal_weight: NonNegative = Field(
        10.0, description=("q_T: the last step's position and heading terms count again, times this.")
    )
    limit_weight: NonNegative = Field(
        1000.0,
        description=("q_lim of the squared excess of |v| over max_velocity and |omega| over max_yaw_rate, per step."),
    )
    max_velocity: Positive = Field(2.0, description="Soft limit on |v| of the rollouts [m/s].")
    max_yaw_rate: Positive = Field(4.0, description="Soft limit on |omega| of the rollouts [rad/s].")

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
