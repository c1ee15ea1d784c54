"""The controller registry: a kind registered from Python or by a pip-installed plugin is usable by name, and the
capabilities it declares are the ones tune, the build and the environment's gains mode go by."""

from __future__ import annotations

import json
import os
import shlex
import subprocess
import sys
import tomllib
from typing import ClassVar, Literal

import jax.numpy as jnp
import numpy as np
import pyarrow.parquet as pq
import pytest
import tomli_w
from conftest import ROOT, SCENARIOS
from documented import documented
from pydantic import BaseModel, Field

import ddtrack
from ddtrack.controllers import Backstepping, Cascade
from ddtrack.scenario import InnerLoopConfig, Positive, controller_kinds, registry

SHORT = ["simulation.duration=3", "simulation.metric_window=[1, 3]", "initial.pose=[0, 0.3, 0]"]


class TestKanayamaConfig(InnerLoopConfig):
    """Kanayama backstepping registered by a test."""

    __test__ = False  # not a test class, whatever its name
    kind: Literal["test_kanayama"]
    gains: tuple[Positive, Positive, Positive] = Field((1.0, 55.0, 15.0), description="[Kx, Ky, Ktheta].")

    def build(self, nominal, control_period, key):
        kx, ky, ktheta = self.gains
        return Cascade(Backstepping(kx=kx, ky=ky, ktheta=ktheta), self.build_inner(nominal, control_period))


@pytest.fixture
def registered():
    """Register ``test_kanayama`` (Kanayama gains, not differentiable) for one test, and forget it after."""
    ddtrack.register_controller(TestKanayamaConfig, has_kanayama_gains=True)
    yield
    del registry._KINDS["test_kanayama"]  # the golden and determinism tests go over every registered kind


PLANS = {"replay": {"times": [0.0], "commands": [[0.0, 0.0]]}}  # the keys a kind cannot do without


def _scenario_file(tmp_path, kind: str):
    data = tomllib.loads((SCENARIOS / "paper_line.toml").read_text())
    data["controller"] = {"kind": kind, **PLANS.get(kind, {})}
    path = tmp_path / "scenario.toml"
    path.write_text(tomli_w.dumps(data))
    return path


def test_a_kind_registered_from_python_runs_by_name(registered, tmp_path):
    scenario = ddtrack.load_scenario(_scenario_file(tmp_path, "test_kanayama"), overrides=SHORT)
    assert isinstance(scenario.controller, TestKanayamaConfig)
    result = ddtrack.run(scenario)
    mine = ddtrack.run(ddtrack.load_scenario(SCENARIOS / "paper_line.toml", overrides=SHORT))
    assert result.status_name == "ok"
    # the same law and inner loop as the built-in backstepping: the same run
    assert float(abs(result.state - mine.state).max()) < 1e-9
    assert "test_kanayama" in ddtrack.scenario.CONTROLLERS and ddtrack.scenario.kanayama_kinds()[-1] == "test_kanayama"
    with pytest.raises(
        ddtrack.ConfigError, match=r"(?s)controller.kind: unknown kind 'test_kanayma'.*did you mean 'test_kanayama'"
    ):
        ddtrack.load_scenario(_scenario_file(tmp_path, "test_kanayma"))


def test_registration_checks_the_config():
    with pytest.raises(TypeError, match="kind"):
        ddtrack.register_controller(Positive)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="already registered"):

        class Other(TestKanayamaConfig):
            kind: Literal["backstepping"]

        ddtrack.register_controller(Other)


def test_tune_goes_by_the_registry(registered, tmp_path):
    from ddtrack.studies.tune import problems

    assert ddtrack.scenario.tunable_kinds() == ["backstepping"]  # differentiable, Kanayama, torque
    scenario = ddtrack.load_scenario(_scenario_file(tmp_path, "test_kanayama"), overrides=SHORT)
    with pytest.raises(ddtrack.ConfigError, match="(?s)'test_kanayama' has no tunable gains.*backstepping"):
        problems([scenario], [0])


def test_gains_mode_takes_exactly_the_kinds_with_kanayama_gains(registered, tmp_path):
    from ddtrack.envs.tracking import _scenario_for, gains_controllers

    with_gains = [name for name, kind in controller_kinds().items() if kind.has_kanayama_gains]
    assert list(gains_controllers()) == with_gains and "test_kanayama" in with_gains
    for name in controller_kinds():
        scenario = ddtrack.load_scenario(_scenario_file(tmp_path, name), overrides=SHORT)
        if name in with_gains:
            _scenario_for(scenario, "gains")
        else:
            with pytest.raises(ddtrack.ConfigError, match="action_mode"):
                _scenario_for(scenario, "gains")


def test_a_broken_plugin_is_named_not_a_traceback(tmp_path):
    info = tmp_path / "broken_plugin-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: broken-plugin\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text("[ddtrack.controllers]\nbroken = no_such_module:register\n")
    env = os.environ | {"PYTHONPATH": str(tmp_path)}
    done = subprocess.run(
        [sys.executable, "-m", "ddtrack", "list"], capture_output=True, text=True, env=env, timeout=300
    )
    assert done.returncode == 2, done.stderr
    assert "plugin 'broken' (from broken-plugin)" in done.stderr and "no_such_module" in done.stderr
    assert "Traceback" not in done.stderr


@pytest.mark.slow
def test_the_example_plugin_installs_and_runs_through_run_and_mc(tmp_path):
    """pip-installed, the example plugin's controller and its 7-state plant are known to every command by name."""
    target = tmp_path / "site"
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation", "--no-index"]
        + ["--target", str(target), str(ROOT / "examples" / "plugin")],
        check=True,
        timeout=300,
    )
    env = os.environ | {"PYTHONPATH": str(target)}
    listed = subprocess.run([sys.executable, "-m", "ddtrack", "list"], capture_output=True, text=True, env=env)
    assert "integral_kanayama" in listed.stdout and "wheel_angles" in listed.stdout, listed.stderr
    # the commands the plugin's README shows, as written (the install above is its first)
    (install, listing, documented_mc) = [s.command for s in documented("examples/plugin/README.md")]
    assert install == "pip install examples/plugin" and listing.split()[:2] == ["ddtrack", "list"]
    (tmp_path / "scenarios").symlink_to(SCENARIOS)
    for command in (listing, documented_mc):
        done = subprocess.run(
            [sys.executable, "-m", *shlex.split(command)], capture_output=True, text=True, env=env, cwd=tmp_path
        )
        assert done.returncode == 0 and "integral_kanayama" in done.stdout, f"{command}\n{done.stderr[-2000:]}"
    scenario = str(_scenario_file(tmp_path, "integral_kanayama"))
    seven = ["--set", "plant.model=wheel_angles"]
    run = [sys.executable, "-m", "ddtrack", "run", scenario, *seven, "--set", "simulation.duration=3"]
    run += ["--set", "simulation.metric_window=[1, 3]", "--out", str(tmp_path / "run")]
    done = subprocess.run(run, capture_output=True, text=True, env=env, timeout=600, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    columns = pq.read_table(tmp_path / "run" / "timeseries.parquet").column_names
    assert {"phi_r", "phi_l"} <= set(columns)  # the plant's own states, recorded by name
    out = tmp_path / "mc"
    command = [sys.executable, "-m", "ddtrack", "mc", scenario, "-n", "3", *seven]
    command += ["--controllers", "integral_kanayama,backstepping", "--out", str(out)]
    done = subprocess.run(command, capture_output=True, text=True, env=env, timeout=600, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    means = json.loads((out / "summary.json").read_text())["controllers"]
    integral, baseline = (means[name]["e_tr_mean"]["mean"] for name in ("integral_kanayama", "backstepping"))
    assert baseline == pytest.approx(0.046, abs=0.002)  # the paper's line case (the wheel angles feed nothing back)
    assert integral < baseline / 5  # the integral removes the friction-induced lag


def test_each_parameter_reaches_its_controller_under_its_own_name():
    """A config's key and the controller field it sets share one name (``same_named``): given values unlike any
    default, every controller field named like a key carries that key's value, and no key is silently dropped."""
    import dataclasses

    from ddtrack.controllers import Backstepping, NNAdaptiveBackstepping
    from ddtrack.controllers.baselines import LTVUnicycleLQR, RegulatedPurePursuit

    nominal, key = ddtrack.model.RobotParams(), __import__("jax").random.PRNGKey(0)
    # keys read elsewhere: the inner loop's, the identification run's, and the emulator's shape
    elsewhere = {"kind", "inner", "kc", "kp", "kd", "identification", "identification_duration", "epochs"}
    elsewhere |= {"identification_speed", "dither", "emulator", "hidden_units", "gains"}
    cases = {
        "backstepping": ({"max_velocity": 1.7, "max_yaw_rate": 3.3, "strict": True}, Backstepping),
        "nn_adaptive_backstepping": (
            {"rates": (1.0, 2.0, 3.0), "gradient_clip": 7.5, "leakage": 0.25, "momentum": 0.45, "gate_error": 0.3}
            | {"max_velocity": 1.7, "learn_saturated": True, "jacobian": "analytic", "freeze_time": 1.5},
            NNAdaptiveBackstepping,
        ),
        "ltv_lqr": ({"min_velocity": 0.01, "dare_iterations": 12, "max_yaw_rate": 3.3}, LTVUnicycleLQR),
        "regulated_pure_pursuit": ({"pace_gain": 0.7, "search_samples": 17, "max_velocity": 1.1}, RegulatedPurePursuit),
    }
    for name, (values, law) in cases.items():
        config_class = controller_kinds()[name].config
        config = config_class.model_validate({"kind": name, **values})
        extra = {"trajectory": ddtrack.trajectories.Line()} if controller_kinds()[name].needs_reference else {}
        outer = config.build(nominal, 0.01, key, **extra)
        outer = getattr(outer, "outer", outer)
        fields = {field.name for field in dataclasses.fields(law)}
        for key_name, value in values.items():
            assert key_name in fields, f"{name}: key {key_name} has no controller field of that name"
            got = getattr(outer, key_name)
            assert got == value or tuple(got) == value, f"{name}.{key_name}: {got} != {value}"
        assert set(config_class.model_fields) - fields <= elsewhere | {"kx", "ky", "ktheta"}, name


def test_the_benches_take_a_registered_kind_by_name_and_rank_only_closed_loop_kinds(registered, tmp_path):
    """A kind registered from Python (as a plugin's is) is in every bench's default selection and accepted by
    ``--controllers`` (``--suite robots``, ``--scenario``, the quick and standard suites); a kind that plays a plan
    back (``replay``) is neither, and naming it says why."""
    from ddtrack.studies.robot_suite import RobotSuite, default_entries, entry_labels, plan_robot_suite
    from ddtrack.studies.scenario_suite import bench_entries
    from ddtrack.studies.suite import TUNED, controller_names

    assert not controller_kinds()["replay"].tracks_reference and controller_kinds()["test_kanayama"].tracks_reference
    assert "test_kanayama" in default_entries() and "replay" not in default_entries()
    assert controller_names(None)[-2:] == ["test_kanayama", TUNED] and "replay" not in controller_names(None)
    labels = entry_labels(["test_kanayama", "test_kanayama/cmd_vel"])
    suite = RobotSuite(robots=("turtlebot3_burger",), trajectories=("square",), conditions=("nominal",), seeds=1)
    plan = plan_robot_suite(suite, labels)
    assert [(c.controller, c.scenario.controller.kind) for c in plan.configurations] == [
        ("test_kanayama", "test_kanayama"),
        ("test_kanayama/cmd_vel", "test_kanayama"),
    ]
    assert plan.configurations[1].scenario.controller.inner == "none"
    (_, added) = bench_entries([SCENARIOS / "paper_line.toml"], ["test_kanayama"])
    assert added.label == "test_kanayama" and added.scenario.controller.kind == "test_kanayama"
    for refused in (lambda: entry_labels(["replay"]), lambda: controller_names(["replay"])):
        with pytest.raises(ddtrack.ConfigError, match="does not track a reference in closed loop"):
            refused()


@ddtrack.pytree_dataclass
class _Silent:
    """A law that logs nothing: constant wheel torques, or a constant (v, omega) command."""

    command: tuple[float, float]
    output_kind: ClassVar[str]

    def init(self, x0, ref0, key):
        return ()

    def step(self, t, y, ref, memory):
        return jnp.asarray(self.command), memory, {}


@ddtrack.pytree_dataclass
class _SilentTorque(_Silent):
    output_kind: ClassVar[str] = "torque"


@ddtrack.pytree_dataclass
class _SilentVelocity(_Silent):
    output_kind: ClassVar[str] = "velocity"


class SilentTorqueConfig(BaseModel):
    """Constant wheel torques, nothing logged (registered by a test)."""

    kind: Literal["silent_torque"]

    def build(self, nominal, control_period, key):
        return _SilentTorque((0.2, 0.1))


class SilentVelocityConfig(BaseModel):
    """A constant (v, omega) command, nothing logged (registered by a test)."""

    kind: Literal["silent_velocity"]

    def build(self, nominal, control_period, key):
        return _SilentVelocity((0.3, 0.1))


def test_a_law_that_logs_nothing_gets_no_other_quantity_in_its_columns(tmp_path):
    """Columns come from layouts by name: a torque law that logs no velocity command has no ``v_cmd`` or
    ``omega_cmd`` column (its torques once filled them), and a velocity law's command is recorded as ``v_cmd``,
    ``omega_cmd`` whether it logs it or not."""
    ddtrack.register_controller(SilentTorqueConfig)
    ddtrack.register_controller(SilentVelocityConfig, output="velocity")
    try:
        torque = ddtrack.load_scenario(_scenario_file(tmp_path, "silent_torque"), overrides=SHORT)
        columns = ddtrack.timeseries(ddtrack.run(torque))
        assert "v_cmd" not in columns and "omega_cmd" not in columns
        assert np.all(columns["tau_r"] == 0.2) and np.all(columns["tau_l"] == 0.1)
        velocity = ddtrack.load_scenario(
            _scenario_file(tmp_path, "silent_velocity"), overrides=[*SHORT, "plant.model=unicycle"]
        )
        columns = ddtrack.timeseries(ddtrack.run(velocity))
        assert np.all(columns["v_cmd"] == 0.3) and np.all(columns["omega_cmd"] == 0.1)
        assert np.all(np.isnan(columns["tau_r"]))
    finally:
        del registry._KINDS["silent_torque"], registry._KINDS["silent_velocity"]
