"""Physical parameters of a differential-drive robot (model.md §0, 1.4, 1.6)."""

from __future__ import annotations

from pydantic import Field

from .._pytree import pytree_dataclass
from ..parameters import NonNegative, Parameters, Positive, declared


class RobotParameters(Parameters):
    """The reduced Lagrangian model's parameters, as a scenario's ``[robot]`` section declares them."""

    mass: Positive = Field(10.0, description="Total mass m [kg].")
    inertia: Positive = Field(0.56, description="Yaw inertia about the centre of mass I_C [kg m^2].")
    com_offset: float = Field(
        0.05, ge=-1.0, le=1.0, description="Signed offset d of the centre of mass ahead of the axle [m]."
    )
    wheel_radius: Positive = Field(0.05, le=2.0, description="Wheel radius R [m].")
    half_axle: Positive = Field(0.25, le=5.0, description="Half the wheel separation L [m].")
    max_torque: Positive = Field(10.0, description="Torque limit per wheel [N m].")
    viscous_friction: NonNegative = Field(0.0, description="Viscous wheel friction b_w [N m s/rad].")
    coulomb_friction: NonNegative = Field(0.0, description="Coulomb wheel friction tau_c [N m].")
    friction_smoothing: Positive = Field(0.01, description="tanh smoothing wheel speed eps_f [rad/s].")
    wheel_inertia: NonNegative = Field(
        0.0,
        le=10.0,
        description=(
            "Spin inertia J_w of each wheel about its axle, wheel plus gear-reflected rotor N^2 J_rotor "
            "[kg m^2]; 0: massless wheels (model.md §1.6)."
        ),
    )


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

    mass: float = declared(RobotParameters)
    inertia: float = declared(RobotParameters)
    com_offset: float = declared(RobotParameters)
    wheel_radius: float = declared(RobotParameters)
    half_axle: float = declared(RobotParameters)
    viscous_friction: float = declared(RobotParameters)
    coulomb_friction: float = declared(RobotParameters)
    friction_smoothing: float = declared(RobotParameters)
    max_torque: float = declared(RobotParameters)
    wheel_inertia: float = declared(RobotParameters)

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
