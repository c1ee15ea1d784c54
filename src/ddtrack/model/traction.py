"""What grip a run needed: the contact forces of the no-slip plant, after the fact, from its recorded motion.

The plant's wheels cannot slip, so the floor supplies whatever force the motion takes. Every force on the body
comes through the two wheel contacts (massless wheels, frictionless caster), so the reduced equations of motion
(``dynamics.body_acceleration``) give them from the recorded (v, omega) alone, whatever the torques, friction and
disturbances were:

* longitudinal, per wheel: F_R + F_L = m (v_dot - d omega^2) and L (F_R - F_L) = I_A omega_dot + m d v omega;
* lateral, shared by the two drive wheels: F_y = m (v omega + d omega_dot) (the centre of mass's centripetal force);
* normal load N = m g / 2 per drive wheel (the caster carries none: an assumption stated in docs/model.md);
* friction needed: mu_i = |(F_i, F_y / 2)| / N.

A straight line at constant acceleration a needs mu = a / g; a steady circle at speed v and radius r needs
mu = v^2 / (r g) (``tests/test_traction.py``). Pure NumPy: it runs on the recorded columns of any run.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

GRAVITY = 9.80665  #: standard gravity [m/s^2]
#: an assumed, generous upper bound for robot wheels on real floors: rubber on dry concrete is about 1.0 static,
#: 0.6-0.85 sliding (sources in docs/guide.md, "Run folder")
MAX_FLOOR_FRICTION = 1.7


def _rate(t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Forward difference (x_{k+1} - x_k) / T: the mean rate over the period in which the torques held still."""
    if len(x) < 2:
        return np.zeros_like(x)
    rate = np.diff(x) / np.diff(t)
    return np.append(rate, rate[-1])


def contact_forces(
    t: npt.ArrayLike,
    v: npt.ArrayLike,
    omega: npt.ArrayLike,
    *,
    mass: float,
    inertia_axle: float,
    com_offset: float,
    half_axle: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(F_R, F_L, F_y) [N]: the floor's longitudinal force on each wheel and its total lateral force, per sample."""
    t, v, omega = (np.asarray(a, dtype=float) for a in (t, v, omega))
    v_dot, omega_dot = _rate(t, v), _rate(t, omega)
    total = mass * (v_dot - com_offset * omega**2)
    difference = (inertia_axle * omega_dot + mass * com_offset * v * omega) / half_axle
    lateral = mass * (v * omega + com_offset * omega_dot)
    return (total + difference) / 2.0, (total - difference) / 2.0, lateral


def required_friction(
    t: npt.ArrayLike,
    v: npt.ArrayLike,
    omega: npt.ArrayLike,
    *,
    mass: float,
    inertia_axle: float,
    com_offset: float,
    half_axle: float,
) -> np.ndarray:
    """The friction coefficient the more loaded wheel needed at each sample, max_i |(F_i, F_y / 2)| / (m g / 2)."""
    right, left, lateral = contact_forces(
        t, v, omega, mass=mass, inertia_axle=inertia_axle, com_offset=com_offset, half_axle=half_axle
    )
    normal = mass * GRAVITY / 2.0
    return np.maximum(np.hypot(right, lateral / 2.0), np.hypot(left, lateral / 2.0)) / normal


def wheel_speeds(
    v: npt.ArrayLike, omega: npt.ArrayLike, *, wheel_radius: float, half_axle: float
) -> tuple[np.ndarray, np.ndarray]:
    """(phi_dot_R, phi_dot_L) [rad/s] = ((v + L omega) / R, (v - L omega) / R)."""
    v, omega = np.asarray(v, dtype=float), np.asarray(omega, dtype=float)
    return (v + half_axle * omega) / wheel_radius, (v - half_axle * omega) / wheel_radius
