"""Load: a sweep of 10,000 short runs and a Monte Carlo batch of 100,000 paper line-case runs, with their
wall time and peak memory.

    python bench/load.py [sweep|mc|both] [--configs 10] [--seeds 1000] [--sweep-chunk 50]
                         [-n 100000] [--mc-chunk 256] [--json]

* ``sweep``: ``ddtrack sweep`` of paper_line shortened to 2 s (200 control periods), a ``robot.mass`` grid of
  CONFIGS values x SEEDS seeds (10,000 runs), SWEEP_CHUNK runs per task, on the embedded 2-worker cluster. The
  driver writes one record per run as tasks finish, then ``results.parquet``.
* ``mc``: ``ddtrack mc scenarios/paper_line.toml -n N --controllers backstepping --chunk MC_CHUNK`` (40 s, 4000
  control periods per run), which keeps only each run's metrics, chunk by chunk. Holding every series instead
  would take N x 4000 x ~20 series x 8 bytes (64 GB for N = 100,000).

Each command runs as a subprocess. Its process tree (driver, Dask workers, JAX threads) is sampled every 0.2 s:
the peak resident memory of each process is its ``VmHWM`` in ``/proc/PID/status`` (the kernel's high-water
mark, so a peak between samples is not missed while the process lives), and the tree's total RSS at each
sample; ``getrusage(RUSAGE_CHILDREN).ru_maxrss`` after the wait cross-checks the largest single process.
Then the output is checked: the number of rows, no duplicate key, every run ``ok``.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil
import pyarrow.parquet as pq

ROOT = Path(__file__).resolve().parents[1]
DDTRACK = [sys.executable, "-m", "ddtrack"]
MIB = 2**20


def hwm(pid: int) -> int:
    """Peak resident memory of process ``pid`` so far [bytes] (0 once it is gone)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def measured(command: list[str]) -> dict:
    """Run ``command``; return its wall time [s], the peak memory of its driver and of its largest other
    process, and the peak total RSS of the tree [MiB]."""
    start = time.perf_counter()
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    peaks: dict[int, tuple[str, int]] = {}
    tree_peak = 0
    while proc.poll() is None:
        try:
            family = [psutil.Process(proc.pid), *psutil.Process(proc.pid).children(recursive=True)]
        except psutil.NoSuchProcess:
            family = []
        total = 0
        for member in family:
            try:
                total += member.memory_info().rss
                kind = (
                    "driver"
                    if member.pid == proc.pid
                    else ("worker" if any("spawn_main" in part for part in member.cmdline()) else "other")
                )
            except psutil.NoSuchProcess:
                continue
            peaks[member.pid] = (kind, max(peaks.get(member.pid, ("", 0))[1], hwm(member.pid)))
        tree_peak = max(tree_peak, total)
        time.sleep(0.2)
    stdout, stderr = proc.communicate()
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        sys.exit(f"{' '.join(command)} failed ({proc.returncode}):\n{stderr}")
    by_kind: dict[str, list[int]] = {}
    for kind, peak in peaks.values():
        by_kind.setdefault(kind, []).append(peak)
    return {
        "wall_s": round(wall, 1),
        "stdout": stdout.strip().splitlines(),
        "driver_peak_mib": round(max(by_kind.get("driver", [0])) / MIB),
        "worker_peak_mib": [round(p / MIB) for p in sorted(by_kind.get("worker", []))],
        "tree_peak_rss_mib": round(tree_peak / MIB),
        "largest_child_maxrss_mib": round(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024),
    }


def load_sweep(folder: Path, *, configs: int, seeds: int, chunk: int) -> dict:
    masses = [round(8.0 + 4.0 * i / max(configs - 1, 1), 6) for i in range(configs)]
    path = folder / "sweep.toml"
    path.write_text(
        f'scenario = "{ROOT / "scenarios" / "paper_line.toml"}"\ncontrollers = ["backstepping"]\n'
        f'seeds = {seeds}\nchunk = {chunk}\n[set]\n"simulation.duration" = 2.0\n'
        f'"simulation.metric_window" = [0.0, 2.0]\n[grid]\n"robot.mass" = {masses}\n'
    )
    out = folder / "sweep"
    figures = measured([*DDTRACK, "sweep", str(path), "--out", str(out), "--workers", "2"])
    keys = pq.read_table(out / "results.parquet", columns=["key", "status"])
    figures |= {
        "runs": configs * seeds,
        "tasks": configs * -(-seeds // chunk),
        "rows": keys.num_rows,
        "distinct_keys": len(set(keys.column("key").to_pylist())),
        "records": sum(1 for _ in (out / "records").glob("*.json")),
        "ok": keys.column("status").to_pylist().count("ok"),
    }
    return figures


def load_mc(folder: Path, *, n: int, chunk: int) -> dict:
    out = folder / "mc"
    figures = measured(
        [
            *DDTRACK,
            "mc",
            str(ROOT / "scenarios" / "paper_line.toml"),
            "-n",
            str(n),
            "--controllers",
            "backstepping",
            "--chunk",
            str(chunk),
            "--out",
            str(out),
        ]
    )
    runs = pq.read_table(out / "runs.parquet", columns=["seed", "status"])
    seeds = runs.column("seed").to_pylist()
    figures |= {
        "runs": n,
        "chunk": chunk,
        "rows": runs.num_rows,
        "distinct_seeds": len(set(seeds)),
        "ok": runs.column("status").to_pylist().count("ok"),
        "robot_steps_per_s": round(n * 4000 / figures["wall_s"]),
        "all_series_would_take_gib": round(n * 4000 * 20 * 8 / 2**30, 1),
    }
    return figures


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("what", nargs="?", choices=("sweep", "mc", "both"), default="both")
    parser.add_argument("--configs", type=int, default=10)
    parser.add_argument("--seeds", type=int, default=1000)
    parser.add_argument("--sweep-chunk", type=int, default=50)
    parser.add_argument("-n", type=int, default=100_000)
    parser.add_argument("--mc-chunk", type=int, default=256)
    parser.add_argument("--json", action="store_true", help="print the figures as one JSON object")
    args = parser.parse_args()
    figures = {}
    with tempfile.TemporaryDirectory() as tmp:
        if args.what in ("sweep", "both"):
            figures["sweep"] = load_sweep(Path(tmp), configs=args.configs, seeds=args.seeds, chunk=args.sweep_chunk)
        if args.what in ("mc", "both"):
            figures["mc"] = load_mc(Path(tmp), n=args.n, chunk=args.mc_chunk)
    if args.json:
        print(json.dumps(figures, indent=2))
        return 0
    if "sweep" in figures:
        f = figures["sweep"]
        print(
            f"sweep: {f['runs']} runs of 2 s in {f['tasks']} tasks, 2 workers: {f['wall_s']} s; "
            f"{f['rows']} rows, {f['distinct_keys']} distinct keys, {f['records']} records, {f['ok']} ok"
        )
        print(
            f"  peak memory: driver {f['driver_peak_mib']} MiB, workers {f['worker_peak_mib']} MiB, "
            f"whole tree {f['tree_peak_rss_mib']} MiB"
        )
    if "mc" in figures:
        f = figures["mc"]
        print(
            f"mc: {f['runs']} runs of 40 s (4000 periods) in chunks of {f['chunk']}: {f['wall_s']} s "
            f"({f['robot_steps_per_s'] / 1e6:.2f} M robot-steps/s); {f['rows']} rows, {f['distinct_seeds']} seeds, "
            f"{f['ok']} ok"
        )
        print(
            f"  peak memory: {f['driver_peak_mib']} MiB (every series held would take "
            f"{f['all_series_would_take_gib']} GiB)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
