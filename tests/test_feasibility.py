"""Scenarios that cannot mean what they say are refused when loaded (exit 2, naming the field and the numbers),
and a failed run's remedy names its cause."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import SCENARIOS

import ddtrack
from ddtrack.errors import ConfigError
from ddtrack.sim import remedy


def test_a_reference_faster_than_the_clamp_is_refused(cli):
    # a 1 m/s circle for a Burger clamped at 0.22 m/s ran "ok" with 1.89 m of error before
    code, _, stderr = cli("validate", SCENARIOS / "burger_sized_20hz.toml", "--set", "trajectory.speed=1")
    assert code == 2 and "Traceback" not in stderr
    assert "trajectory.speed" in stderr and "1 m/s" in stderr and "controller.max_velocity = 0.22" in stderr


def test_a_speed_in_km_per_hour_gets_the_conversion():
    with pytest.raises(ConfigError, match=r"meant in km/h, that is 0\.139 m/s"):
        ddtrack.load_scenario(SCENARIOS / "burger_sized_20hz.toml", overrides=["trajectory.speed=0.5"])


def test_a_yaw_rate_beyond_the_clamp_is_refused():
    with pytest.raises(ConfigError, match="yaw rate.*controller.max_yaw_rate"):
        ddtrack.load_scenario(SCENARIOS / "circle.toml", overrides=["controller.max_yaw_rate=0.1"])


def test_an_angle_in_degrees_is_refused_with_its_radians(cli):
    code, _, stderr = cli("run", SCENARIOS / "paper_line.toml", "--set", "trajectory.heading=45")
    assert code == 2 and "trajectory.heading" in stderr and f"{math.radians(45):.10g}" in stderr
    with pytest.raises(ConfigError, match=r"initial.pose\[2\]"):
        ddtrack.load_scenario(SCENARIOS / "paper_line.toml", overrides=["initial.pose=[0, 10, 90]"])


def test_a_mass_in_grams_is_refused():
    with pytest.raises(ConfigError, match="robot.mass.*radius of gyration"):
        ddtrack.load_scenario(SCENARIOS / "burger_sized_20hz.toml", overrides=["robot.mass=1000"])
    with pytest.raises(ConfigError, match="plant.mass"):
        ddtrack.load_scenario(SCENARIOS / "burger_sized_20hz.toml", overrides=["plant.mass=1000"])


def test_a_reference_near_the_clamp_is_warned(cli):
    code, _, stderr = cli("validate", SCENARIOS / "paper_line.toml", "--set", "trajectory.speed=1.9")
    assert code == 0 and "[reference_near_limit]" in stderr and "95 %" in stderr


@pytest.mark.parametrize("path", sorted(SCENARIOS.glob("*.toml")), ids=lambda p: p.stem)
def test_every_shipped_scenario_is_feasible(path):
    from ddtrack.feasibility import check

    assert check(ddtrack.load_scenario(path)) == []


def test_the_remedy_names_saturation_as_the_cause():
    saturated = {"saturated": np.r_[np.ones(80), np.zeros(20)]}
    assert "lower the gains" in remedy("diverged", {"saturated": np.ones(3)})  # failed at once: no evidence
    assert "could not do what the reference asked" in remedy("diverged", saturated)
    assert "lower the gains" in remedy("diverged", {"saturated": np.zeros(100)})


@pytest.mark.parametrize("name", ["paper_square", "figure_eight"])
def test_the_sampled_reference_is_the_reference_at_each_period(name):
    """The load-time checks sample the reference over a padded length (one program for many lengths) and keep
    the run's samples: they must be the trajectory's own values at t = 0, T_c, ..., the duration."""
    import jax

    from ddtrack.feasibility import sample_reference

    scenario = ddtrack.load_scenario(SCENARIOS / f"{name}.toml")
    sim = scenario.simulation
    times = np.linspace(0.0, sim.duration, int(sim.duration / sim.control_period) + 1)
    expected = jax.vmap(scenario.trajectory.build())(times)
    sampled = sample_reference(scenario)
    for got, want in zip(jax.tree_util.tree_leaves(sampled), jax.tree_util.tree_leaves(expected), strict=True):
        assert got.shape == times.shape
        np.testing.assert_allclose(got, np.asarray(want), rtol=0, atol=1e-12)


LOAD_TWICE = """
import json, sys
import ddtrack
from ddtrack import compilations, feasibility

ddtrack.enable_float64()
compilations.enable_compilation_cache()  # in $DDTRACK_CACHE_DIR, as the ddtrack command does
with compilations.counting_programs() as lowered:
    scenario = ddtrack.load_scenario(sys.argv[1])
    facts = feasibility.reference_facts(scenario)
sampled = feasibility.sample_reference(scenario)
print(json.dumps({"lowered": sum(lowered.values()), "facts": facts._asdict(), "peak": float(max(abs(sampled.v)))}))
"""


def test_a_scenario_loaded_before_is_validated_without_compiling(tmp_path):
    """Loading samples the reference once (a JAX program); its facts are then kept beside the persistent cache, so
    a later process validates the same scenario without tracing, lowering or running anything, and reads the same
    numbers to the bit."""
    import json
    import os
    import subprocess
    import sys

    environment = os.environ | {"DDTRACK_CACHE_DIR": str(tmp_path), "JAX_PLATFORMS": "cpu"}
    outputs = []
    for _ in range(2):
        command = [sys.executable, "-c", LOAD_TWICE, str(SCENARIOS / "figure_eight.toml")]
        done = subprocess.run(command, env=environment, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr[-3000:]
        outputs.append(json.loads(done.stdout))
    first, again = outputs
    assert first["lowered"] >= 1 and again["lowered"] == 0
    assert first["facts"] == again["facts"] and first["facts"]["peak_speed"] == first["peak"]
    assert len(list((tmp_path / "jax" / "ddtrack-references").glob("*.json"))) == 1
