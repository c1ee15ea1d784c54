"""The odometry estimate's covariance, from the sensing model that produced it (docs/ros.md, "Covariances").

A ``nav_msgs/Odometry`` carries a 6 x 6 covariance of its pose (x, y, z, roll, pitch, yaw) and of its twist. For
the estimate of ``[sensing] odometry`` it is the estimator's own uncertainty, linearised along the run:

* each encoder reads floor(phi n / 2 pi) counts: a reading error e uniform over one count q = 2 pi / n, variance
  q^2 / 12, independent from reading to reading. An increment carries e_k - e_{k+1}, so consecutive increments'
  errors are correlated (their sum telescopes): the propagation carries the last reading's error in its state;
* the pose error follows the arc update's Jacobians: delta_{k+1} = F_k delta_k + G_k (e_k - e_{k+1});
* an absolute fix blended with gain g replaces delta by (1 - g) delta + g n, n the fix's noise;
* the speeds are increments over T_c: var v = R^2 q^2 / (12 T_c^2), var omega = var v / L^2, uncorrelated;
* with the heading from a gyro of white rate noise of density N, each period's turn is off by an independent error
  of variance N^2 T_c (the encoders still give the distance), and var omega = N^2 / T_c.

What the estimator cannot know is not in it: a wheel radius or half axle other than its nominal R-hat, L-hat,
wheels that slip, a gyro's bias. The true pose's ``/odom`` is exact, so its covariance is zero.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ..scenario import Scenario

#: a planar covariance's (x, y, yaw) and (v_x, v_y, omega) as indices into ROS's 6 x 6 row-major matrix
PLANAR = np.array([0, 1, 5])


def odometry_covariances(
    columns: Mapping[str, np.ndarray], propagation: CovariancePropagation
) -> tuple[np.ndarray, np.ndarray]:
    """(pose, twist) covariances, each (N, 36) row-major, of the odometry estimate in ``columns`` (``odom_theta``,
    ``odom_v``, ``odom_omega`` per control period), carried by ``propagation`` from its period 0 (a fresh one)."""
    theta, v, omega = (np.asarray(columns[f"odom_{name}"], dtype=float) for name in ("theta", "v", "omega"))
    pose = np.stack([propagation.step(*row) for row in zip(theta, v, omega, strict=True)]) if len(theta) else None
    pose = np.zeros((0, 3, 3)) if pose is None else pose
    return _ros_six(pose), _ros_six(np.broadcast_to(propagation.twist, pose.shape))


class CovariancePropagation:
    """The odometry estimate's covariance period by period, so a live robot (``ddtrack robot``) computes each
    period's in constant time: with the nominal ``wheel_radius`` R and ``half_axle`` L [m], control ``period`` T_c
    [s], ``encoder_counts`` n per revolution (0: exact angles) and an absolute fix every ``fix_periods`` periods
    (0: none) blended with ``fix_gain`` and noise of these standard deviations [m], [rad]; ``gyro_noise_density``
    [rad/s/sqrt(Hz)]: the turns come from a gyro of that white noise (None: the encoders').

    Attributes
    ----------
    twist : ndarray
        (3, 3) covariance of (v, 0, omega), the same every period.
    """

    def __init__(
        self,
        *,
        wheel_radius: float,
        half_axle: float,
        period: float,
        encoder_counts: int,
        fix_periods: int = 0,
        fix_gain: float = 0.0,
        fix_position_std: float = 0.0,
        fix_heading_std: float = 0.0,
        gyro_noise_density: float | None = None,
    ) -> None:
        self.period, self.fix_periods, self.fix_gain = period, fix_periods, fix_gain
        self.reading = 0.0 if encoder_counts == 0 else (2.0 * np.pi / encoder_counts) ** 2 / 12.0
        self.fix = np.diag([fix_position_std**2, fix_position_std**2, fix_heading_std**2])
        # the augmented error (pose error, last readings' errors): 3 + 2 states, readings' errors independent
        self.sigma = np.zeros((5, 5))
        self.sigma[3:, 3:] = self.reading * np.eye(2)
        # (dphi_R, dphi_L) -> (d, turn)
        self.wheels = np.array([[0.5, 0.5], [0.5 / half_axle, -0.5 / half_axle]]) * wheel_radius
        self.gyro = gyro_noise_density is not None
        if self.gyro:  # the encoders give the distance only; the turn's error is the gyro's, fresh each period
            self.wheels[1] = 0.0
        self.density = gyro_noise_density or 0.0
        speed = 4.0 * self.reading * (wheel_radius / 2.0 / period) ** 2  # two increments, each of two readings' errors
        self.twist = np.diag([speed, 0.0, self.density**2 / period if self.gyro else speed / half_axle**2])
        self.k, self.theta = 0, 0.0

    @classmethod
    def of(cls, scenario: Scenario) -> CovariancePropagation | None:
        """The propagation of ``scenario``'s ``[sensing]``, with the controller's nominal R-hat, L-hat; None without
        ``[sensing] odometry`` (the pose reported is the true one, exact)."""
        sensing, period = scenario.sensing, float(scenario.simulation.control_period)
        if not sensing.odometry:
            return None
        gyro = sensing.gyro(scenario.robot.preset_robot())  # (noise density, bias) where the heading is a gyro's
        return cls(
            wheel_radius=scenario.robot.wheel_radius,
            half_axle=scenario.robot.half_axle,
            period=period,
            encoder_counts=sensing.encoder_counts,
            fix_periods=round(sensing.fix_period / period),
            fix_gain=sensing.fix_gain,
            fix_position_std=sensing.fix_position_std,
            fix_heading_std=sensing.fix_heading_std,
            gyro_noise_density=None if gyro is None else gyro[0],
        )

    def step(self, theta: float, v: float, omega: float) -> np.ndarray:
        """The (3, 3) covariance of (x, y, yaw) at the next period, whose estimate is (``theta``, ``v``, ``omega``)."""
        k, period = self.k, self.period
        if k > 0:
            sigma, reading, density = self.sigma, self.reading, self.density
            distance, turn = v * period, omega * period  # the arc of period k - 1 -> k, as the estimate took it
            middle = self.theta + turn / 2.0
            f = np.array(
                [[1.0, 0.0, -distance * np.sin(middle)], [0.0, 1.0, distance * np.cos(middle)], [0.0, 0.0, 1.0]]
            )
            arc = np.array(
                [
                    [np.cos(middle), -distance / 2.0 * np.sin(middle)],
                    [np.sin(middle), distance / 2.0 * np.cos(middle)],
                    [0.0, 1.0],
                ]
            )
            g = arc @ self.wheels
            step = np.block([[f, g], [np.zeros((2, 3)), np.zeros((2, 2))]])
            noise = np.vstack([-g, np.eye(2)])  # the new readings' errors enter the increment with a minus sign
            sigma = step @ sigma @ step.T + reading * noise @ noise.T
            sigma[:3, :3] += density**2 * period * np.outer(arc[:, 1], arc[:, 1])
            if self.fix_periods and k % self.fix_periods == 0:
                sigma[:3, :3] = (1.0 - self.fix_gain) ** 2 * sigma[:3, :3] + self.fix_gain**2 * self.fix
                sigma[:3, 3:] *= 1.0 - self.fix_gain
                sigma[3:, :3] *= 1.0 - self.fix_gain
            self.sigma = sigma
        self.k, self.theta = k + 1, theta
        return self.sigma[:3, :3].copy()


def _ros_six(planar: np.ndarray) -> np.ndarray:
    """(N, 3, 3) planar covariances as (N, 36): ROS's 6 x 6 row-major, zero outside x, y and yaw."""
    six = np.zeros((planar.shape[0], 6, 6))
    six[:, PLANAR[:, None], PLANAR[None, :]] = planar
    return six.reshape(planar.shape[0], 36)
