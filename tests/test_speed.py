"""An interactive run comes fast: what ``import ddtrack`` and the command line load, how many programs a run
needs and whether the persistent compilation cache answers them (docs/benchmarks.md, "One interactive run").

Not timed tests (the machine's load would decide them): each checks the cause of a slow start instead.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("jax", "gymnasium", "matplotlib", "dask", "distributed", "pandas", "pyarrow", "scipy")
SHORT = ["--set", "simulation.duration=0.5", "--set", "simulation.metric_window=[0, 0.5]"]


def python(code: str, **env: str) -> str:
    """Run ``code`` in a fresh interpreter on this checkout's sources; return its stdout."""
    environment = {k: v for k, v in os.environ.items() if not k.startswith(("JAX_", "XLA_"))}
    environment |= {"PYTHONPATH": str(ROOT / "src"), **env}
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, env=environment, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr
    return done.stdout + done.stderr


def loaded(code: str) -> list[str]:
    out = python(code + f"\nimport sys; print('LOADED', [m for m in {HEAVY!r} if m in sys.modules])")
    return json.loads(out.split("LOADED ", 1)[1].splitlines()[0].replace("'", '"'))


def test_import_ddtrack_loads_no_heavy_library():
    assert loaded("import ddtrack") == []


def test_help_and_version_load_no_heavy_library():
    assert loaded("from ddtrack.cli import main\nmain(['--help'])\nmain(['--version'])") == []


def test_loading_a_scenario_loads_only_jax():
    """SciPy's interpolation (0.2 s) waits for a timed-waypoints reference, the figures' libraries for the run
    folder: a scenario that needs neither loads neither."""
    code = "import ddtrack\nddtrack.enable_float64()\nddtrack.load_scenario('scenarios/paper_line.toml')"
    assert loaded(code) == ["jax"]


@pytest.mark.parametrize("first", ["ddtrack", "jax"])
def test_importing_ddtrack_leaves_jax_alone_and_registers_the_environment(first):
    """Whichever comes first, JAX stays in float32 until the script says otherwise (a process-wide setting is the
    caller's decision), and Gymnasium knows the environment."""
    second = "jax" if first == "ddtrack" else "ddtrack"
    out = python(
        f"import {first}, {second}, gymnasium\n"
        "before = jax.numpy.ones(1).dtype\n"
        "ddtrack.enable_float64()\n"
        "print(before, jax.numpy.ones(1).dtype, 'ddtrack/DiffDriveTracking-v0' in gymnasium.registry)"
    )
    assert out.split()[-3:] == ["float32", "float64", "True"]


def test_a_script_without_float64_is_told_the_fix():
    out = python(
        "import ddtrack\n"
        "try:\n"
        "    ddtrack.load_scenario('scenarios/paper_line.toml')\n"
        "except ddtrack.RunError as exc:\n"
        "    print('refused:', exc)\n"
    )
    assert "refused: ddtrack computes in float64" in out and "ddtrack.enable_float64()" in out


def test_names_load_on_first_use():
    out = python(
        "import ddtrack\nprint(all(callable(getattr(ddtrack, n)) for n in ddtrack.__all__), "
        "sorted(ddtrack.__all__) == sorted(n for n in dir(ddtrack) if n in ddtrack.__all__))"
    )
    assert out.split()[-2:] == ["True", "True"]


def test_the_ddtrack_process_collects_garbage_in_large_rounds_and_a_script_keeps_its_own():
    """At Python's default thresholds some 630 collections took 0.3 s of a 2 s warm run: the ``ddtrack`` process
    raises them before it does anything else; ``main`` called from a script leaves the script's alone."""
    out = python(
        "import gc, ddtrack.cli as cli\n"
        "print('SCRIPT', gc.get_threshold())\n"
        "cli.main(['--version'])\n"
        "print('AFTER_MAIN', gc.get_threshold())\n"
        "cli.main = lambda: print('PROCESS', gc.get_threshold()) or 0\n"
        "cli.entry_point()"
    )
    from ddtrack.cli import GC_THRESHOLDS

    seen = dict(line.split(" ", 1) for line in out.splitlines() if line.startswith(("SCRIPT", "AFTER_", "PROCESS")))
    assert seen["SCRIPT"] == seen["AFTER_MAIN"] != seen["PROCESS"] == str(GC_THRESHOLDS), out


def compile_log(cache: Path, out: Path) -> str:
    """stderr of a short ``ddtrack run`` (the console entry point, fast exit included) logging its compiles."""
    code = (
        "import sys; from ddtrack.cli import entry_point\n"
        f"sys.argv = ['ddtrack', 'run', 'scenarios/paper_line.toml', '--out', {str(out)!r}, *{SHORT!r}]\n"
        "entry_point()"
    )
    return python(code, DDTRACK_CACHE_DIR=str(cache), JAX_LOG_COMPILES="1")


@pytest.mark.slow
def test_a_warm_run_needs_few_programs_and_the_cache_answers_each(tmp_path):
    compile_log(tmp_path / "cache", tmp_path / "cold")
    log = compile_log(tmp_path / "cache", tmp_path / "warm")
    programs = [line for line in log.splitlines() if "Compiling " in line]
    hits = [line for line in log.splitlines() if "Persistent compilation cache hit" in line]
    # the reference sampled for the load-time checks, the draws, the initial state's conversion, the simulation:
    # each small eager dispatch would be a program of its own
    assert 1 <= len(programs) <= 4, "\n".join(programs)
    assert len(hits) == len(programs), log  # the cold run, exited fast, left every entry behind
    assert (tmp_path / "warm" / "metrics.json").stat().st_size > 0
    assert json.loads((tmp_path / "warm" / "metrics.json").read_text())["status"] == "ok"


def test_the_nn_identification_is_one_program():
    """Run op by op, the identification's glue (the exciting reference's sines, the draws, the samples) was some 90
    small programs, each traced and looked up on its own: 0.5 s of a warm NN-adaptive run."""
    code = (
        "import ddtrack\nfrom ddtrack.runner import prepare\nddtrack.enable_float64()\n"
        "spec = ddtrack.load_scenario('scenarios/paper_line.toml', controller='nn_adaptive_backstepping', overrides="
        "['controller.identification_duration=1', 'controller.epochs=1'])\nprepare(spec)"
    )
    programs = [line for line in python(code, JAX_LOG_COMPILES="1").splitlines() if "Compiling " in line]
    assert any("Compiling jit(identify) " in line for line in programs), "\n".join(programs)
    assert not any(f"Compiling jit({glue}) " in line for line in programs for glue in ("sin", "scan")), programs


def test_the_plain_script_reads_the_case_as_ddtrack_does():
    """bench/speed.py's baseline process simulates the same closed loop as ``ddtrack run``."""
    sys.path.insert(0, str(ROOT / "bench"))
    from python_loop import params_from_scenario, params_from_toml

    import ddtrack

    path = ROOT / "scenarios" / "paper_line.toml"
    assert params_from_toml(path) == params_from_scenario(ddtrack.load_scenario(path))


def test_the_floor_process_imports_everything_a_run_does(tmp_path):
    """bench/speed.py's floor (imports and backend start alone) is a floor of ``ddtrack run``: a run loads no heavy
    library the floor process did not."""
    sys.path.insert(0, str(ROOT / "bench"))
    from speed import FLOOR_CODE

    setup, exit_now = FLOOR_CODE.rsplit("; ", 1)
    assert exit_now == "ddtrack.cli.exit_now(0)"
    heavy = f"{{m for m in {HEAVY!r} if m in sys.modules}}"
    code = (
        f"{setup}\nimport json, sys\nfloor = {heavy}\nfrom ddtrack.cli import main\n"
        f"assert main(['run', 'scenarios/paper_line.toml', '--out', {str(tmp_path / 'run')!r}, *{SHORT!r}]) == 0\n"
        f"print('HEAVY', json.dumps({{'floor': sorted(floor), 'run': sorted({heavy} - floor)}}))"
    )
    loaded = json.loads(python(code).split("HEAVY ", 1)[1].splitlines()[0])
    assert loaded["run"] == [] and {"jax", "matplotlib", "pyarrow"} <= set(loaded["floor"]), loaded
