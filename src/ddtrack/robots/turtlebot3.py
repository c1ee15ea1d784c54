"""The ROBOTIS TurtleBot3 Burger and Waffle Pi: URDF links, DYNAMIXEL datasheets, ROBOTIS' limits, each sourced."""

from __future__ import annotations

import dataclasses
import math

from .datasheets import GyroDatasheet, MotorDatasheet, RobotPreset, UrdfLink, composite_body, composite_height, rpm

_TURTLEBOT3_PAGE = "ROBOTIS e-Manual, TurtleBot3 specifications (https://emanual.robotis.com/docs/en/platform/turtlebot3/specifications/)"
_DXL = "ROBOTIS e-Manual, TurtleBot3 appendix DYNAMIXEL (https://emanual.robotis.com/docs/en/platform/turtlebot3/appendix_dynamixel/)"
_URDF = "ROBOTIS-GIT/turtlebot3, turtlebot3_description/urdf/{}.urdf (https://github.com/ROBOTIS-GIT/turtlebot3)"
_PARAM = "ROBOTIS-GIT/turtlebot3, turtlebot3_bringup/param/{}.yaml (wheels.separation, wheels.radius)"
_BAM = (
    "Rhoban BAM, identified servo armatures (arXiv:2410.08650): XL330 0.002 kg m^2, MX-64 0.012 kg m^2, output-referred"
)

# XL330 and MX-64 armatures identified by Rhoban BAM [kg m^2], output-referred
BAM_ARMATURE_XL330 = 0.002
BAM_ARMATURE_MX64 = 0.012

# Operating Mode (control table address 11) as each e-Manual lists it: the XL430 has no Current Control Mode
XL430_W250 = MotorDatasheet(
    "DYNAMIXEL XL430-W250", 11.1, 1.4, 1.3, rpm(57.0), 0.0, 258.5, 4096,
    "ROBOTIS e-Manual, XL430-W250 (https://emanual.robotis.com/docs/en/dxl/x/xl430-w250/), 11.1 V, Operating "
    "Modes; " + _DXL,
    ("velocity", "position", "extended_position", "pwm"),
)  # fmt: skip
XM430_W210 = MotorDatasheet(
    "DYNAMIXEL XM430-W210", 11.1, 2.7, 2.1, rpm(70.0), 0.0, 212.6, 4096,
    "ROBOTIS e-Manual, XM430-W210 (https://emanual.robotis.com/docs/en/dxl/x/xm430-w210/), 11.1 V, Operating "
    "Modes; " + _DXL,
    ("current", "velocity", "position", "extended_position", "current_based_position", "pwm"),
)  # fmt: skip

# The OpenCR board's IMU, whose yaw the stock odometry takes as its heading (use_imu: true in the bringup
# parameters; turtlebot3_node's odometry then turns by the IMU yaw's change and drives by the wheels' mean)
_ODOMETRY_USE_IMU = (
    "ROBOTIS-GIT/turtlebot3, turtlebot3_bringup/param/humble/{}.yaml (diff_drive_controller odometry.use_imu: "
    "true) and turtlebot3_node/src/odometry.cpp (delta_theta from the IMU's yaw)"
)
_GYRO_DENSITY = math.radians(0.01)  # 0.01 deg/s/sqrt(Hz)
_GYRO_CALIBRATION = 0.5  # [s] at rest averaged at power-up (assumed)
OPENCR_MPU9250 = GyroDatasheet(
    "InvenSense MPU-9250 on the OpenCR 1.0",
    _GYRO_DENSITY,
    _GYRO_DENSITY / math.sqrt(_GYRO_CALIBRATION),
    "InvenSense MPU-9250 Product Specification PS-MPU-9250A-01, gyroscope rate noise spectral density "
    "0.01 deg/s/sqrt(Hz); the IMU per the ROBOTIS OpenCR page (http://support.robotis.com/en/product/controller/"
    "opencr.htm, sensor: 9-axis InvenSense MPU9250)",
    "assumed: one standard deviation of what averaging the gyro at rest for 0.5 s leaves (the OpenCR firmware "
    "calibrates the gyro's offset at power-up; its averaging time is taken, not measured), density / sqrt(0.5 s) "
    f"= {_GYRO_DENSITY / math.sqrt(_GYRO_CALIBRATION):.3g} rad/s; drift with temperature is not modelled",
)

# The URDF links, as far as yaw and load transfer matter. A wheel joint is rotated -1.57 rad about x, so the wheel
# link's y axis is the vertical: its yaw inertia is the URDF's iyy. The caster and laser links are point masses:
# their URDF inertia tensors (0.001 kg m^2 each, on 5 g and 114 g) are placeholders, a 5 g caster with that inertia
# would have a radius of gyration of 0.45 m. Heights: base_link sits 0.010 m above base_footprint (the floor), each
# link's inertial origin at its joint's z above that.
_BASE_Z = 0.010
BURGER_LINKS = (
    UrdfLink("base_link", 8.2573504e-01, 0.0, 0.0, 2.0064271e-03, z=_BASE_Z),
    UrdfLink("wheel_left_link", 2.8498940e-02, 0.0, 0.080, 1.1192413e-05, z=_BASE_Z + 0.023),
    UrdfLink("wheel_right_link", 2.8498940e-02, 0.0, -0.080, 1.1192413e-05, z=_BASE_Z + 0.023),
    UrdfLink("caster_back_link", 0.005, -0.081, 0.0, z=_BASE_Z - 0.004),
    UrdfLink("base_scan", 0.114, -0.032, 0.0, z=_BASE_Z + 0.172),
)
WAFFLE_PI_LINKS = (
    UrdfLink("base_link", 1.3729096e00, 0.0, 0.0, 1.4612727e-02, z=_BASE_Z),
    UrdfLink("wheel_left_link", 2.8498940e-02, 0.0, 0.144, 1.1192413e-05, z=_BASE_Z + 0.023),
    UrdfLink("wheel_right_link", 2.8498940e-02, 0.0, -0.144, 1.1192413e-05, z=_BASE_Z + 0.023),
    UrdfLink("caster_back_right_link", 0.005, -0.177, -0.064, z=_BASE_Z - 0.004),
    UrdfLink("caster_back_left_link", 0.005, -0.177, 0.064, z=_BASE_Z - 0.004),
    UrdfLink("base_scan", 0.114, -0.064, 0.0, z=_BASE_Z + 0.122),
)
# the centre of base_link's collision box above the floor [m]: where its mass would sit if spread through the box
BASE_BOX_CENTRE = {"turtlebot3_burger": _BASE_Z + 0.070, "turtlebot3_waffle_pi": _BASE_Z + 0.047}
TURTLEBOT3_WHEEL_SPIN_INERTIA = 2.0712558e-05  # izz of wheel_left_link, the spin axis [kg m^2]


def _turtlebot3(
    name: str,
    description: str,
    urdf: str,
    param_file: str,
    links: tuple[UrdfLink, ...],
    separation: float,
    motor: MotorDatasheet,
    armature: float,
    armature_why: str,
    spec: tuple[float, float, float],
) -> RobotPreset:
    spec_speed, spec_yaw_rate, spec_mass = spec  # ROBOTIS' top speed [m/s], top yaw rate [rad/s], weight [kg]
    mass, x_com, inertia = composite_body(links)
    height = composite_height(links)
    boxed = composite_height((dataclasses.replace(links[0], z=BASE_BOX_CENTRE[name]), *links[1:]))
    casters = [link.x for link in links if link.name.startswith("caster")]
    radius, half_axle = 0.033, separation / 2.0
    top_speed = motor.no_load_speed * radius  # both wheels at the no-load speed
    coulomb = 0.02 * motor.stall_torque
    return RobotPreset(
        name=name,
        description=description,
        params={
            "mass": mass,
            "inertia": inertia,
            "com_offset": x_com,
            "wheel_radius": radius,
            "half_axle": half_axle,
            "max_torque": motor.stall_torque,
            "viscous_friction": 0.0,
            "coulomb_friction": coulomb,
        },
        wheel_inertia=TURTLEBOT3_WHEEL_SPIN_INERTIA + armature,
        caster_position=sum(casters) / len(casters),
        max_speed=min(spec_speed, top_speed),
        max_yaw_rate=min(spec_yaw_rate, top_speed / half_axle),
        rated_limits=(spec_speed, spec_yaw_rate),
        gyro=OPENCR_MPU9250,
        com_height=height,
        motor=motor,
        lag=None,
        input="velocity",
        sources={
            "mass": _URDF.format(urdf),
            "inertia": _URDF.format(urdf),
            "com_offset": _URDF.format(urdf),
            "wheel_radius": _PARAM.format(param_file) + "; " + _URDF.format(urdf) + " (wheel cylinder radius)",
            "half_axle": _PARAM.format(param_file),
            "max_torque": motor.source,
            "wheel_inertia": _URDF.format(urdf) + " (wheel izz); " + _BAM,
            "caster_position": _URDF.format(urdf),
            "max_speed": _TURTLEBOT3_PAGE + f" ({spec_speed} m/s); " + motor.source,
            "max_yaw_rate": _TURTLEBOT3_PAGE + f" ({spec_yaw_rate} rad/s); " + motor.source,
            "motor": motor.source,
            "input": "ROBOTIS-GIT/turtlebot3, turtlebot3_node: the base takes cmd_vel (v, omega) commands and runs "
            "its DYNAMIXELs in velocity mode",
            "odometry_heading": _ODOMETRY_USE_IMU.format(param_file),
            "gyro_noise_density": OPENCR_MPU9250.source,
            "com_height": _URDF.format(urdf),
        },
        assumptions={
            "mass": f"derived: sum of the URDF's link masses ({len(links)} links); ROBOTIS gives {spec_mass} kg",
            "inertia": "derived: the links' yaw inertias moved to the composite centre of mass (parallel axis); the "
            "caster and laser are point masses, their URDF inertias (0.001 kg m^2) being placeholders",
            "com_offset": "derived: composite centre of mass of the URDF's links; base_link's inertial origin is at "
            "the axle midpoint, so the offset comes from the laser and caster behind it",
            "half_axle": f"derived: separation {separation} m / 2",
            "max_torque": f"the stall torque at {motor.voltage} V, the 3-cell LiPo battery's voltage",
            "viscous_friction": "assumed 0: a motor model's back-EMF is the speed-dependent drag",
            "coulomb_friction": "assumed: 2 % of the stall torque for gearbox and bearing drag (none is published)",
            "wheel_inertia": f"derived: wheel spin izz + assumed armature {armature:.3g} kg m^2 ({armature_why})",
            "caster_position": "the caster joint's x in the URDF (mean of the casters), behind the axle like the "
            "centre of mass",
            "max_speed": f"derived: the lower of ROBOTIS' limit and no-load speed x R = {top_speed:.4g} m/s",
            "max_yaw_rate": "derived: the lower of ROBOTIS' limit and no-load speed x R / L "
            f"= {top_speed / half_axle:.4g} rad/s",
            "lag": "none identified; the motor datasheet describes the drive",
            "gyro_bias": OPENCR_MPU9250.bias_why,
            "com_height": "derived: the links' mass-weighted heights; base_link's inertial origin sits at its frame, "
            "1 cm above the floor, likely a placeholder like its x, so this likely understates the height: with "
            f"base_link's mass at its collision box's centre it would be {boxed:.3g} m (set plant.com_height)",
            "motor": "no-load current not published (the 52/40 mA standby current is the electronics): taken as 0",
        },
    )


TURTLEBOT3_BURGER = _turtlebot3(
    "turtlebot3_burger",
    "ROBOTIS TurtleBot3 Burger: 1 kg, two DYNAMIXEL XL430-W250 wheel servos, rear caster",
    "turtlebot3_burger",
    "burger",
    BURGER_LINKS,
    0.160,
    XL430_W250,
    BAM_ARMATURE_XL330,
    "not published; that of the XL330 identified by BAM, the closest cored X-series servo with a similar "
    "gear ratio (288.4:1 against 258.5:1)",
    (0.22, 2.84, 1.0),
)
TURTLEBOT3_WAFFLE_PI = _turtlebot3(
    "turtlebot3_waffle_pi",
    "ROBOTIS TurtleBot3 Waffle Pi: 1.8 kg, two DYNAMIXEL XM430-W210 wheel servos, two rear casters",
    "turtlebot3_waffle_pi",
    "waffle_pi",
    WAFFLE_PI_LINKS,
    0.287,
    XM430_W210,
    math.sqrt(BAM_ARMATURE_XL330 * BAM_ARMATURE_MX64),
    "not published; the geometric mean of BAM's XL330 and MX-64, which the XM430 lies between in size and torque",
    (0.26, 1.82, 1.8),
)
