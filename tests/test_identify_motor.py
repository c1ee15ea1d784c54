"""Identifying a voltage-driven robot's motors (docs/identification.md): the drivetrain constants and the armature's
R_a and k_e recovered from synthetic logs of a known robot within their reported uncertainty, the fragment a
scenario runs with ``[plant.motor]``, the voltages the motor plants log, and bad input refused with one line."""

from __future__ import annotations

import json
import re
import tomllib

import numpy as np
import pyarrow.parquet as pq
import pytest

from ddtrack.model.motors import DCMotor
from ddtrack.model.params import RobotParams
from ddtrack.scenario import load_scenario
from ddtrack.scenario.motor_configs import scenario_motor
from ddtrack.sysid import drive_constants, identify_motor, motor_log, motor_model, reversing_steps
from ddtrack.sysid.fit import unseparated

RADIUS, HALF = 0.033, 0.08
#: a Burger-sized robot with a 10 % heavier motor than its datasheet's, a lossy gearbox and a little viscous drag
MOTOR = DCMotor(
    resistance=8.5, torque_constant=1.2, back_emf=1.6, efficiency=0.9, supply_voltage=11.1, current_limit=1.3
)
PLAN = reversing_steps(amplitude=6.0, duration=16.0, rate=50.0, seed=0)
BURGER_WHEEL_INERTIA = 0.00202  #: wheel + N^2 J_rotor of its XL430 servo: the drive's time constant is 13 ms
#: massless wheels make it 3.5 ms: such a log is taken at 200 Hz to resolve it
FAST_PLAN = reversing_steps(amplitude=6.0, duration=16.0, rate=200.0, seed=0)


def robot(wheel_inertia: float) -> RobotParams:
    return RobotParams(
        mass=1.3,
        inertia=0.012,
        com_offset=-0.03,
        wheel_radius=RADIUS,
        half_axle=HALF,
        viscous_friction=0.002,
        coulomb_friction=0.01,
        wheel_inertia=wheel_inertia,
    )


def test_the_drive_constants_predict_the_robot_the_plant_simulates():
    """Under a held voltage u on both wheels, the voltage-driven robot (its own physics: the PWM driver and the body
    with spinning wheels) accelerates at v_dot = 2 (u - kV phi - kS tanh(phi / eps_f)) / (R kA_v), phi = v / R, and
    settles at v = R (u - kS) / kV."""
    truth = robot(wheel_inertia=BURGER_WHEEL_INERTIA)
    kA_v, _, _, kV, kS = drive_constants(truth, MOTOR)
    t = np.arange(0.0, 1.0, 1e-3)
    v = motor_log(truth, MOTOR, t, np.full((t.size, 2), 3.0)).speeds.speed[:, 0]
    assert v[-1] == pytest.approx(RADIUS * (3.0 - kS) / kV, rel=1e-6)
    middle = (v[1:] + v[:-1]) / (2 * RADIUS)  # the wheels' speed halfway through each millisecond
    rate = 2 * (3.0 - kV * middle - kS * np.tanh(middle / truth.friction_smoothing)) / (RADIUS * kA_v)
    np.testing.assert_allclose(np.diff(v)[:40] / 1e-3, rate[:40], rtol=1e-3)  # the first 40 ms: v rises fast


def test_the_motor_model_is_recovered_within_its_reported_uncertainty():
    truth = robot(wheel_inertia=BURGER_WHEEL_INERTIA)
    drive, armature = drive_constants(truth, MOTOR), np.array([MOTOR.resistance, MOTOR.back_emf])
    z_drive, z_armature = [], []
    for seed in range(10):  # 50 seeds are published (bench/identify_motor_coverage.py)
        log = motor_log(truth, MOTOR, *PLAN, noise=(0.002, 0.01), current_noise=0.005, delay=0.02, seed=seed)
        fit = identify_motor(log, wheel_radius=RADIUS, half_axle=HALF, max_delay=0.04)  # 0.02, a whole sample, inside
        assert abs(fit.drive.delay - 0.02) <= 4 * fit.drive.delay_std and fit.armature is not None
        z_drive.append((fit.drive.params - drive) / fit.drive.std)
        fitted = np.array([fit.armature.resistance, fit.armature.back_emf])
        z_armature.append((fitted - armature) / np.array(fit.armature.std))
    z = np.concatenate([np.array(z_drive), np.array(z_armature)], axis=1)
    # 70 intervals at a nominal 95 %: below 85 % has probability about 1e-4 if they are right
    assert (np.abs(z) <= 1.96).mean() >= 0.85 and np.all(np.abs(z) < 5), np.round(z, 2)
    # R_a and k_e each on at least 7 of 10 seeds (fewer: probability about 1e-3): a voltage paired with its current
    # one sample off at the switches (the fitted delay a little past a whole sample) took k_e's to 4 of 10
    assert np.all((np.abs(z[:, -2:]) <= 1.96).sum(axis=0) >= 7), np.round(z[:, -2:], 2)


def write_log(path, log) -> None:
    speeds = log.speeds
    columns = [speeds.t, *speeds.command.T, *speeds.speed.T, *log.current.T]
    header = "t [s],u_r [V],u_l [V],v [m/s],omega [rad/s],i_r [A],i_l [A]\n"
    path.write_text(
        header + "".join(",".join(repr(float(c)) for c in row) + "\n" for row in zip(*columns, strict=True))
    )


def test_identify_motor_writes_the_motor_and_robot_a_scenario_runs(tmp_path, cli):
    """A log of a robot with massless wheels (so the weighed mass anchors the torques exactly) and no noise gives
    back its motor (efficiency folded into k_t) and body; the fragment runs as a scenario's plant."""
    truth = robot(wheel_inertia=0.0)
    write_log(tmp_path / "log.csv", motor_log(truth, MOTOR, *FAST_PLAN))
    out = tmp_path / "motor.toml"
    code, printed, _ = cli(
        "identify", tmp_path / "log.csv", "--model", "motor", "--preset", "turtlebot3_burger", "--mass", 1.3,
        "--max-delay", 0, "--out", out,
    )  # fmt: skip
    assert code == 0 and "R_a = 8.5" in printed and "k_e = 1.6" in printed
    # SysId's four (and kS), as printed, are the truth's converted: WPILib takes them as they are
    from ddtrack.sysid.motor import SYSID_NAMES, sysid_constants

    expected_sysid = sysid_constants(drive_constants(truth, MOTOR), wheel_radius=RADIUS, half_axle=HALF)
    for name, value in zip(SYSID_NAMES, expected_sysid, strict=True):
        shown = re.findall(rf"#   {name} = ([-+0-9.e]+) \+-", printed)[-1]  # kS is also the drive's
        assert float(shown) == pytest.approx(value, rel=2e-2 if name == "kS" else 2e-3), name
    fragment = tomllib.loads(out.read_text())
    motor, plant = fragment["plant"]["motor"], fragment["plant"]
    expected_motor = {"resistance": 8.5, "back_emf": 1.6, "torque_constant": 0.9 * 1.2, "efficiency": 1.0}
    for key, value in expected_motor.items():
        assert motor[key] == pytest.approx(value, rel=1e-3), key
    expected_plant = {"mass": 1.3, "inertia": 0.012, "com_offset": -0.03, "viscous_friction": 0.002}
    for key, value in expected_plant.items():
        assert plant[key] == pytest.approx(value, rel=2e-3), key
    assert plant["coulomb_friction"] == pytest.approx(0.01, rel=2e-2)  # a tanh corner, seen only near zero speed
    scenario = tmp_path / "identified.toml"
    scenario.write_text(
        'name = "identified"\n[simulation]\nduration = 1.0\ncontrol_period = 0.05\nsubsteps = 20\n[robot]\n'
        'preset = "turtlebot3_burger"\n[trajectory]\nkind = "circle"\nradius = 0.5\nspeed = 0.1\n'
        '[controller]\nkind = "kinematic_backstepping"\n'
        + out.read_text().replace("[plant]\n", '[plant]\nmodel = "motor_velocity"\n')
    )
    built = scenario_motor(load_scenario(scenario))
    assert float(built.resistance) == pytest.approx(8.5, rel=1e-3)
    assert float(built.supply_voltage) == 11.1  # not identified: the preset's stays
    assert cli("run", scenario, "--out", tmp_path / "run")[0] == 0
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert metrics["motor_no_load_speed"] == pytest.approx(11.1 / motor["back_emf"], rel=1e-12)  # the run's motor


def test_the_motor_plants_log_the_voltage_their_driver_applies(tmp_path, cli):
    """Under the PI wheel loop, u_r, u_l are kp (phi* - phi) + ki z whenever no limit acts (model.md §1.7)."""
    scenario = tmp_path / "s.toml"
    scenario.write_text(
        'name = "s"\n[simulation]\nduration = 2.0\ncontrol_period = 0.05\nsubsteps = 20\n[robot]\n'
        'preset = "turtlebot3_burger"\n[plant]\nmodel = "motor_velocity"\n[trajectory]\nkind = "circle"\n'
        'radius = 0.5\nspeed = 0.1\n[controller]\nkind = "kinematic_backstepping"\n'
    )
    assert cli("run", scenario, "--out", tmp_path / "run")[0] == 0
    table = pq.read_table(tmp_path / "run" / "timeseries.parquet").to_pydict()
    column = lambda name: np.asarray(table[name])  # noqa: E731
    kp, ki = load_scenario(scenario).plant.velocity_pi
    for side, sign in (("r", 1.0), ("l", -1.0)):
        setpoint = (column("v_cmd") + sign * HALF * column("omega_cmd")) / RADIUS
        wheel = (column("v") + sign * HALF * column("omega")) / RADIUS
        pi_voltage = kp * (setpoint - wheel) + ki * column(f"pi_{side}")
        within = np.abs(column(f"i_{side}")) < 1.29  # the current limit is 1.3 A
        assert within.mean() > 0.9
        np.testing.assert_allclose(column(f"u_{side}")[within], pi_voltage[within], rtol=0, atol=1e-9)


def test_plant_motor_overrides_the_preset_and_is_checked(tmp_path):
    base = (
        'name = "m"\n[robot]\n{robot}\n[plant]\nmodel = "{model}"\n[plant.motor]\n{motor}\n'
        '[trajectory]\nkind = "circle"\nradius = 0.5\nspeed = 0.1\n[controller]\nkind = "kinematic_backstepping"\n'
    )

    def motor(robot: str, model: str, keys: str) -> DCMotor:
        path = tmp_path / "m.toml"
        path.write_text(base.format(robot=robot, model=model, motor=keys))
        return scenario_motor(load_scenario(path))

    burger = 'preset = "turtlebot3_burger"'
    overridden = motor(burger, "motor_torque", "resistance = 5.0")
    assert float(overridden.resistance) == 5.0 and float(overridden.supply_voltage) == 11.1
    alone = motor("mass = 1.0", "motor_torque", "resistance = 2.0\ntorque_constant = 0.5\nback_emf = 0.5\n"
                  "supply_voltage = 12.0")  # fmt: skip
    assert float(alone.current_limit) == 6.0 and float(alone.efficiency) == 1.0  # V_s / R_a, and no loss
    from ddtrack.errors import ConfigError

    with pytest.raises(ConfigError, match=r"plant.motor: gives no torque_constant, back_emf, supply_voltage"):
        motor("mass = 1.0", "motor_torque", "resistance = 2.0")
    with pytest.raises(ConfigError, match=r"plant.motor: is read only by models"):
        motor(burger, "dynamic", "resistance = 2.0")


def test_identify_motor_refuses_what_it_cannot_use_and_writes_nothing(tmp_path, cli):
    truth = robot(wheel_inertia=BURGER_WHEEL_INERTIA)
    log = motor_log(truth, MOTOR, *PLAN)
    write_log(tmp_path / "log.csv", log)
    out = tmp_path / "motor.toml"
    cases = [
        ((tmp_path / "log.mcap", "--preset", "turtlebot3_burger"), "no standard ROS 2 message"),
        ((tmp_path / "log.csv", "--wheel-radius", RADIUS, "--half-axle", HALF), "--mass: the motor model needs"),
    ]
    no_currents = tmp_path / "no_currents.csv"
    no_currents.write_text(
        "\n".join(",".join(row.split(",")[:5]) for row in (tmp_path / "log.csv").read_text().split("\n"))
    )
    cases.append(
        ((no_currents, "--wheel-radius", RADIUS, "--half-axle", HALF, "--mass", 1.3), "log the currents (i_r, i_l)")
    )
    for words, message in cases:
        code, _, err = cli("identify", *words, "--model", "motor", "--max-delay", 0, "--out", out)
        assert code == 2 and message in err and len(err.strip().splitlines()) <= 2, err
        assert not out.exists()


def test_excite_writes_a_plan_of_voltages(tmp_path, cli):
    code, printed, _ = cli("excite", "--volts", 6, "--duration", 20, "--rate", 50, "--out", tmp_path / "v.csv")
    assert code == 0 and "1000 voltage pairs" in printed
    rows = np.loadtxt(tmp_path / "v.csv", delimiter=",", skiprows=1)
    assert rows.shape == (1000, 3) and np.abs(rows[:, 1:]).max() <= 6.0 and np.ptp(rows[:, 1] - rows[:, 2]) > 0
    code, _, err = cli("excite", "--volts", 6, "--out", tmp_path / "v.mcap")
    assert code == 2 and "--out" in err and not (tmp_path / "v.mcap").exists()


def test_a_parameter_the_log_leaves_open_is_named_with_the_plan_that_pins_it():
    model = motor_model(wheel_radius=RADIUS, half_axle=HALF)
    notes = unseparated(model, np.array([38.0, -0.3, 0.2, 1.9, 0.2]), np.array([1.0, 1.0, 0.01, 0.01, 0.01]))
    assert len(notes) == 1 and notes[0].startswith("kA_md") and "ddtrack excite --volts" in notes[0]


def test_the_sysid_constants_give_wpilib_the_drivetrain_the_robot_is():
    """The drive's constants as SysId reports them (kV, kA linear and angular), passed to WPILib's own
    ``identifyDrivetrainSystem`` with the track width, build the linear system of the voltage-driven robot's side
    speeds: its step response from rest is the robot's (its own physics, spinning wheels and all), and its time
    constants are the ones ``identify`` prints. The per-wheel constants passed as they are (what ``identify`` once
    called SysId's) give one more than ten times too slow."""
    from scipy.linalg import expm
    from wpimath.system.plant import LinearSystemId

    from ddtrack.sysid.motor import sysid_constants, time_constants

    truth = RobotParams(
        mass=1.3,
        inertia=0.012,
        com_offset=0.0,  # SysId has no term for the centre of mass's coupling
        wheel_radius=RADIUS,
        half_axle=HALF,
        viscous_friction=0.002,
        coulomb_friction=0.0,  # nor for kS in the linear system
        wheel_inertia=BURGER_WHEEL_INERTIA,
    )
    drive = drive_constants(truth, MOTOR)
    kS, kV_lin, kA_lin, kV_ang, kA_ang = sysid_constants(drive, wheel_radius=RADIUS, half_axle=HALF)
    assert kS == 0.0
    system = LinearSystemId.identifyDrivetrainSystem(kV_lin, kA_lin, kV_ang, kA_ang, 2 * HALF)
    A, B = np.asarray(system.A()), np.asarray(system.B())  # states (left, right) speeds [m/s], inputs volts
    volts = np.array([2.0, 5.0])  # left, right: turning while it speeds up
    t = np.arange(0.0, 0.3, 1e-3)
    speeds = motor_log(truth, MOTOR, t, np.tile(volts[::-1], (t.size, 1))).speeds.speed  # (u_r, u_l) in
    sides = np.column_stack([speeds[:, 0] - HALF * speeds[:, 1], speeds[:, 0] + HALF * speeds[:, 1]])
    settled = -np.linalg.solve(A, B @ volts)
    wpilib = np.array([settled - expm(A * s) @ settled for s in t])
    np.testing.assert_allclose(sides, wpilib, rtol=1e-6, atol=1e-9 * np.abs(settled).max())
    poles = sorted(-1.0 / np.linalg.eigvals(A).real)
    assert poles == pytest.approx(sorted(time_constants(drive, wheel_radius=RADIUS, half_axle=HALF)), rel=1e-9)
    _, _, kA_w, kV, _ = drive
    naive = LinearSystemId.identifyDrivetrainSystem(kV, drive[0], kV, kA_w, 2 * HALF)
    slow = sorted(-1.0 / np.linalg.eigvals(np.asarray(naive.A())).real)
    assert all(s > 10 * p for s, p in zip(slow, poles, strict=True)), (slow, poles)
