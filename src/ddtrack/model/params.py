"""Physical parameters of a differential-drive robot (model.md §0, 1.4, 1.6)."""

from __future__ import annotations

from .._pytree import pytree_dataclass


@pytree_dataclass
class RobotParams:
    """Parameters of the reduced Lagrangian model (model.md §1.3). All SI units.

    Attributes
    ----------
    mass : float
        Total mass m [kg].
    inertia : float
        Yaw inertia about the centre of mass, I_C [kg m^2].
    com_offset : float
        Signed distance d from the axle midpoint A to the centre of mass, + ahead [m].
    wheel_radius : float
        Wheel radius R [m].
    half_axle : float
        Half the wheel separation, L [m].
    viscous_friction : float
        Viscous wheel friction b_w [N m s/rad], per wheel.
    coulomb_friction : float
        Coulomb wheel friction tau_c [N m], per wheel, smoothed by tanh.
    friction_smoothing : float
        Wheel speed epsilon_f of the tanh Coulomb model [rad/s].
    max_torque : float
        Actuator limit |tau_R|, |tau_L| <= max_torque [N m].
    wheel_inertia : float
        Spin inertia J_w of each wheel about its axle, the wheel plus its gear-reflected rotor N^2 J_rotor
        [kg m^2] (model.md §1.6). 0: massless wheels, the model of §1.3.
    """

    mass: float = 10.0
    inertia: float = 0.56
    com_offset: float = 0.05
    wheel_radius: float = 0.05
    half_axle: float = 0.25
    viscous_friction: float = 0.0
    coulomb_friction: float = 0.0
    friction_smoothing: float = 0.01
    max_torque: float = 10.0
    wheel_inertia: float = 0.0

    @property
    def inertia_axle(self) -> float:
        """I_A = I_C + m d^2, yaw inertia about the axle midpoint [kg m^2]."""
        return self.inertia + self.mass * self.com_offset**2

    @property
    def effective_mass(self) -> float:
        """m + 2 J_w / R^2: the mass the wheel torques accelerate along the track [kg] (model.md §1.6)."""
        return self.mass + 2.0 * self.wheel_inertia / self.wheel_radius**2

    @property
    def effective_inertia_axle(self) -> float:
        """I_A + 2 J_w L^2 / R^2: the yaw inertia the wheel torques turn [kg m^2] (model.md §1.6)."""
        return self.inertia_axle + 2.0 * self.wheel_inertia * self.half_axle**2 / self.wheel_radius**2
