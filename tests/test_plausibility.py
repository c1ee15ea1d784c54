"""What a run asked of a preset's motors: wheel speed against the no-load speed and torque against the torque-speed
curve (model.md §1.7), as metrics and warnings; the motor-driven plant, which cannot exceed them, is never flagged."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import SCENARIOS

from ddtrack.model.motor_plants import motor_from_datasheet
from ddtrack.model.motors import torque_envelope
from ddtrack.plausibility import motor_metrics
from ddtrack.robots import preset

BURGER_MOTOR = motor_from_datasheet(preset("turtlebot3_burger").motor)
NO_LOAD = float(BURGER_MOTOR.no_load_speed)
STALL = float(BURGER_MOTOR.stall_torque)


def _columns(speed_r, speed_l, tau_r, tau_l) -> dict:
    return {
        name: np.asarray(value, dtype=float)
        for name, value in zip(
            ("wheel_speed_r", "wheel_speed_l", "tau_r", "tau_l"), (speed_r, speed_l, tau_r, tau_l), strict=True
        )
    }


def test_a_wheel_past_the_no_load_speed_counts_its_periods():
    speeds = [0.0, 0.5 * NO_LOAD, 1.1 * NO_LOAD, -1.2 * NO_LOAD]  # either direction counts
    metrics = motor_metrics(BURGER_MOTOR, _columns(speeds, np.zeros(4), np.zeros(4), np.zeros(4)), 0.05)
    assert metrics["motor_no_load_speed"] == pytest.approx(NO_LOAD)
    assert metrics["time_beyond_no_load_speed"] == pytest.approx(2 * 0.05)


def test_the_torque_excess_is_measured_from_the_curve_at_the_wheels_speed():
    # at rest the curve spans +- stall; at half the no-load speed the upper end is half the stall torque (model.md
    # §1.7, a straight line with no current limit below stall); at the no-load speed it is 0
    speed = np.array([0.0, 0.5 * NO_LOAD, NO_LOAD])
    high = np.asarray(torque_envelope(BURGER_MOTOR, speed)[1])
    np.testing.assert_allclose(high, [STALL, STALL / 2, 0.0], atol=1e-9 * STALL)
    inside = motor_metrics(BURGER_MOTOR, _columns(speed, speed, 0.99 * high, -0.5 * high), 0.05)
    assert inside["torque_beyond_envelope_max"] == 0.0 and inside["time_outside_torque_envelope"] == 0.0
    beyond = motor_metrics(BURGER_MOTOR, _columns(speed, speed, high + [0.0, 0.1, 0.3], high), 0.05)
    assert beyond["torque_beyond_envelope_max"] == pytest.approx(0.3)
    assert beyond["time_outside_torque_envelope"] == pytest.approx(2 * 0.05)


def test_velocity_input_runs_have_no_motor_metrics():
    assert motor_metrics(BURGER_MOTOR, {"tau_r": np.full(3, np.nan), "tau_l": np.full(3, np.nan)}, 0.05) == {}


def _burger_run(cli, out, *overrides: str) -> tuple[int, dict, str]:
    settings = [
        "robot.preset=turtlebot3_burger",
        "controller.kind=backstepping",
        "simulation.duration=3",
        "simulation.metric_window=[0, 3]",
        *overrides,
    ]
    code, _, stderr = cli(
        "run", SCENARIOS / "burger_sized_20hz.toml", *(a for s in settings for a in ("--set", s)), "--out", out
    )
    return code, json.loads((out / "metrics.json").read_text()), stderr


def test_a_torque_source_driving_a_burger_past_its_motor_is_flagged(tmp_path, cli):
    code, metrics, stderr = _burger_run(cli, tmp_path / "fast", "trajectory.speed=0.25", "controller.max_velocity=0.3")
    codes = [w["code"] for w in metrics["warnings"]]
    assert code == 0 and metrics["status"] == "ok"
    assert metrics["wheel_speed_max"] > metrics["motor_no_load_speed"] == pytest.approx(NO_LOAD)
    assert metrics["time_beyond_no_load_speed"] > 0 and metrics["torque_beyond_envelope_max"] > 0.1 * STALL
    assert {"wheel_speed_beyond_motor", "torque_beyond_motor"} <= set(codes), codes
    assert "no voltage could turn them that fast" in stderr


def test_the_motor_driven_plant_stays_inside_its_curve(tmp_path, cli):
    code, metrics, _ = _burger_run(cli, tmp_path / "motor", "plant.model=motor_torque")
    codes = {w["code"] for w in metrics["warnings"]}
    assert code == 0 and metrics["status"] == "ok"
    assert metrics["torque_beyond_envelope_max"] <= 1e-6 * STALL and metrics["time_outside_torque_envelope"] == 0
    assert metrics["time_beyond_no_load_speed"] == 0
    assert not codes & {"wheel_speed_beyond_motor", "torque_beyond_motor"}


def test_a_slipping_wheel_is_checked_at_its_own_spin_not_the_bodys_rolling_speed():
    """A slip plant records each wheel's spin (phidot_r, phidot_l); while it slips, the body's (v +- L omega) / R is
    another speed, at which the motor's curve would misjudge the torque (false torque_beyond_motor flags)."""
    from ddtrack.model import RobotParams
    from ddtrack.plausibility import traction_columns

    params = RobotParams(**preset("turtlebot3_burger").params)
    t = np.arange(5) * 0.05
    body = {"t": t, "v": np.full(5, 0.1), "omega": np.zeros(5), "tau_r": np.full(5, 0.2), "tau_l": np.full(5, 0.2)}
    rolling = traction_columns(params, body)
    np.testing.assert_allclose(rolling["wheel_speed_r"], 0.1 / params.wheel_radius)
    spinning = traction_columns(params, body | {"phidot_r": np.full(5, 5.0), "phidot_l": np.full(5, 4.0)})
    assert np.all(spinning["wheel_speed_r"] == 5.0) and np.all(spinning["wheel_speed_l"] == 4.0)


def test_a_slip_run_meets_its_motors_curve_alone_and_as_a_batch_row():
    """The TurtleBot3 Waffle Pi of the robots suite on its filleted square, over cmd_vel on its slip plant: its
    servos apply torques within their curve at the wheels' spin, and ``ddtrack mc``'s batch path (which keeps only the
    series the metrics read) checks them at the same speeds as the run alone."""
    from ddtrack.runner import prepare, prepare_batch, run_record, run_setup
    from ddtrack.scenario.files import validate_scenario
    from ddtrack.studies.batches import batch_metrics
    from ddtrack.studies.robot_suite import ROBOTS, base_scenario, suite_entry

    data = base_scenario(ROBOTS["turtlebot3_waffle_pi"], suite_entry("kinematic_backstepping"), "square")
    data["simulation"] |= {"duration": 12.0, "metric_window": [0.0, 12.0]}  # the first corner
    spec = validate_scenario(data)
    setup, draws = prepare(spec)
    _, alone = run_record(spec, setup, run_setup(spec, setup, draws))
    (row,) = batch_metrics(spec, *prepare_batch(spec, [spec.simulation.seed]))
    keys = (
        "torque_beyond_envelope_max",
        "time_outside_torque_envelope",
        "wheel_speed_max",
        "time_beyond_no_load_speed",
    )
    assert {k: row[k] for k in keys} == {k: alone[k] for k in keys}
    assert alone["torque_beyond_envelope_max"] < 1e-9 and alone["time_outside_torque_envelope"] == 0.0


def test_a_robot_without_a_preset_or_motor_is_held_to_its_declared_top_speed(tmp_path, cli):
    """The Burger-sized ideal robot has torque sources that turn its wheels at any speed, but declares the Burger's
    top speed (``[robot] top_speed``): LTV/LQR's rims, max |v| + L |omega| read off the run's own series, went past
    it (9.16 rad/s at the wheel, 153 % of an XL430's no-load speed) and the run says so; without the declaration
    nothing bounds it, and nothing is said."""
    import pyarrow.parquet as pq

    short = ["--set", "simulation.duration=3", "--set", "simulation.metric_window=[0, 3]"]
    out = tmp_path / "run"
    code, _, stderr = cli("run", SCENARIOS / "burger_sized_20hz.toml", "--controller", "ltv_lqr", *short, "--out", out)
    series = pq.read_table(out / "timeseries.parquet").to_pydict()
    rim = float(np.max(np.abs(series["v"]) + 0.08 * np.abs(series["omega"])))
    assert code == 0 and rim / 0.033 == pytest.approx(9.16, abs=0.01)
    (warning,) = json.loads((out / "metrics.json").read_text())["warnings"]
    assert warning["code"] == "speed_beyond_robot" and f"reached {rim:.3g} m/s" in warning["message"]
    assert "0.220 m/s" in warning["message"] and "[speed_beyond_robot]" in stderr
    path = tmp_path / "undeclared.toml"
    path.write_text((SCENARIOS / "burger_sized_20hz.toml").read_text().replace("top_speed = 0.22", ""))
    code, _, _ = cli("run", path, "--controller", "ltv_lqr", *short, "--out", tmp_path / "undeclared")
    assert code == 0 and json.loads((tmp_path / "undeclared" / "metrics.json").read_text())["warnings"] == []
