"""Package-wide properties: the import layering, float64 outputs, determinism, docstrings, README vs CI."""

from __future__ import annotations

import ast
import inspect
import re
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import ROOT, SCENARIOS

import ddtrack

PACKAGE = ROOT / "src" / "ddtrack"

# DESIGN 2: imports point down only; modules on one line are siblings and may not import each other.
LAYERS = [
    {
        "errors",
        "geometry",
        "_pytree",
        "_ordered",
        "_after_import",
        "_format",
        "shipped",
        "layout",
        "compilations",
    },
    {"precision", "parameters"},
    {"outdir", "feasibility", "integrators"},
    {"model", "trajectories"},
    {"controllers", "robots"},
    {"sim"},
    {"identification"},
    {"scenario", "metrics", "adaptation", "plausibility"},
    {"runner", "plotting"},
    {"animation", "schema", "studies"},
    {"rundir"},
    {"report", "envs", "ros"},
    {"sysid"},
    {"cluster"},
    {"cli"},
]


def _short(seconds: int) -> list[str]:
    """Overrides that shorten a shipped scenario (its metric window must shrink with it)."""
    return [f"simulation.duration={seconds}", f"simulation.metric_window=[0, {seconds}]"]


RANK = {name: rank for rank, names in enumerate(LAYERS) for name in names}


def _top(module_path: Path) -> str:
    rel = module_path.relative_to(PACKAGE)
    return rel.parts[0].removesuffix(".py")


def _imported_tops(module_path: Path) -> set[str]:
    tree = ast.parse(module_path.read_text())
    depth = len(module_path.relative_to(PACKAGE).parts) - 1  # 0 for ddtrack/x.py, 1 for ddtrack/sub/x.py
    tops = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level > 0:
            if node.level == depth + 1:  # relative to the package root
                tops.add(node.module.split(".")[0] if node.module else "")
        elif isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("ddtrack"):
            tops.add(node.module.split(".")[1] if "." in node.module else "")
    return tops - {""}


def test_imports_point_down_only():
    checked = 0
    for path in PACKAGE.rglob("*.py"):
        top = _top(path)
        if top in ("__init__", "__main__"):
            continue
        assert top in RANK, f"{top} has no place in the layering; add it to LAYERS and DESIGN"
        for imported in _imported_tops(path):
            assert imported in RANK, f"{path.name} imports unknown module {imported}"
            assert RANK[imported] < RANK[top], f"{path.relative_to(PACKAGE)} imports {imported} (same or higher layer)"
            checked += 1
    assert checked > 20


def test_the_simulator_never_imports_a_concrete_controller():
    for path in (PACKAGE / "sim").glob("*.py"):
        assert "controllers" not in _imported_tops(path)


def test_every_output_array_is_float64():
    scenario = ddtrack.load_scenario(SCENARIOS / "paper_line.toml", overrides=[*_short(1)])
    result = ddtrack.run(scenario)
    leaves = jax.tree_util.tree_leaves(
        (result.t, result.state, result.reference, result.error, result.control, result.logs)
    )
    assert len(leaves) > 15
    for leaf in leaves:
        assert leaf.dtype == jnp.float64, leaf.dtype
    for name, column in ddtrack.timeseries(result).items():
        assert column.dtype == np.float64, name


def test_same_seed_same_bits_other_seed_other_draws():
    scenario = ddtrack.load_scenario(SCENARIOS / "figure_eight.toml", overrides=[*_short(3)])
    first, again = ddtrack.run(scenario, seed=5), ddtrack.run(scenario, seed=5)
    other = ddtrack.run(scenario, seed=6)
    assert np.array_equal(np.asarray(first.state), np.asarray(again.state))
    assert np.array_equal(np.asarray(first.control), np.asarray(again.control))
    assert not np.array_equal(np.asarray(first.state), np.asarray(other.state))  # Gaussian disturbance and noise


def test_parameter_draws_follow_the_seed_and_leave_the_rest_alone():
    scenario = ddtrack.load_scenario(SCENARIOS / "waypoints.toml")
    masses = {ddtrack.prepare(scenario, seed=s)[0].plant_params.mass for s in range(20)}
    assert len(masses) == 20 and all(8.0 <= m <= 12.0 for m in masses)  # uniform +-20 % of 10 kg
    setup, _ = ddtrack.prepare(scenario, seed=3)
    assert setup.plant_params.inertia == scenario.plant_params().inertia
    assert setup.nominal.mass == 10.0  # the controller's belief is not drawn


def test_swapping_the_controller_keeps_the_random_draws():
    scenario = ddtrack.load_scenario(SCENARIOS / "figure_eight.toml", overrides=[*_short(2)])
    other = ddtrack.load_scenario(SCENARIOS / "figure_eight.toml", overrides=[*_short(2), "controller.inner=pd"])
    (_, draws_a), (_, draws_b) = ddtrack.prepare(scenario, seed=1), ddtrack.prepare(other, seed=1)
    assert np.array_equal(draws_a.disturbance, draws_b.disturbance) and np.array_equal(draws_a.noise, draws_b.noise)


@pytest.mark.parametrize("seconds", [2, 10.24, 10.25, 41])
def test_a_run_s_draws_are_its_own_length_s_draws(seconds):
    """prepare draws a power-of-two length and keeps the run's rows (one program for many lengths): the rows must
    be the very draws of an array of the run's own length, so that no result depends on the bucket."""
    import jax

    from ddtrack.compilations import padded_length
    from ddtrack.runner import streams

    scenario = ddtrack.load_scenario(
        SCENARIOS / "figure_eight.toml",
        overrides=[f"simulation.duration={seconds}", f"simulation.metric_window=[0, {seconds}]"],
    )
    n = scenario.simulation.n_steps
    assert padded_length(n) >= n and padded_length(n) & (padded_length(n) - 1) == 0
    _, draws = ddtrack.prepare(scenario, seed=4)
    keys = streams(4)
    assert draws.disturbance.shape == (n, 2) and draws.noise.shape == (n, 5)
    assert np.array_equal(draws.disturbance, np.asarray(jax.random.normal(keys["disturbance"], (n, 2))))
    assert np.array_equal(draws.noise, np.asarray(jax.random.normal(keys["noise"], (n, 5))))


# Every shipped scenario runs and tracks, with every controller: tests/test_golden.py.


def test_public_api_is_documented():
    for name in ddtrack.__all__:
        obj = getattr(ddtrack, name)
        assert inspect.getdoc(obj), f"ddtrack.{name} has no docstring"


def _is_protocol(node: ast.ClassDef) -> bool:
    return any(
        isinstance(base, (ast.Name, ast.Subscript)) and ast.unparse(base).startswith("Protocol") for base in node.bases
    )


def test_every_public_function_and_class_has_a_docstring():
    """Top-level functions and classes without a leading underscore, in every module; and the methods of the
    protocols (their docstrings are the calling convention that implementations follow)."""
    missing = []
    for path in sorted(PACKAGE.rglob("*.py")):
        where = path.relative_to(PACKAGE)
        for node in ast.parse(path.read_text()).body:
            if not isinstance(node, (ast.FunctionDef, ast.ClassDef)) or node.name.startswith("_"):
                continue
            if not ast.get_docstring(node):
                missing.append(f"{where}:{node.lineno} {node.name}")
            if isinstance(node, ast.ClassDef) and _is_protocol(node):
                missing += [
                    f"{where}:{m.lineno} {node.name}.{m.name}"
                    for m in node.body
                    if isinstance(m, ast.FunctionDef) and not m.name.startswith("_") and not ast.get_docstring(m)
                ]
    assert missing == [], "no docstring: " + ", ".join(missing)


def _section(doc: str, name: str) -> bool:
    return re.search(rf"^{name}\n-{{3,}}$", doc, flags=re.M) is not None


def test_the_public_api_has_numpydoc_sections():
    """``ddtrack.__all__``: Parameters (Attributes for a record type) where there are arguments, Returns where
    something is returned; and a docstring on every public method and property of its classes."""
    for name in ddtrack.__all__:
        obj = getattr(ddtrack, name)
        doc = inspect.getdoc(obj)
        try:
            parameters = [
                p for p in inspect.signature(obj).parameters.values() if p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
            ]
        except ValueError:  # an exception class without its own __init__
            parameters = []
        if inspect.isclass(obj):
            if parameters:
                assert _section(doc, "Parameters") or _section(doc, "Attributes"), f"ddtrack.{name}: no Parameters"
            for member, value in vars(obj).items():
                function = value.fget if isinstance(value, property) else getattr(value, "__func__", value)
                if not member.startswith("_") and inspect.isfunction(function):
                    assert inspect.getdoc(function), f"ddtrack.{name}.{member} has no docstring"
            continue
        if parameters:
            assert _section(doc, "Parameters"), f"ddtrack.{name} has no Parameters section"
        if inspect.signature(obj).return_annotation not in (None, "None", inspect.Signature.empty):
            assert _section(doc, "Returns"), f"ddtrack.{name} has no Returns section"


def test_ci_runs_the_readme_test_command():
    readme = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```bash\n(.*?)\n```", readme, flags=re.S)
    assert len(blocks) >= 2 and "ddtrack run scenarios/paper_line.toml" in blocks[0]
    test_command = blocks[1].strip()
    assert test_command.endswith("scripts/check")  # lint, types, docs, then pytest (tests/test_quality.py)
    ci = (ROOT / ".ci" / "run").read_text().strip().splitlines()
    assert ci[-1] == test_command


def test_torque_columns_come_from_the_plant_kind():
    from ddtrack.controllers import Backstepping
    from ddtrack.model import KinematicPlant
    from ddtrack.sim import Draws
    from ddtrack.trajectories import Line

    line = Line(heading=0.3, speed=0.5)
    x0 = jnp.array([0.0, 0.2, 0.0, 0.0, 0.0])
    kinematic = ddtrack.simulate(
        ddtrack.ClosedLoop(KinematicPlant(), Backstepping(), line), x0, Draws.zeros(50), n_steps=50
    )
    columns = ddtrack.timeseries(kinematic)
    assert np.all(np.isnan(columns["tau_r"])) and np.all(np.isnan(columns["tau_l"]))  # a velocity input has no torque
    assert np.array_equal(columns["v_cmd"], np.asarray(kinematic.control[:, 0]))
    dynamic = ddtrack.run(ddtrack.load_scenario(SCENARIOS / "paper_line.toml", overrides=_short(1)))
    columns = ddtrack.timeseries(dynamic)
    assert np.array_equal(columns["tau_r"], np.asarray(dynamic.control[:, 0]))


def test_no_source_file_is_over_500_lines():
    """One concern per file (docs/architecture.md): a module that grows past 500 lines is split, not scrolled."""
    lengths = {str(p.relative_to(PACKAGE)): len(p.read_text().splitlines()) for p in PACKAGE.rglob("*.py")}
    assert len(lengths) > 60 and max(lengths.values()) <= 500, sorted(lengths.items(), key=lambda kv: -kv[1])[:3]


def test_the_suite_runs_its_longest_files_first():
    """The order of tests/conftest.py holds: every file it names exists (a renamed one would silently lose its
    place), and scripts/check keeps xdist from reordering the files by their number of tests."""
    from conftest import LONGEST_FIRST

    assert [name for name in LONGEST_FIRST if not (ROOT / "tests" / name).is_file()] == []
    pytest_line = next(line for line in (ROOT / "scripts" / "check").read_text().splitlines() if "-m pytest" in line)
    assert "--dist loadfile" in pytest_line and "--no-loadscope-reorder" in pytest_line, pytest_line
