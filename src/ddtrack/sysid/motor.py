"""The motor model of a robot driven by voltages (model.md §1.7, §1.3), as ``ddtrack identify --model motor`` fits
it (docs/identification.md).

Each wheel's torque is tau_i = g (u_i - k_e phi_dot_i) with g = eta k_t / R_a (L_a = 0). Put into the body model
(:mod:`ddtrack.sysid.body`) and divided by g, the no-slip robot is linear in the drivetrain constants
q = (kA_v, kA_md, kA_w, kV, kS) = (M_v / g, m d / g, M_w / g, k_e + b_w / g, tau_c / g)::

    (u_R + u_L) / R   = kA_v v_dot - kA_md omega^2    + (kV (phi_R + phi_L) + kS (s_R + s_L)) / R
    L (u_R - u_L) / R = kA_w omega_dot + kA_md v omega + L (kV (phi_R - phi_L) + kS (s_R - s_L)) / R

with phi_i the wheel speeds and s_i = tanh(phi_i / eps_f): the body model with voltages for torques, so the same
fit serves both. WPILib's SysId characterises a drivetrain by kS, kV and kA too, but per side and per body motion
(linear and angular): :func:`sysid_constants` converts q to those. Voltages and motion fix q
only: every torque in it is scaled by the one motor gain g, so a known mass anchors it (g = m / kA_v, the wheels'
spin inertia folded in as in the body model). Currents, where logged, separate the motor itself: the armature
equation u = R_a i + k_e phi_dot gives R_a and k_e by least squares, then eta k_t = g R_a and the wheels' viscous
friction b_w = g (kV - k_e); without them the viscous friction is folded into k_e.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError
from ..model.motors import DCMotor
from ..model.params import RobotParams
from ..model.traction import wheel_speeds
from .body import body_model, equivalent_robot
from .fit import SpeedFit, SpeedLog, SpeedModel, identify, propagated, simulate
from .schedule import held_at

NAMES = ("kA_v", "kA_md", "kA_w", "kV", "kS")
#: standard errors of the fitted delay within which a switch leaves a sample's voltage unknown (the armature fit
#: pairs each current with the voltage in force at its stamp; one step off there reads a 12 V swing as noise)
UNSURE = 3.0


def motor_model(*, wheel_radius: float, half_axle: float, friction_smoothing: float = 0.01) -> SpeedModel:
    """The voltage-driven robot of wheel radius R [m] and half axle L [m]: the body model read in volts."""
    body = body_model(wheel_radius=wheel_radius, half_axle=half_axle, friction_smoothing=friction_smoothing)
    return dataclasses.replace(
        body,
        name="motor",
        names=NAMES,
        units=("V s^2/m^2", "V s^2/m", "V s^2", "V s/rad", "V"),
        meanings=(
            "M_v / g, the mass the wheels drive per motor gain g = eta k_t / R_a",
            "m d / g, the centre of mass's offset",
            "M_w / g, the yaw inertia about the axle",
            "k_e + b_w / g, back-EMF and viscous friction per wheel",
            "tau_c / g, Coulomb friction per wheel",
        ),
        input_names=("u_r", "u_l"),
        excitation="drive voltage steps of both signs, straight and turning (ddtrack excite --volts)",
    )


@dataclass(frozen=True)
class ArmatureFit:
    """R_a and k_e from u = R_a i + k_e phi_dot over both wheels, with standard errors."""

    resistance: float  #: [ohm]
    back_emf: float  #: [V s/rad]
    std: tuple[float, float]
    noise: float  #: residual spread [V]


@dataclass(frozen=True)
class MotorLog:
    """A voltage log: ``speeds`` with the armature voltages (u_r, u_l) [V] as its input, and the currents (n, 2) [A]
    measured at the same times, or None."""

    speeds: SpeedLog
    current: np.ndarray | None = None


@dataclass(frozen=True)
class MotorFit:
    """The drivetrain constants (``drive``, with the voltage delay) and, with currents, the armature's."""

    drive: SpeedFit
    armature: ArmatureFit | None


def armature_fit(
    voltage: np.ndarray, current: np.ndarray, wheel_speed: np.ndarray, predicted_speed: np.ndarray
) -> ArmatureFit:
    """u = R_a i + k_e phi_dot over both wheels' samples (one motor type) by instrumental variables: the measured
    current and wheel speed are the regressors, the voltage and the fitted model's wheel speed (``predicted_speed``,
    free of measurement noise) the instruments. Plain least squares would read the speed's noise as a smaller k_e
    (errors in variables). Raises ConfigError when currents and speeds do not vary apart."""
    rows = np.column_stack([np.ravel(current), np.ravel(wheel_speed)])
    instruments = np.column_stack([np.ravel(voltage), np.ravel(predicted_speed)])
    target = np.ravel(voltage)
    cross = instruments.T @ rows
    if np.linalg.cond(cross) > 1e12:
        raise ConfigError("LOG", "the currents and wheel speeds do not vary apart", "drive steps and reversals")
    solution = np.linalg.solve(cross, instruments.T @ target)
    residual = target - rows @ solution
    inverse = np.linalg.inv(cross)
    covariance = inverse @ (instruments.T @ instruments) @ inverse.T * float(residual @ residual) / (residual.size - 2)
    std = np.sqrt(np.diag(covariance))
    return ArmatureFit(float(solution[0]), float(solution[1]), (float(std[0]), float(std[1])), float(residual.std()))


def identify_motor(
    log: MotorLog,
    *,
    wheel_radius: float,
    half_axle: float,
    friction_smoothing: float = 0.01,
    max_delay: float = 0.3,
) -> MotorFit:
    """The drivetrain constants and voltage delay of the robot that recorded ``log``; with its currents, R_a and
    k_e (the voltages taken at the same delay as the motion's; samples whose voltage a switch within UNSURE of the
    delay's standard errors leaves in doubt are left out)."""
    model = motor_model(wheel_radius=wheel_radius, half_axle=half_axle, friction_smoothing=friction_smoothing)
    drive = identify(model, log.speeds, max_delay=max_delay)
    if log.current is None:
        return MotorFit(drive, None)
    t = np.asarray(log.speeds.t, dtype=float)
    sent = log.speeds.inputs()
    voltage = held_at(t, *sent, drive.delay)
    margin = UNSURE * drive.delay_std  # a sample this near a switch may have had either voltage: it is left out
    known = np.all(held_at(t, *sent, drive.delay - margin) == held_at(t, *sent, drive.delay + margin), axis=1)
    measured = np.asarray(log.speeds.speed, dtype=float)
    predicted = simulate(model, drive.params, t, None, measured[0], False, drive.substeps, sent=sent, delay=drive.delay)
    wheels = [
        np.column_stack(wheel_speeds(s[:, 0], s[:, 1], wheel_radius=wheel_radius, half_axle=half_axle))[known]
        for s in (measured, predicted)
    ]
    return MotorFit(drive, armature_fit(voltage[known], np.asarray(log.current, dtype=float)[known], *wheels))


def drive_constants(robot: RobotParams, motor: DCMotor) -> np.ndarray:
    """(kA_v, kA_md, kA_w, kV, kS) of ``robot`` whose wheels ``motor`` turns: (M_v, m d, M_w, g k_e + b_w, tau_c) / g,
    g = eta k_t / R_a, the wheels' spin inertia in M_v and M_w (what a log of it should give; a datasheet's
    prediction)."""
    gain = float(motor.efficiency * motor.torque_constant / motor.resistance)
    R, L, m, d = (float(x) for x in (robot.wheel_radius, robot.half_axle, robot.mass, robot.com_offset))
    spin = 2 * float(robot.wheel_inertia) / R**2
    inertia_axle = float(robot.inertia) + m * d**2 + spin * L**2
    viscous, coulomb = float(robot.viscous_friction), float(robot.coulomb_friction)
    return np.array([m + spin, m * d, inertia_axle, gain * float(motor.back_emf) + viscous, coulomb]) / gain


#: the names WPILib's SysId gives a drivetrain's constants, and their units (angular ones per rad/s of yaw rate)
SYSID_NAMES = ("kS", "kV_linear", "kA_linear", "kV_angular", "kA_angular")
SYSID_UNITS = ("V", "V s/m", "V s^2/m", "V s/rad", "V s^2/rad")


def sysid_constants(params: np.ndarray, *, wheel_radius: float, half_axle: float) -> np.ndarray:
    """WPILib SysId's drivetrain constants (:data:`SYSID_NAMES`) from the drive's (kA_v, kA_md, kA_w, kV, kS).

    SysId writes each side's voltage as kS sgn + kV x + kA x_dot, linear (x the side's speed [m/s], both sides
    equal) and angular (x the yaw rate [rad/s], the sides opposite). Put v or omega alone into the motor model
    (wheel speeds (v +- L omega) / R, u_R = +-u_L): kV_linear = kV / R, kA_linear = R kA_v / 2,
    kV_angular = L kV / R, kA_angular = R kA_w / (2 L), and kS as it is. SysId has no term for the centre of mass's
    coupling kA_md (zero with the centre of mass on the axle). WPILib's ``identifyDrivetrainSystem`` takes them with
    the track width 2 L (tests/test_identify_motor.py checks the system it builds against the motor plant)."""
    kA_v, _, kA_w, kV, kS = (float(value) for value in params)
    R, L = float(wheel_radius), float(half_axle)
    return np.array([kS, kV / R, R * kA_v / 2, L * kV / R, R * kA_w / (2 * L)])


def sysid_std(fit: SpeedFit, *, wheel_radius: float, half_axle: float) -> np.ndarray:
    """The standard errors of :func:`sysid_constants` of ``fit``, by the delta method from the drive's covariance."""

    def named(x: np.ndarray) -> dict[str, float]:
        values = sysid_constants(x, wheel_radius=wheel_radius, half_axle=half_axle)
        return dict(zip(SYSID_NAMES, (float(v) for v in values), strict=True))

    std = propagated(named, np.asarray(fit.params, dtype=float), fit.covariance)
    return np.array([std[name] for name in SYSID_NAMES])


def time_constants(params: np.ndarray, *, wheel_radius: float, half_axle: float) -> tuple[float, float]:
    """The drive's time constants [s] of v and omega without friction's corner and the centre of mass's coupling:
    kA_v R^2 / (2 kV) and kA_w R^2 / (2 L^2 kV) (the back-EMF and viscous drag against the inertia)."""
    kA_v, _, kA_w, kV, _ = (float(value) for value in params)
    return kA_v * wheel_radius**2 / (2 * kV), kA_w * wheel_radius**2 / (2 * half_axle**2 * kV)


def plant_fragment(
    fit: MotorFit, *, mass: float, supply_voltage: float | None, preset_motor: DCMotor | None
) -> tuple[dict[str, float], dict[str, float], list[str]]:
    """The ``[plant]`` keys of the equivalent robot, its ``[plant.motor]`` keys, and notes on what was folded or
    taken from elsewhere. ``mass`` [kg] anchors the motor gain; ``preset_motor`` gives R_a when no currents were
    logged (a ConfigError names the options when neither is there); ``supply_voltage`` [V] is written if given."""
    armature = None if fit.armature is None else (fit.armature.resistance, fit.armature.back_emf)
    plant, motor, notes = _fragment(fit.drive.params, armature, mass, preset_motor)
    if supply_voltage is not None:
        motor["supply_voltage"] = supply_voltage
    return plant, motor, notes


def fragment_std(fit: MotorFit, *, mass: float, preset_motor: DCMotor | None) -> dict[str, float]:
    """The standard error of each key of :func:`plant_fragment` (``motor.`` before the motor's), by the delta
    method from the drive's covariance and the armature's standard errors (the two fits taken as independent);
    the mass is given, the preset's resistance exact."""
    drive = np.asarray(fit.drive.params, dtype=float)
    if fit.armature is None:
        values, covariance = drive, fit.drive.covariance
    else:
        values = np.concatenate([drive, [fit.armature.resistance, fit.armature.back_emf]])
        covariance = np.zeros((values.size, values.size))
        covariance[: drive.size, : drive.size] = fit.drive.covariance
        covariance[drive.size :, drive.size :] = np.diag(np.square(fit.armature.std))

    def keys(x: np.ndarray) -> dict[str, float]:
        armature = None if fit.armature is None else (float(x[drive.size]), float(x[drive.size + 1]))
        plant, motor, _ = _fragment(x[: drive.size], armature, mass, preset_motor)
        return plant | {f"motor.{key}": value for key, value in motor.items()}

    return propagated(keys, values, covariance)


def _fragment(
    drive: np.ndarray, armature: tuple[float, float] | None, mass: float, preset_motor: DCMotor | None
) -> tuple[dict[str, float], dict[str, float], list[str]]:
    """:func:`plant_fragment` from the drive constants and the armature's (R_a, k_e), or None without currents."""
    kA_v, kA_md, kA_w, kV, kS = (float(value) for value in drive)
    gain = mass / kA_v  # g = eta k_t / R_a [N m/V]
    md, inertia_axle = gain * kA_md, gain * kA_w
    notes = [
        f"the motor gain eta k_t / R_a = {gain:.4g} N m/V comes from the mass {mass:g} kg: the wheels' spin inertia "
        "is folded into the robot's mass and inertia, and gearbox efficiency into k_t (efficiency = 1)"
    ]
    if armature is not None:
        resistance, back_emf = armature
        viscous = gain * (kV - back_emf)
        if viscous < 0.0:
            notes.append(f"kV is below the currents' k_e by {back_emf - kV:.2g} V s/rad: viscous friction set to 0")
            viscous = 0.0
    elif preset_motor is not None:
        resistance, back_emf, viscous = float(preset_motor.resistance), kV, 0.0
        notes.append(
            f"no currents logged: R_a = {resistance:.4g} ohm is the preset's datasheet value, and the wheels' viscous "
            "friction is folded into k_e"
        )
    else:
        raise ConfigError(
            "LOG",
            "without currents the motor's resistance cannot be told from its torque constant",
            "log the currents (i_r, i_l), or give --preset for its datasheet resistance",
        )
    plant = equivalent_robot(np.array([mass, md, inertia_axle, viscous, gain * kS]))
    motor = {"resistance": resistance, "torque_constant": gain * resistance, "back_emf": back_emf, "efficiency": 1.0}
    return plant, motor, notes
