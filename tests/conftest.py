"""Shared fixtures: paths of the shipped scenarios and a helper that runs the CLI in-process."""

from __future__ import annotations

import os
import resource
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MPLBACKEND", "Agg")  # headless, as the ddtrack command draws (set before Matplotlib loads)

import ddtrack
from ddtrack.cli import collect_garbage_rarely, main
from ddtrack.compilations import mapping_limit, memory_mappings, release_compilations

# a crashing test process writes no core file: a pytest worker holds gigabytes, which would land in the checkout
resource.setrlimit(resource.RLIMIT_CORE, (0, resource.getrlimit(resource.RLIMIT_CORE)[1]))
ddtrack.enable_float64()  # as a script must, before any test builds an array
collect_garbage_rarely()  # as the ddtrack process does: a worker's full collections walk every program it holds
# The persistent compilation cache stays off in the test processes (see below), yet JAX 0.10 still hashes every
# program into a cache key and takes its cache-writing path unless the cache is disabled outright: do that, so the
# thousands of in-process compilations take the plain path (a pytest worker once segfaulted inside that path)
import jax  # noqa: E402

jax.config.update("jax_enable_compilation_cache", False)

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "scenarios"


def central_difference(f, x: np.ndarray, h: float) -> np.ndarray:
    """d f / d x by central differences, one column per component of ``x``."""
    columns = []
    for j in range(x.size):
        step = np.zeros_like(x)
        step[j] = h
        columns.append((np.asarray(f(x + step)) - np.asarray(f(x - step))) / (2 * h))
    return np.stack(columns, axis=-1)


def simulate_unbatched(scenario, setup, draws):
    """A prepared run (``ddtrack.runner.prepare``) through the unbatched simulator, ``ddtrack.sim.simulate``, as a
    ``SimResult``. ``ddtrack run`` simulates it as row 0 of a batch of two (``ddtrack.sim.simulate_alone``), which
    compiles about a third slower and rounds a few values differently in the last bit (both measured)."""
    from ddtrack.runner import closed_loop
    from ddtrack.sim import simulate

    # the loop ddtrack run's program takes
    return simulate(closed_loop(scenario, setup), setup.x0, draws, n_steps=scenario.simulation.n_steps)


@pytest.fixture(scope="session", autouse=True)
def no_persistent_cache_in_this_process():
    """In-process CLI calls leave JAX's persistent compilation cache off. It is process-global: once on, every later
    test would write its executables too, and after some 400 tests' compilations jaxlib 0.10 aborted or crashed
    while (de)serialising one (the tune gradient). A ``ddtrack`` process compiles a few programs and exits; the
    tests that start ``ddtrack`` as a subprocess (test_readme, test_nothing_lost, ...) still use the cache."""
    import ddtrack.cli
    import ddtrack.cli.bench
    import ddtrack.cli.identify
    import ddtrack.cli.studies

    with pytest.MonkeyPatch.context() as patch:
        for module in (ddtrack.cli, ddtrack.cli.bench, ddtrack.cli.identify, ddtrack.cli.studies):
            patch.setattr(module, "enable_compilation_cache", lambda: None)
        yield


#: Each compiled XLA program holds memory mappings of its own, and Linux refuses a process more than
#: vm.max_map_count (65,530) of them; at the limit XLA crashes inside a compile (ddtrack.compilations). A pytest
#: worker that kept every program compiled by some 400 tests held 65,174 (measured). So after each test a worker
#: holding more than half the limit releases its compiled programs (``release_compilations``), as a sweep's worker
#: does, and a test after which the process still holds more than this share of the limit fails named instead of a
#: crash later. Programs are otherwise kept from one test file to the next: with the caches emptied after every
#: file, the suite compiled 7,709 programs instead of 5,297 and took 14 min 18 s instead of 12 min 5 s on two cores.
MAPPING_SHARE_ALLOWED = 0.6


@pytest.fixture(autouse=True)
def mappings_within_budget():
    yield
    if release_compilations():
        held, limit = memory_mappings(), mapping_limit()
        assert held is None or limit is None or held <= MAPPING_SHARE_ALLOWED * limit, (
            f"{held} memory mappings held after this test (limit {limit}): compiled programs are kept alive"
        )


@pytest.fixture(autouse=True)
def persistent_cache_stays_off():
    """Names the test that turned the persistent cache on in this process (see above) instead of a crash later."""
    import jax

    yield
    assert jax.config.jax_compilation_cache_dir is None, "this test turned on JAX's persistent cache in-process"


@pytest.fixture
def cli(capsys):
    """Run ``ddtrack ARGS`` in-process; return (exit code, stdout, stderr)."""

    def invoke(*args: str) -> tuple[int, str, str]:
        code = main([str(a) for a in args])
        out, err = capsys.readouterr()
        return code, out, err

    return invoke


# The longest test files first (seconds on two cores, measured): pytest-xdist (scripts/check, ``--dist loadfile``)
# hands whole files to the workers in this order, so no long file starts last and leaves the other core idle. The
# order holds only with ``--no-loadscope-reorder``: by default xdist orders the files by their number of tests.
LONGEST_FIRST = (
    "test_golden.py",  # 165 s (before its cross cases ran unbatched: alone on one core 125 -> 101 s)
    "test_determinism.py",  # 100
    "test_identify.py",  # 89
    "test_readme.py",  # 172 (every command the README shows; measured beside a running benchmark)
    "test_guide.py",  # 106 (likewise, the guide's)
    "test_install.py",  # 77 (a new venv: pip installs ddtrack and its dependencies)
    "test_examples.py",  # 56
    "test_sweep.py",  # 56
    "test_nn_adaptive.py",  # 54
    "test_identify_motor.py",  # 47
    "test_nn_scaling.py",  # 44
    "test_report.py",  # 38
    "test_cmd_vel.py",  # 38
    "test_batch.py",  # 30
    "test_baselines_adaptive_mppi.py",  # 28
    "test_motor_plants.py",  # 26
)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: the rest keep their order
