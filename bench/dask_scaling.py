"""Dask scaling: the same sweep on 1 and on 2 workers of the embedded local cluster.

    python bench/dask_scaling.py [--json] [--seeds 128] [--chunk 64]

The paper's line case with backstepping, 4 configurations (`robot.mass` grid) x SEEDS seeds, CHUNK runs per
task. For each worker count: start the cluster, run a small warm-up sweep (each worker compiles the task once;
JAX's persistent cache is shared), then time the real sweep alone. Efficiency = T(1) / (2 T(2)).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def sweep_file(folder: Path, seeds: int, chunk: int) -> Path:
    path = folder / "sweep.toml"
    path.write_text(
        f'scenario = "{ROOT / "scenarios" / "paper_line.toml"}"\ncontrollers = ["backstepping"]\n'
        f'seeds = {seeds}\nchunk = {chunk}\n[grid]\n"robot.mass" = [9.0, 10.0, 11.0, 12.0]\n'
    )
    return path


def timed_sweep(workers: int, seeds: int, chunk: int) -> float:
    from distributed import Client

    from ddtrack.cluster import local_cluster
    from ddtrack.studies.sweep import plan_sweep, read_sweep, run_sweep

    with tempfile.TemporaryDirectory() as tmp, local_cluster(workers) as cluster, Client(cluster) as client:
        folder = Path(tmp)
        warm = sweep_file(folder, chunk * workers, chunk)  # one task per worker, same shapes as the real sweep
        run_sweep(plan_sweep(read_sweep(warm), folder), folder / "warm", client)
        real = sweep_file(folder, seeds, chunk)
        plan = plan_sweep(read_sweep(real), folder)
        start = time.perf_counter()
        run_sweep(plan, folder / "real", client)
        return time.perf_counter() - start


def main() -> None:
    from ddtrack import enable_float64

    enable_float64()  # the driver loads scenarios; the workers get it from the sweep's plugin
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--seeds", type=int, default=128)
    parser.add_argument("--chunk", type=int, default=64)
    args = parser.parse_args()
    t1 = timed_sweep(1, args.seeds, args.chunk)
    t2 = timed_sweep(2, args.seeds, args.chunk)
    runs = 4 * args.seeds
    report = {
        "date": datetime.now(UTC).isoformat(timespec="seconds"),
        "runs": runs,
        "chunk": args.chunk,
        "tasks": runs // args.chunk,
        "one_worker_s": t1,
        "two_workers_s": t2,
        "speedup": t1 / t2,
        "efficiency": t1 / (2 * t2),
    }
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(
            f"{runs} runs in {report['tasks']} tasks: 1 worker {t1:.1f} s, 2 workers {t2:.1f} s, "
            f"speed-up {t1 / t2:.2f}x, efficiency {100 * report['efficiency']:.0f} %"
        )


if __name__ == "__main__":
    main()
