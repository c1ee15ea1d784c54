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


def count_programs(controllers: str) -> tuple[int, int]:
    """(cells, simulation programs lowered) running every cell of the robots suite once, two seeds each."""
    import ddtrack
    from ddtrack.compilations import counting_programs
    from ddtrack.robot_suite import RobotSuite, plan_robot_suite
    from ddtrack.runner import monte_carlo

    ddtrack.enable_float64()
    short = ("simulation.duration=2.0", "simulation.metric_window=[0.0, 2.0]")
    plan = plan_robot_suite(RobotSuite(seeds=2, overrides=short), controllers.split(","))
    frame = plan.trajectory_frame()  # as run_sweep does
    with counting_programs() as counts:
        for configuration in plan.configurations:
            monte_carlo(configuration.scenario, [0, 1], chunk_size=2, frame=frame)
    return len(plan.configurations), counts["jit(_metric_series)"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--controllers", default=CONTROLLERS)
    parser.add_argument("--source", type=Path, action="append", default=[], help="another checkout's src, first")
    parser.add_argument("--count", action="store_true", help="count the simulation programs instead of timing")
    args = parser.parse_args()
    if args.count:
        cells, programs = count_programs(args.controllers)
        print(f"{cells} cells: {programs} simulation programs")
        return
    for source in [*args.source, None]:
        with tempfile.TemporaryDirectory() as scratch:
            root = Path(scratch)
            cold = timed_bench(source, args.controllers, root / "cache", root / "cold")
            warm = timed_bench(source, args.controllers, root / "cache", root / "warm")
        print(f"{source or 'installed'}: cold {cold:.0f} s, warm {warm:.0f} s", flush=True)


if __name__ == "__main__":
    main()
