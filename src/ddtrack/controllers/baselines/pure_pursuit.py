"""Regulated pure pursuit, adapted to time-parameterised references.

Sources: S. Macenski, S. Singh, F. Martín, J. Ginés, "Regulated Pure Pursuit for Robot Path Tracking",
Autonomous Robots 47 (2023), arXiv:2305.20026, and its reference implementation, the ROS 2 Nav2
``nav2_regulated_pure_pursuit_controller`` (parameter names in brackets below). Pure pursuit itself:
R. C. Coulter, "Implementation of the Pure Pursuit Path Tracking Algorithm", CMU-RI-TR-92-01 (1992).

One control period, robot at p = (x, y) with heading theta and measured speed v, reference time t::

    1. L = clip(|v| lookahead_time, min_lookahead, max_lookahead)           adaptive lookahead, L_t = v_t l_t
                                                                            [use_velocity_scaled_lookahead_dist]
    2. carrot: sample the reference at t + i H / M (i = 0..M, H = search_horizon, M = search_samples); take
       the first sample at distance >= L from p and move it back along its segment onto the circle of
       radius L about p [use_interpolation], so |carrot - p| = L. If the reference point itself is farther
       than L (the robot lags or is off the path) it is the carrot; if no sample is that far (the path
       ends within reach) the last sample is [Nav2 takes the path's last pose].
    3. kappa = 2 y_c / (x_c^2 + y_c^2)  (= 2 y_c / L^2)                      the arc through p tangent to the
       heading, (x_c, y_c) the carrot in the robot frame                     heading and through the carrot
    4. v_d = clip(v_r + k_s e_x, 0, max_velocity)                            pace keeping (ours, see below)
    5. v_k = v_d min(1, r / r_min), r = 1 / |kappa|, floored at min(min_regulated_speed, v_d)
                                                                            curvature heuristic
                                                                            [regulated_linear_scaling_min_radius,
                                                                             regulated_linear_scaling_min_speed]
    6. if the reference comes to rest within the horizon with less than approach_distance of path left:
       v_a = min(v_k, max(v_k d_goal / approach_distance, min_approach_speed)), d_goal = |rest point - p|
                                                                            approach heuristic
                                                                            [approach_velocity_scaling_dist,
                                                                             min_approach_linear_velocity]
    7. v = min(v_a, max_yaw_rate / |kappa|);  omega = v kappa               yaw-rate limit along the same arc
    8. if |atan2(y_c, x_c)| > rotate_min_angle: v = 0, omega = sign(atan2(y_c, x_c)) rotate_yaw_rate
                                                                            [use_rotate_to_heading,
                                                                             rotate_to_heading_min_angle,
                                                                             rotate_to_heading_angular_vel]

What differs from Nav2, and why:

* Nav2 follows a *path* at a set speed; here the reference is a time law, so the carrot search starts at
  the reference point of time t (not at the path point nearest the robot) and the desired speed keeps
  pace with it: v_d = v_r + k_s e_x, e_x the along-track error of model.md §2.2 (positive: reference ahead),
  so the along-track error decays at rate k_s (``pace_gain``) instead of growing without bound.
* The floor of step 5 is capped at v_d, so a robot ahead of its reference (v_d = 0) can wait for it;
  Nav2 always floors at ``regulated_linear_scaling_min_speed``.
* The paper's proximity (obstacle cost) heuristic and its collision checking do not apply: ddtrack has
  no obstacles. Nav2's angular-acceleration ramp of the rotation in place is left to the inner loop.
* The yaw-rate limit of step 7 is ddtrack's shared ``max_yaw_rate`` clamp, applied by slowing down on
  the arc rather than by clipping omega, so the commanded curvature stays the pure-pursuit one.

The command's derivative nu_c_dot handed to the inner loop is 0: pure pursuit is a kinematic law with no
analytic derivative, and a backward difference over one period spikes whenever the carrot jumps (a
square corner, entering or leaving the rotation in place), the reason model.md §2.5 prefers analytic rates.
On a line or a circle at constant speed the true derivative is 0 anyway.
"""

from __future__ import annotations

import math
from typing import Annotated, Any

import jax
import jax.numpy as jnp
from jax import Array
from pydantic import Field

from ..._pytree import pytree_dataclass
from ...geometry import posture_error
from ...layout import pose, pose_vector, position, velocity
from ...parameters import NonNegative, Parameters, Positive, Structure, declared
from ...trajectories import Reference
from ..base import Logs, VelocityCommand


def lookahead_distance(
    speed: Array, lookahead_time: Array | float, min_lookahead: Array | float, max_lookahead: Array | float
) -> Array:
    """Adaptive lookahead L = clip(|v| l_t, L_min, L_max) [m].

    As in Macenski et al. 2023 (Nav2's velocity-scaled lookahead).
    """
    return jnp.clip(jnp.abs(speed) * lookahead_time, min_lookahead, max_lookahead)


def circle_exit(inside: Array, outside: Array, center: Array, radius: Array) -> Array:
    """The point where the segment from ``inside`` (closer than ``radius`` to ``center``) to ``outside``
    (at least ``radius`` away) crosses the circle: the larger root s of |inside + s d - center| = radius."""
    d, f = outside - inside, inside - center
    a = jnp.maximum(d @ d, 1e-300)  # > 0 whenever the two points straddle the circle; keeps the other case finite
    b, c = f @ d, f @ f - radius**2
    s = (-b + jnp.sqrt(jnp.maximum(b * b - a * c, 0.0))) / a
    return inside + jnp.clip(s, 0.0, 1.0) * d


def find_carrot(points: Array, position: Array, lookahead: Array) -> Array:
    """The carrot on the sampled reference ``points`` (M+1, 2), searched from the first one: the first
    crossing of the circle of radius ``lookahead`` about ``position``, interpolated on its segment; the
    first point when it is already outside; the last point when none is outside (the path ends within reach)."""
    outside = jnp.hypot(points[:, 0] - position[0], points[:, 1] - position[1]) >= lookahead
    i = jnp.argmax(outside)  # first point outside; 0 when there is none
    crossing = circle_exit(points[jnp.maximum(i - 1, 0)], points[i], position, lookahead)
    return jnp.where(~outside[i], points[-1], jnp.where(i == 0, points[0], crossing))


def pursuit_curvature(carrot: Array, pose: Array) -> tuple[Array, Array]:
    """kappa = 2 y_c / (x_c^2 + y_c^2) [1/m] of the arc from ``pose`` = (x, y, theta), tangent to its heading,
    through ``carrot`` (Coulter 1992), and the carrot's bearing atan2(y_c, x_c) [rad] in the robot frame."""
    c, s = jnp.cos(pose[2]), jnp.sin(pose[2])
    dx, dy = carrot[0] - pose[0], carrot[1] - pose[1]
    x_c, y_c = c * dx + s * dy, -s * dx + c * dy
    distance2 = x_c**2 + y_c**2
    kappa = jnp.where(
        distance2 > 1e-18, 2.0 * y_c / jnp.maximum(distance2, 1e-18), 0.0
    )  # robot on the carrot: go straight
    return kappa, jnp.arctan2(y_c, x_c)


def curvature_regulation(speed: Array, kappa: Array, min_radius: Array | float) -> Array:
    """The paper's curvature heuristic: speed * r / r_min on arcs tighter than r_min (r = 1/|kappa|), else speed."""
    return speed * jnp.minimum(1.0, 1.0 / jnp.maximum(jnp.abs(kappa) * min_radius, 1e-300))


class PurePursuitParameters(Parameters):
    """Regulated pure pursuit's parameters (Macenski et al. 2023, Nav2's defaults where it has them)."""

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
    search_samples: Structure[int] = Field(
        50, ge=2, le=1000, description="Segments of that search (linear between samples)."
    )
    max_velocity: Positive = Field(2.0, description="Clamp on v_c [m/s].")
    max_yaw_rate: Positive = Field(4.0, description="Clamp on |omega_c|, by slowing down on the same arc [rad/s].")


@pytree_dataclass
class RegulatedPurePursuit:
    """Regulated pure pursuit over a time-parameterised reference (module docstring; Macenski et al. 2023).

    In: measured state y = [x, y, theta, v, omega], the reference at t, and ``trajectory`` itself (the
    carrot is searched along it). Out: nu_c = (v_c [m/s], omega_c [rad/s]) with nu_c_dot = 0, for an
    inner loop in a :class:`~ddtrack.controllers.Cascade`. Stateless. Lengths [m], times [s], speeds
    [m/s], yaw rates [rad/s], ``pace_gain`` k_s [1/s]. Logs ``lookahead`` L [m], ``curvature`` kappa
    [1/m] and ``rotating`` (1.0 while it rotates in place toward the carrot).
    """

    trajectory: Any
    lookahead_time: float = declared(PurePursuitParameters)
    min_lookahead: float = declared(PurePursuitParameters)
    max_lookahead: float = declared(PurePursuitParameters)
    pace_gain: float = declared(PurePursuitParameters)
    min_radius: float = declared(PurePursuitParameters)
    min_regulated_speed: float = declared(PurePursuitParameters)
    approach_distance: float = declared(PurePursuitParameters)
    min_approach_speed: float = declared(PurePursuitParameters)
    rotate_min_angle: float = declared(PurePursuitParameters)
    rotate_yaw_rate: float = declared(PurePursuitParameters)
    max_velocity: float = declared(PurePursuitParameters)
    max_yaw_rate: float = declared(PurePursuitParameters)
    search_horizon: float = declared(PurePursuitParameters)
    search_samples: int = declared(PurePursuitParameters)
    rotate_to_heading: Array | bool = declared(PurePursuitParameters)

    def init(self, x0: Array, ref0: Reference, key: Array) -> tuple[()]:
        return ()

    def carrot(self, t: Array, y: Array) -> tuple[Array, Array, Reference]:
        """The carrot [m], the lookahead L [m] and the sampled reference (fields of shape (M+1,))."""
        times = t + jnp.linspace(0.0, self.search_horizon, self.search_samples + 1)
        samples = jax.vmap(self.trajectory)(times)
        lookahead = lookahead_distance(velocity(y)[0], self.lookahead_time, self.min_lookahead, self.max_lookahead)
        return find_carrot(jnp.stack([samples.x, samples.y], axis=1), position(y), lookahead), lookahead, samples

    def command(self, t: Array, y: Array, ref: Reference, memory: tuple[()]) -> tuple[VelocityCommand, tuple[()], Logs]:
        carrot, lookahead, samples = self.carrot(t, y)
        kappa, bearing = pursuit_curvature(carrot, pose_vector(y))
        e_x = posture_error(*pose(y), ref.x, ref.y, ref.theta)[0]
        paced = ref.v + self.pace_gain * e_x
        v_d = jnp.clip(paced, 0.0, self.max_velocity)
        v = jnp.maximum(curvature_regulation(v_d, kappa, self.min_radius), jnp.minimum(self.min_regulated_speed, v_d))
        # the goal is where the reference comes to rest, when that is near (Nav2: the path's end)
        steps = jnp.hypot(jnp.diff(samples.x), jnp.diff(samples.y))
        approaching = (samples.v[-1] <= 0.0) & (jnp.sum(steps) < self.approach_distance)
        here = position(y)
        to_goal = jnp.hypot(samples.x[-1] - here[0], samples.y[-1] - here[1])
        v = jnp.where(
            approaching, jnp.minimum(v, jnp.maximum(v * to_goal / self.approach_distance, self.min_approach_speed)), v
        )
        yaw_limited = v * jnp.abs(kappa) > self.max_yaw_rate
        v = jnp.where(yaw_limited, self.max_yaw_rate / jnp.maximum(jnp.abs(kappa), 1e-300), v)
        omega = v * kappa
        rotating = jnp.logical_and(self.rotate_to_heading, jnp.abs(bearing) > self.rotate_min_angle)
        v = jnp.where(rotating, 0.0, v)
        omega = jnp.where(rotating, jnp.sign(bearing) * self.rotate_yaw_rate, omega)
        saturated = ((paced > self.max_velocity) | yaw_limited) & ~rotating
        nu_c = jnp.stack([v, omega])
        command = VelocityCommand(nu_c, jnp.zeros(2), jnp.zeros(2), saturated.astype(nu_c.dtype))
        logs = {"lookahead": lookahead, "curvature": kappa, "rotating": rotating.astype(nu_c.dtype)}
        return command, memory, logs

    def observe(self, memory: tuple[()], saturated: Array) -> tuple[()]:
        return memory
