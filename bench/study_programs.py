"""What a study compiles and what it costs: ``ddtrack bench --suite robots`` cold and warm, and its program count.

Times the command a user runs, as a fresh process, twice: **cold** (an empty compilation cache) and **warm** (the
cache the cold run left, a new output folder), for each source tree given (``--source DIR``: another checkout's
``src``, timed back to back with this one's on the same machine). ``--count`` runs the same cells in this process
with one seed pair each and counts the simulation programs JAX lowers (one per structure is the target).

    python bench/study_programs.py [--controllers A,B,C] [--source /path/to/other/src ...] [--count]

Results: docs/benchmarks.md, "What a study compiles".
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CONTROLLERS = "backstepping,kinematic_backstepping,ltv_lqr/cmd_vel"  #: 98 cells: the three output kinds


def timed_bench(source: Path | None, controllers: str, cache: Path, out: Path) -> float:
    """Seconds of one ``ddtrack bench --suite robots`` process, its imports from ``source`` (default installed)."""
    env = dict(os.environ, DDTRACK_CACHE_DIR=str(cache))
    if source is not None:
        env["PYTHONPATH"] = str(source)
    command = [sys.executable, "-m", "ddtrack", "bench", "--suite", "robots", "--controllers", controllers]
    start = time.perf_counter()
    subprocess.run([*command, "--out", str(out)], env=env, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - start


def count_programs(controllers: str) -> tuple[int, int, int]:
    """(cells, simulation programs lowered, programs the study said it needs) running every cell of the robots suite
    once, two seeds each, as ``bench`` does (``run_sweep``: tasks batched across cells), on a worker thread in this
    process so that the count sees its compilations."""
    from distributed import Client, LocalCluster

    import ddtrack
    from ddtrack.compilations import counting_programs
    from ddtrack.studies.robot_suite import RobotSuite, plan_robot_suite
    from ddtrack.studies.sweep import run_sweep

    ddtrack.enable_float64()
    short = ("simulation.duration=2.0", "simulation.metric_window=[0.0, 2.0]")
    plan = plan_robot_suite(RobotSuite(seeds=2, overrides=short), controllers.split(","))
    said: list[int] = []
    with (
        tempfile.TemporaryDirectory() as out,
        LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster,
        Client(cluster) as client,
        counting_programs() as counts,
    ):
        run_sweep(plan, Path(out), client, on_programs=lambda needed, held: said.append(needed))
    return len(plan.configurations), counts["jit(_metric_series)"], said[0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--controllers", default=CONTROLLERS)
    parser.add_argument("--source", type=Path, action="append", default=[], help="another checkout's src, first")
    parser.add_argument("--count", action="store_true", help="count the simulation programs instead of timing")
    args = parser.parse_args()
    if args.count:
        cells, programs, needed = count_programs(args.controllers)
        print(f"{cells} cells: {programs} simulation programs compiled, {needed} said needed")
        return
    for source in [*args.source, None]:
        with tempfile.TemporaryDirectory() as scratch:
            root = Path(scratch)
            cold = timed_bench(source, args.controllers, root / "cache", root / "cold")
            warm = timed_bench(source, args.controllers, root / "cache", root / "warm")
        print(f"{source or 'installed'}: cold {cold:.0f} s, warm {warm:.0f} s", flush=True)


if __name__ == "__main__":
    main()
