"""Parameters declared once (ddtrack.parameters): the scenario's ``[controller]`` model and the runtime pytree read one
declaration, a number is a traced leaf (changing it compiles nothing new), and what is compile-time structure says so.
"""

from __future__ import annotations

import dataclasses
import importlib
import tomllib
from pathlib import Path
from typing import Any

import jax
import pytest

import ddtrack
from ddtrack._pytree import parts
from ddtrack.parameters import Structure, declaration, declared, is_structure
from ddtrack.scenario import validate_scenario
from ddtrack.scenario.build import build
from ddtrack.scenario.registry import controller_kinds
from ddtrack.shipped import scenario_path

BUILT_IN = [name for name in controller_kinds() if name != "replay"]  # replay has no parameters, only its plan


def _scenario(controller: dict[str, Any]) -> Any:
    data = tomllib.loads(scenario_path("paper_line").read_text())
    return validate_scenario({**data, "controller": controller})


def _nudged(value: Any) -> Any:
    """Another valid value of a number or a tuple of numbers (25 % larger, and 0 becomes 0.01), or of a switch."""
    if isinstance(value, bool):
        return not value
    if isinstance(value, tuple):
        return tuple(_nudged(item) for item in value)
    return value * 1.25 if value else 0.01


@pytest.mark.parametrize("kind", BUILT_IN)
def test_a_number_compiles_no_new_program(kind):
    """Each declared number of a built-in controller (a switch that is a select in the program, such as
    ``strict``, included), changed alone, leaves the built controller's pytree structure (what keys its compiled
    program) unchanged: no number is a compile-time constant by accident."""
    config = controller_kinds()[kind].config
    reference = jax.tree_util.tree_structure(build(_scenario({"kind": kind})).controller)
    changed = []
    for name, field in config.model_fields.items():
        value = field.default
        if name == "kind" or is_structure(config, name) or isinstance(value, str) or value is None:
            continue
        try:
            scenario = _scenario({"kind": kind, name: _nudged(value)})
        except ddtrack.ConfigError:  # a relation with another key (e.g. gains inside gain_max) refuses this value
            continue
        assert jax.tree_util.tree_structure(build(scenario).controller) == reference, f"{kind}.{name}"
        changed.append(name)
    assert len(changed) >= 3, f"{kind}: only {changed} could be changed"


def test_a_structure_parameter_compiles_another_program():
    """A parameter declared Structure reaches the program's key: the structure changes with it."""
    for kind, name, value in [
        ("ltv_lqr", "dare_iterations", 16),
        ("mppi", "horizon", 10),
        ("nn_adaptive_backstepping", "online_learning", False),
        ("regulated_pure_pursuit", "search_samples", 20),
    ]:
        assert is_structure(controller_kinds()[kind].config, name)
        default = jax.tree_util.tree_structure(build(_scenario({"kind": kind})).controller)
        other = jax.tree_util.tree_structure(build(_scenario({"kind": kind, name: value})).controller)
        assert other != default, f"{kind}.{name}"


#: runtime fields whose default is not the section's: the section's None means "resolve it" (here, the preset's gyro)
RESOLVED = {"Sensing.gyro_noise_density", "Sensing.gyro_bias"}


def _assert_declared(obj_or_cls: Any, config: Any, what: str) -> None:
    """Every field of the runtime ``obj_or_cls`` that shares a name with a key of ``config`` and has a default takes
    that default from a declaration (no second copy that could drift), with its value and staticness."""
    cls = obj_or_cls if isinstance(obj_or_cls, type) else type(obj_or_cls)
    for field in dataclasses.fields(cls):
        if field.name not in config.model_fields or field.default is dataclasses.MISSING or field.name == "kind":
            continue
        if config.model_fields[field.name].is_required():  # the section has no default that could be repeated
            continue
        if f"{cls.__name__}.{field.name}" in RESOLVED:
            assert config.model_fields[field.name].default is None
            continue
        declared_by = declaration(cls, field.name)
        assert declared_by is not None, f"{cls.__name__}.{field.name} repeats a default of {what}'s"
        model, name = declared_by
        assert field.default == model.model_fields[name].default
        assert field.metadata.get("static", False) == is_structure(model, name)


@pytest.mark.parametrize("kind", BUILT_IN)
def test_runtime_defaults_are_the_declarations(kind):
    """A built controller's parts take their defaults from the declarations of its ``[controller]`` keys."""
    config = controller_kinds()[kind].config
    for part in parts(build(_scenario({"kind": kind})).controller):
        _assert_declared(part, config, kind)


def test_robot_trajectory_and_sensing_defaults_are_the_declarations():
    """So do the robot's parameters, the curves and the sensing chain, for their sections' keys."""
    from ddtrack.model import RobotParams, Sensing
    from ddtrack.scenario import RobotConfig, SensingConfig
    from ddtrack.scenario.registry import trajectory_kinds
    from ddtrack.trajectories import Circle, FigureEight, Line, Sinusoid

    _assert_declared(RobotParams, RobotConfig, "[robot]")
    _assert_declared(Sensing, SensingConfig, "[sensing]")
    for runtime, kind in [(Line, "line"), (Circle, "circle"), (FigureEight, "figure_eight"), (Sinusoid, "sinusoid")]:
        _assert_declared(runtime, trajectory_kinds()[kind], kind)


def test_disturbance_defaults_are_the_declarations():
    """The sinusoid's bias and phase default once, for the ``[disturbance]`` section and the runtime torque."""
    from ddtrack.model import WheelDisturbance
    from ddtrack.model.disturbance import SinusoidTorque
    from ddtrack.scenario.sections import SinusoidDisturbance

    assert issubclass(SinusoidDisturbance, SinusoidTorque)
    _assert_declared(WheelDisturbance, SinusoidDisturbance, "[disturbance] sinusoid")
    assert declaration(WheelDisturbance, "bias") == (SinusoidTorque, "bias")


def test_timing_is_declared_once():
    """The control period and the substeps default once: the ``[simulation]`` keys, the closed loop, every runtime
    part that samples time, the simulator's solver and the identification run's keyword defaults."""
    import inspect

    from ddtrack.controllers import NNAdaptiveParameters
    from ddtrack.identification import identify
    from ddtrack.integrators import RK4
    from ddtrack.parameters import TIMING, Timing
    from ddtrack.scenario import SimulationConfig

    assert issubclass(SimulationConfig, Timing) and is_structure(SimulationConfig, "substeps")
    from ddtrack.model.slip import slip_plant_model
    from ddtrack.model.slip_velocity import slip_velocity_model
    from ddtrack.sim.simulate import ClosedLoop

    timed = []
    for cls in _package_dataclasses():  # a slip plant's own `substeps` is its minimum, not the loop's: not here
        for field in dataclasses.fields(cls):
            if field.name == "control_period" and field.default is not dataclasses.MISSING:
                assert declaration(cls, field.name) == (Timing, field.name), f"{cls.__name__}.{field.name}"
                timed.append(cls.__name__)
    assert {"WheelPD", "MPPI", "LTVUnicycleLQR", "AdaptiveDynamicCompensator", "Sensing"} <= set(timed), timed
    assert declaration(ClosedLoop, "control_period") == (Timing, "control_period")
    assert declaration(RK4, "substeps") == (Timing, "substeps") and ClosedLoop(None, None, None).solver == RK4()
    defaults = inspect.signature(identify).parameters
    assert defaults["control_period"].default == TIMING.control_period == 0.01
    assert defaults["substeps"].default == TIMING.substeps == 10
    defaults = inspect.signature(identify).parameters  # and the NN-adaptive law's identification run's own
    for argument, declared_name in [
        ("duration", "identification_duration"),
        ("epochs", "epochs"),
        ("learning_rate", "learning_rate"),
        ("momentum", "momentum"),
        ("clip_norm", "gradient_clip"),
    ]:
        assert defaults[argument].default == NNAdaptiveParameters.model_fields[declared_name].default, argument
    for factory in (slip_plant_model, slip_velocity_model):
        defaults = inspect.signature(factory).parameters
        assert (defaults["period"].default, defaults["substeps"].default) == (TIMING.control_period, TIMING.substeps)


def _package_dataclasses() -> list[type]:
    root = Path(ddtrack.__file__).parent
    classes = []
    for path in sorted(root.rglob("*.py")):
        name = ".".join(("ddtrack", *path.relative_to(root).with_suffix("").parts)).removesuffix(".__init__")
        if name.startswith(("ddtrack.cli", "ddtrack.__main__", "ddtrack.ros", "ddtrack.envs", "ddtrack.report")):
            continue  # no pytrees there; the command line sets JAX's devices as it is imported
        module = importlib.import_module(name)
        for value in vars(module).values():
            if isinstance(value, type) and dataclasses.is_dataclass(value) and value.__module__ == name:
                classes.append(value)
    return classes


def test_every_static_field_is_declared_structure_or_says_why():
    """A static field compiles a program per value: each of ddtrack's is either declared Structure or says why it
    cannot be a traced number."""
    statics = []
    for cls in _package_dataclasses():
        for field in dataclasses.fields(cls):
            if not field.metadata.get("static"):
                continue
            statics.append(f"{cls.__name__}.{field.name}")
            declared_by = declaration(cls, field.name)
            reason = field.metadata.get("why")
            assert reason or (declared_by and is_structure(*declared_by)), f"{cls.__name__}.{field.name}: why static?"
    assert "SensedPlant.queue_capacity" in statics and "NNAdaptiveBackstepping.jacobian" in statics


def test_declared_reads_its_model():
    """A runtime field declared by a model takes its default and its staticness; a misspelt name is refused."""
    from ddtrack._pytree import pytree_dataclass
    from ddtrack.parameters import Parameters

    class Law(Parameters):
        gain: float = 2.5
        samples: Structure[int] = 8

    @pytree_dataclass
    class Runtime:
        gain: float = declared(Law)
        count: int = declared(Law, "samples")

    assert Runtime().gain == 2.5 and Runtime().count == 8
    leaves, treedef = jax.tree_util.tree_flatten(Runtime())
    assert leaves == [2.5] and jax.tree_util.tree_structure(Runtime(count=4)) != treedef
    with pytest.raises(TypeError, match="no such field"):

        @pytree_dataclass
        class Wrong:
            gian: float = declared(Law)


def test_every_part_samples_at_the_scenario_period(monkeypatch):
    """The control period is copied into every part of a controller that samples time; a build that hands one
    part another period is refused, naming the part (it would integrate or differentiate at the wrong rate)."""
    from ddtrack.controllers import Cascade, ComputedTorque
    from ddtrack.controllers.baselines import LTVUnicycleLQR
    from ddtrack.scenario import LTVLQRConfig

    def wrong(self, nominal, control_period, key):
        return Cascade(LTVUnicycleLQR(control_period=2 * control_period), ComputedTorque(nominal))

    scenario = _scenario({"kind": "ltv_lqr"})
    assert build(scenario).controller.outer.control_period == scenario.simulation.control_period
    monkeypatch.setattr(LTVLQRConfig, "build", wrong)
    with pytest.raises(TypeError, match="LTVUnicycleLQR with control_period 0.02"):
        build(scenario)
