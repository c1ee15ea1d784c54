"""The grip a run needed (the no-slip plant's contact forces, from its recorded motion): analytic cases, agreement
with the applied torques, and the paper's line case, which needs more friction than any floor gives."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import SCENARIOS

import ddtrack
from ddtrack.model import traction
from ddtrack.plausibility import traction_columns
from ddtrack.runner import prepare, run_setup
from ddtrack.sim import timeseries

BODY = {"mass": 4.0, "inertia_axle": 0.2, "com_offset": 0.0, "half_axle": 0.15}


def test_constant_acceleration_on_a_line_needs_a_over_g():
    t = np.arange(0.0, 2.0, 0.01)
    a = 1.5
    mu = traction.required_friction(t, a * t, np.zeros_like(t), **BODY)
    np.testing.assert_allclose(mu, a / traction.GRAVITY, rtol=1e-9)


def test_a_steady_circle_needs_v_squared_over_r_g():
    t = np.arange(0.0, 2.0, 0.01)
    v, radius = 0.8, 2.0
    mu = traction.required_friction(t, np.full_like(t, v), np.full_like(t, v / radius), **BODY)
    np.testing.assert_allclose(mu, v**2 / (radius * traction.GRAVITY), rtol=1e-9)
    # a centre of mass ahead of the axle changes nothing in steady turning (omega_dot = 0) but the longitudinal load
    mu_offset = traction.required_friction(
        t, np.full_like(t, v), np.full_like(t, v / radius), **BODY | {"com_offset": 0.1}
    )
    assert np.all(mu_offset > mu)


def test_contact_forces_match_the_applied_torques(tmp_path):
    # no wheel friction and no disturbance: every force on the body is the torque at a wheel over its radius
    spec = ddtrack.load_scenario(
        SCENARIOS / "paper_line.toml",
        overrides=[
            "plant.viscous_friction=0",
            "plant.coulomb_friction=0",
            'disturbance={kind = "none"}',
            "simulation.duration=5",
            "simulation.metric_window=[0, 5]",
        ],
    )
    setup, draws = prepare(spec)
    c = timeseries(run_setup(spec, setup, draws))
    p = setup.plant_params
    right, left, _ = traction.contact_forces(
        c["t"],
        c["v"],
        c["omega"],
        mass=float(p.mass),
        inertia_axle=float(p.inertia_axle),
        com_offset=float(p.com_offset),
        half_axle=float(p.half_axle),
    )
    scale = float(np.max(np.abs(c["tau_r"]))) / float(p.wheel_radius)
    inner = slice(0, -1)  # the last sample repeats the previous period's rate
    # the forward difference is the mean over the period in which the torque was held; v and omega move within it
    for force, torque in ((right, c["tau_r"]), (left, c["tau_l"])):
        gap = np.abs(force[inner] - torque[inner] / float(p.wheel_radius))
        assert np.median(gap) < 0.005 * scale and np.max(gap) < 0.03 * scale
    assert set(traction_columns(p, c)) == {"mu_required", "wheel_speed_r", "wheel_speed_l"}


def test_the_paper_line_needs_more_grip_than_any_floor(tmp_path, cli):
    out = tmp_path / "run"
    code, _, stderr = cli(
        "run",
        SCENARIOS / "paper_line.toml",
        "--set",
        "simulation.duration=5",
        "--set",
        "simulation.metric_window=[0, 5]",
        "--out",
        out,
    )
    assert code == 0
    metrics = json.loads((out / "metrics.json").read_text())
    # 10 N m on 0.05 m wheels of a 10 kg robot: 200 N against 49 N of normal load per wheel, less friction
    assert 3.0 < metrics["mu_required_max"] < 4.2
    assert metrics["time_above_floor_mu"] > 0.0 and metrics["wheel_speed_max"] > 0.0
    # in 5 s the robot, 7 m off the line at the start, has not reached it: off its path to the end of the window
    assert [w["code"] for w in metrics["warnings"]] == ["lost_path", "friction_beyond_any_floor"]
    assert "not physically possible" in stderr


def test_a_gentle_run_needs_no_warning(tmp_path, cli):
    out = tmp_path / "run"
    code, _, stderr = cli(
        "run",
        SCENARIOS / "circle.toml",
        "--set",
        "simulation.duration=5",
        "--set",
        "simulation.metric_window=[0, 5]",
        "--set",
        "plant.floor_friction=3",
        "--out",
        out,
    )
    metrics = json.loads((out / "metrics.json").read_text())
    assert code == 0 and metrics["mu_required_max"] < 3 and metrics["warnings"] == [], stderr


@pytest.mark.parametrize("floor", [0.05, 0.8])
def test_the_floor_setting_moves_the_threshold(floor):
    spec = ddtrack.load_scenario(SCENARIOS / "circle.toml", overrides=[f"plant.floor_friction={floor}"])
    assert spec.plant.floor_friction == floor and spec.plant_params().mass > 0  # the floor is not a robot key
