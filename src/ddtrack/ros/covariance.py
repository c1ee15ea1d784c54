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

import numpy as np

#: a planar covariance's (x, y, yaw) and (v_x, v_y, omega) as indices into ROS's 6 x 6 row-major matrix
PLANAR = np.array([0, 1, 5])


def odometry_covariances(
    columns: Mapping[str, np.ndarray],
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
) -> tuple[np.ndarray, np.ndarray]:
    """(pose, twist) covariances, each (N, 36) row-major, of the odometry estimate in ``columns`` (``odom_theta``,
    ``odom_v``, ``odom_omega`` per control period), with the nominal ``wheel_radius`` R and ``half_axle`` L [m],
    control ``period`` T_c [s], ``encoder_counts`` n per revolution (0: exact angles) and an absolute fix every
    ``fix_periods`` periods (0: none) blended with ``fix_gain`` and noise of these standard deviations [m], [rad];
    ``gyro_noise_density`` [rad/s/sqrt(Hz)]: the turns come from a gyro of that white noise (None: the encoders').
    """
    theta, v, omega = (np.asarray(columns[f"odom_{name}"], dtype=float) for name in ("theta", "v", "omega"))
    reading = 0.0 if encoder_counts == 0 else (2.0 * np.pi / encoder_counts) ** 2 / 12.0
    fix = np.diag([fix_position_std**2, fix_position_std**2, fix_heading_std**2])
    # the augmented error (pose error, last readings' errors): 3 + 2 states, readings' errors independent
    sigma = np.zeros((5, 5))
    sigma[3:, 3:] = reading * np.eye(2)
    pose = np.zeros((len(theta), 3, 3))
    wheels = np.array([[0.5, 0.5], [0.5 / half_axle, -0.5 / half_axle]]) * wheel_radius  # (dphi_R, dphi_L) -> (d, turn)
    gyro = gyro_noise_density is not None
    if gyro:  # the encoders give the distance only; the turn's error is the gyro's, fresh each period
        wheels[1] = 0.0
    density = gyro_noise_density or 0.0
    for k in range(1, len(theta)):
        distance, turn = v[k] * period, omega[k] * period  # the arc of period k - 1 -> k, as the estimate took it
        middle = theta[k - 1] + turn / 2.0
        f = np.array([[1.0, 0.0, -distance * np.sin(middle)], [0.0, 1.0, distance * np.cos(middle)], [0.0, 0.0, 1.0]])
        arc = np.array(
            [
                [np.cos(middle), -distance / 2.0 * np.sin(middle)],
                [np.sin(middle), distance / 2.0 * np.cos(middle)],
                [0.0, 1.0],
            ]
        )
        g = arc @ wheels
        step = np.block([[f, g], [np.zeros((2, 3)), np.zeros((2, 2))]])
        noise = np.vstack([-g, np.eye(2)])  # the new readings' errors enter the increment with a minus sign
        sigma = step @ sigma @ step.T + reading * noise @ noise.T
        sigma[:3, :3] += density**2 * period * np.outer(arc[:, 1], arc[:, 1])
        if fix_periods and k % fix_periods == 0:
            sigma[:3, :3] = (1.0 - fix_gain) ** 2 * sigma[:3, :3] + fix_gain**2 * fix
            sigma[:3, 3:] *= 1.0 - fix_gain
            sigma[3:, :3] *= 1.0 - fix_gain
        pose[k] = sigma[:3, :3]
    speed = 4.0 * reading * (wheel_radius / 2.0 / period) ** 2  # two increments, each of two readings' errors
    twist = np.diag([speed, 0.0, density**2 / period if gyro else speed / half_axle**2])
    return _ros_six(pose), _ros_six(np.broadcast_to(twist, pose.shape))


def _ros_six(planar: np.ndarray) -> np.ndarray:
    """(N, 3, 3) planar covariances as (N, 36): ROS's 6 x 6 row-major, zero outside x, y and yaw."""
    six = np.zeros((planar.shape[0], 6, 6))
    six[:, PLANAR[:, None], PLANAR[None, :]] = planar
    return six.reshape(planar.shape[0], 36)
