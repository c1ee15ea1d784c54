"""An independent MuJoCo model of a differential-drive robot, built from a :class:`ddtrack.model.RobotParams`.

MuJoCo knows nothing of ddtrack's reduced equations: it integrates a free-floating chassis with two hinged wheels
that touch a floor through soft frictional contacts, and a frictionless caster. Where the floor's friction can carry
the motion, it must reproduce the no-slip plant; where it cannot, its wheels slip. ``tests/test_mujoco.py`` uses it.

How the model matches ddtrack's (docs/model.md §1, §1.6):

* the chassis and the two wheels together have ddtrack's mass m, yaw inertia I_C about their centre of mass, and
  that centre of mass at body x = d ahead of the axle midpoint A (the chassis frame's origin, at axle height R);
* the wheels are spheres of radius R at body y = +-L (a sphere touches the floor at one point under its centre
  whatever the chassis's small roll; a cylinder's edge contacts would move the contact point), hinged about body y,
  with spin inertia J_w, driven by ``motor`` actuators (a torque per wheel, the right wheel at y = -L first); each
  wheel is a disc of 2 % of m (its spin inertia m_w R^2 / 2 at most J_w), the rest of J_w, a geared rotor's
  N^2 J_rotor, is the hinge's ``armature``;
* ddtrack's viscous wheel friction b_w becomes the hinge's ``damping``; its tanh-smoothed Coulomb friction has no
  exact MuJoCo counterpart, so the compared parameters have none (:func:`compared_params`);
* a frictionless caster (a sphere with ``condim = 1`` and a higher ``priority``, so the contact takes its
  frictionless properties, not the floor's) at body x = l_c, on the centre of mass's side, keeps the chassis level
  and carries the load m g d / l_c;
* the centre of mass sits at floor height by default, so accelerating moves no load between the wheels and the
  caster (the planar model has no height; the normal loads stay the static m g (1 - d / l_c) / 2 per wheel);
* the floor's friction is mu, with an elliptic friction cone: the friction circle of docs/model.md §1.5.

The numerical settings matter: a small time step (0.1-0.2 ms), the contact's time constant tied to it (2 time steps,
the least MuJoCo allows), the Newton solver run to a tight tolerance with enough iterations, ``impratio`` > 1 so
friction is stiffer than the normal contact, and gravity along -z. MuJoCo's soft contacts lag the no-slip
constraint: a turning robot's wheels creep sideways at about v omega times half the time constant, so the two
simulators drift apart in proportion to it (docs/reliability.md, "Independent physics check: MuJoCo").

"""

from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np

from ddtrack.model import RobotParams

GRAVITY = 9.80665  #: [m/s^2], as ddtrack.model.traction


def compared_params(params: RobotParams, *, wheel_inertia: float | None = None) -> RobotParams:
    """``params`` without Coulomb wheel friction (MuJoCo has no tanh-smoothed counterpart), with ``wheel_inertia``
    if given (MuJoCo's hinged wheels need some spin inertia; ddtrack then models the same J_w, docs/model.md §1.6),
    and with no torque limit in the way of the replayed torques."""
    changes: dict[str, float] = {"coulomb_friction": 0.0, "max_torque": 1e6}
    if wheel_inertia is not None:
        changes["wheel_inertia"] = wheel_inertia
    return dataclasses.replace(params, **changes)


def mjcf(
    params: RobotParams,
    *,
    friction: float,
    caster_position: float,
    timestep: float = 1e-4,
    wheel_mass: float | None = None,
    com_height: float = 0.0,
    integrator: str = "implicitfast",
) -> str:
    """The MJCF text of the robot on a floor with friction coefficient ``friction``.

    Parameters
    ----------
    params
        The robot; its ``wheel_inertia`` must be positive and its ``coulomb_friction`` zero.
    friction
        Floor friction mu.
    caster_position
        Body x of the caster l_c [m], on the centre of mass's side of the axle, |d| < |l_c|.
    timestep
        MuJoCo's time step [s]; the contact's time constant is 2 of them, the least MuJoCo allows.
    wheel_mass
        Mass of each wheel [kg], part of m (default 2 % of m).
    com_height
        Height of the whole robot's centre of mass above the floor [m] (default 0: no load transfer).
    integrator
        MuJoCo's integrator; ``implicitfast`` treats the hinges' damping implicitly.
    """
    m, i_c, d = float(params.mass), float(params.inertia), float(params.com_offset)
    radius, half, j_w = float(params.wheel_radius), float(params.half_axle), float(params.wheel_inertia)
    if j_w <= 0.0:
        raise ValueError("MuJoCo's hinged wheels need a spin inertia: give params.wheel_inertia > 0")
    if float(params.coulomb_friction) != 0.0:
        raise ValueError("MuJoCo has no tanh-smoothed Coulomb wheel friction: zero it (compared_params)")
    if caster_position * d < 0.0 or abs(d) >= abs(caster_position):
        raise ValueError(f"the caster (x = {caster_position}) must be beyond the centre of mass (d = {d})")
    m_w = 0.02 * m if wheel_mass is None else wheel_mass
    m_c = m - 2.0 * m_w
    x_c = m * d / m_c  # chassis centre of mass: the three bodies' mean is at d
    # heights relative to the chassis frame (axle height R above the floor): the whole robot's at com_height
    z_c = (m * (com_height - radius)) / m_c
    # the wheel itself, a disc: spin inertia m_w R^2 / 2 at most J_w, the rest of J_w is the geared rotor's N^2 J_rotor,
    # which turns about the axle only: the hinge's armature
    j_disc = min(0.5 * m_w * radius**2, j_w)
    armature = j_w - j_disc
    i_w_perp = 0.6 * j_disc  # the disc's inertia about its diameters (>= its spin inertia / 2)
    # parallel-axis theorem about the robot's centre of mass: I_C = chassis + its offset + two wheels
    i_zz = i_c - m_c * (x_c - d) ** 2 - 2.0 * (i_w_perp + m_w * (d**2 + half**2))
    if i_zz <= 0.0:
        raise ValueError(f"wheels of {m_w} kg leave the chassis no yaw inertia (I_C = {i_c})")
    caster_radius = 0.5 * radius
    timeconst = 2.0 * timestep
    damping = float(params.viscous_friction)
    wheels = "\n".join(
        f"""      <body name="wheel_{side}" pos="0 {y} 0">
        <joint name="hinge_{side}" type="hinge" axis="0 1 0" damping="{damping!r}"
               armature="{armature!r}"/>
        <inertial pos="0 0 0" mass="{m_w!r}" diaginertia="{i_w_perp!r} {j_disc!r} {i_w_perp!r}"/>
        <geom name="tyre_{side}" type="sphere" size="{radius!r}" friction="{friction!r} 0 0" contype="1"
              conaffinity="0" condim="3"/>
      </body>"""
        for side, y in (("right", -half), ("left", half))
    )
    return f"""<mujoco model="ddtrack_robot">
  <compiler angle="radian" inertiafromgeom="false" balanceinertia="false"/>
  <option timestep="{timestep!r}" gravity="0 0 {-GRAVITY!r}" integrator="{integrator}" solver="Newton"
          iterations="100" ls_iterations="50" tolerance="1e-12" cone="elliptic" impratio="10"/>
  <default>
    <geom solref="{timeconst!r} 1" solimp="0.9999 0.9999 0.001"/>
  </default>
  <worldbody>
    <geom name="floor" type="plane" size="0 0 1" friction="{friction!r} 0 0" contype="0" conaffinity="1"
          condim="3"/>
    <body name="chassis" pos="0 0 {radius!r}">
      <freejoint name="base"/>
      <inertial pos="{x_c!r} 0 {z_c!r}" mass="{m_c!r}" diaginertia="{0.6 * i_zz!r} {0.6 * i_zz!r} {i_zz!r}"/>
      <geom name="caster" type="sphere" size="{caster_radius!r}" pos="{caster_position!r} 0 {caster_radius - radius!r}"
            friction="0 0 0" condim="1" priority="1" contype="1" conaffinity="0"/>
{wheels}
    </body>
  </worldbody>
  <actuator>
    <motor name="tau_r" joint="hinge_right" gear="1"/>
    <motor name="tau_l" joint="hinge_left" gear="1"/>
  </actuator>
</mujoco>
"""


class MujocoRobot:
    """The robot of :func:`mjcf`, stepped a control period at a time under held wheel torques."""

    def __init__(self, params: RobotParams, **options: float) -> None:
        self.params = params
        self.model = mujoco.MjModel.from_xml_string(mjcf(params, **options))
        self.data = mujoco.MjData(self.model)
        self.chassis = self.model.body("chassis").id
        self.wheels = (self.model.body("wheel_right").id, self.model.body("wheel_left").id)
        self.tyres = (self.model.geom("tyre_right").id, self.model.geom("tyre_left").id)
        mujoco.mj_forward(self.model, self.data)

    @property
    def time(self) -> float:
        return float(self.data.time)

    def settle(self, duration: float = 0.2) -> None:
        """Let the robot sink into its soft contacts at rest, then restart the clock and pose at zero."""
        self.advance(np.zeros(2), duration)
        self.data.qpos[:2] = 0.0
        self.data.qvel[:] = 0.0
        self.data.time = 0.0
        mujoco.mj_forward(self.model, self.data)

    def advance(self, torques: np.ndarray, period: float) -> None:
        """Hold wheel torques (tau_R, tau_L) [N m] for ``period`` [s]."""
        self.data.ctrl[:] = torques
        mujoco.mj_step(self.model, self.data, nstep=round(period / self.model.opt.timestep))

    def body(self) -> np.ndarray:
        """ddtrack's BODY vector [x, y, theta, v, omega] of the axle midpoint A."""
        x, y = self.data.xpos[self.chassis, :2]
        rot = self.data.xmat[self.chassis]
        velocity = np.zeros(6)  # [angular, linear] at A, in the chassis frame
        mujoco.mj_objectVelocity(self.model, self.data, mujoco.mjtObj.mjOBJ_BODY, self.chassis, velocity, 1)
        return np.array([x, y, math.atan2(rot[3], rot[0]), velocity[3], velocity[2]])

    def slip_speeds(self) -> np.ndarray:
        """Speed [m/s] of each wheel's material point at the floor (right, left): zero while it grips."""
        speeds = []
        for wheel in self.wheels:
            velocity = np.zeros(6)  # [angular, linear] at the wheel's centre, world axes
            mujoco.mj_objectVelocity(self.model, self.data, mujoco.mjtObj.mjOBJ_BODY, wheel, velocity, 0)
            contact = velocity[3:] + np.cross(velocity[:3], [0.0, 0.0, -float(self.params.wheel_radius)])
            speeds.append(float(np.hypot(contact[0], contact[1])))
        return np.array(speeds)

    def contact_forces(self) -> dict[str, np.ndarray]:
        """The floor's force on each wheel and the caster, [normal, tangential magnitude] [N] by geom name."""
        forces: dict[str, np.ndarray] = {}
        wrench = np.zeros(6)
        for i in range(self.data.ncon):
            contact = self.data.contact[i]
            name = next(self.model.geom(int(g)).name for g in contact.geom if self.model.geom(int(g)).name != "floor")
            mujoco.mj_contactForce(self.model, self.data, i, wrench)
            forces[name] = forces.get(name, np.zeros(2)) + [wrench[0], math.hypot(wrench[1], wrench[2])]
        return forces
