"""Nothing lost: a sweep whose driver is SIGKILLed at random moments, again and again, then resumed.

    python bench/kill_resume.py [--kills 20] [--seed 0] [--masses 10] [--seeds 40] [--chunk 10] [--json]

The sweep: figure_eight (Gaussian disturbance and noise, so every seed differs) shortened to 10 s, a
``robot.mass`` grid of MASSES values x SEEDS seeds, CHUNK runs per task, on the embedded 2-worker cluster.

1. It runs once, uninterrupted, into ``reference/`` (this also fills JAX's compilation cache), then once more,
   timed, while the records are counted: when the first and the last record landed.
2. The same sweep runs as a real ``ddtrack sweep`` process into a fresh store, SIGKILLed after a random delay
   (``random.Random(SEED)``, uniform between 0.2 s and 1 s past the timed run's last record: kills land while
   the cluster starts, while records are written, and while the tables are written), and started again, which
   resumes; until a start finishes before its kill. That store is then compared with the reference, and the
   next cycle starts from an empty store, until KILLS kills have been survived. After each kill the driver's
   worker processes must exit by themselves (distributed's parent-alive pipe); any that does not within 20 s
   is counted as an orphan and killed.
3. Each finished store is compared with the reference: the same set of keys, record by record equal (records
   hold no wall-clock field: key, configuration, seed, status, metrics, error), no temporary or partial file
   left, no key twice in ``results.parquet``, and the two ``results.parquet`` tables equal.

Prints kills survived, records lost, duplicated, differing; exit code 0 when all are zero.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil
import pyarrow.parquet as pq

ROOT = Path(__file__).resolve().parents[1]
PYTHON = sys.executable


def sweep_file(folder: Path, *, masses: int, seeds: int, chunk: int, duration: float) -> Path:
    grid = [round(8.0 + 4.0 * i / max(masses - 1, 1), 6) for i in range(masses)]
    path = folder / "sweep.toml"
    path.write_text(
        f'scenario = "{ROOT / "scenarios" / "figure_eight.toml"}"\ncontrollers = ["backstepping"]\n'
        f'seeds = {seeds}\nchunk = {chunk}\n[set]\n"simulation.duration" = {duration!r}\n'
        f'"simulation.metric_window" = [0.0, {duration!r}]\n[grid]\n"robot.mass" = {grid}\n'
    )
    return path


def command(path: Path, out: Path) -> list[str]:
    return [PYTHON, "-m", "ddtrack", "sweep", str(path), "--out", str(out), "--workers", "2"]


def records(out: Path) -> dict[str, dict]:
    """Every file in ``out/records`` read as JSON, by file stem (a partial file would fail here)."""
    return {p.stem: json.loads(p.read_text()) for p in sorted((out / "records").glob("*.json"))}


def kill_family(proc: subprocess.Popen) -> int:
    """SIGKILL the driver alone, as a crash would; wait for its workers to exit by themselves. Returns the
    number of orphan workers (killed here) that outlived it by 20 s."""
    try:
        family = psutil.Process(proc.pid).children(recursive=True)
    except psutil.NoSuchProcess:
        family = []
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)
    _, alive = psutil.wait_procs(family, timeout=20)
    for child in alive:
        try:
            child.kill()
        except psutil.NoSuchProcess:
            pass
    return len(alive)


def compare(reference: Path, out: Path) -> dict:
    """What ``out`` lost, gained, duplicated or changed against ``reference``."""
    want, got = records(reference), records(out)
    leftovers = [p.name for p in (out / "records").iterdir() if p.suffix != ".json" or p.name.startswith(".")]
    leftovers += [p.name for p in out.iterdir() if p.name.startswith(".")]
    result = pq.read_table(out / "results.parquet")
    keys = result.column("key").to_pylist()
    return {
        "lost": len(set(want) - set(got)),
        "extra": len(set(got) - set(want)),
        "duplicated": len(keys) - len(set(keys)),
        "differing": sum(want[k] != got[k] for k in set(want) & set(got)),
        "leftovers": sorted(leftovers),
        "tables_equal": result.equals(pq.read_table(reference / "results.parquet")),
    }


def timed(path: Path, out: Path) -> tuple[float, float, float]:
    """Run the sweep uninterrupted; return (wall time, time of the first record, time of the last) [s]."""
    start = time.perf_counter()
    proc = subprocess.Popen(command(path, out), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    first = last = None
    count = 0
    while proc.poll() is None:
        found = len(list((out / "records").glob("*.json"))) if (out / "records").is_dir() else 0
        now = time.perf_counter() - start
        if found and first is None:
            first = now
        if found > count:
            count, last = found, now
        time.sleep(0.05)
    if proc.returncode != 0:
        sys.exit(f"the uninterrupted sweep failed:\n{proc.stderr.read().decode()}")
    return time.perf_counter() - start, first or 0.0, last or 0.0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kills", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--masses", type=int, default=10)
    parser.add_argument("--seeds", type=int, default=40)
    parser.add_argument("--chunk", type=int, default=10)
    parser.add_argument("--duration", type=float, default=10.0, help="simulated seconds per run")
    parser.add_argument("--json", action="store_true", help="print the figures as one JSON object")
    args = parser.parse_args()
    rng = random.Random(args.seed)

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        path = sweep_file(folder, masses=args.masses, seeds=args.seeds, chunk=args.chunk, duration=args.duration)
        total = args.masses * args.seeds
        reference = folder / "reference"
        timed(path, reference)  # fills the compilation cache
        wall, first, last = timed(path, folder / "again")
        again = compare(reference, folder / "again")

        kills, orphans, cycles, starts = 0, 0, [], 0
        totals = {"lost": 0, "extra": 0, "duplicated": 0, "differing": 0, "leftovers": [], "tables_equal": True}
        start = time.perf_counter()
        while kills < args.kills:
            out = folder / f"cycle{len(cycles)}"
            progress = []
            while True:
                delay = rng.uniform(0.2, last + 1.0) if kills < args.kills else math.inf
                starts += 1
                proc = subprocess.Popen(command(path, out), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
                try:
                    proc.wait(timeout=None if math.isinf(delay) else delay)
                except subprocess.TimeoutExpired:
                    orphans += kill_family(proc)
                    kills += 1
                    done = len(list((out / "records").glob("*.json"))) if (out / "records").is_dir() else 0
                    progress.append(done)
                    print(f"kill {kills:2d} after {delay:5.2f} s: {done}/{total} records", file=sys.stderr)
                    continue
                if proc.returncode != 0:
                    sys.exit(f"a resumed sweep failed:\n{proc.stderr.read().decode()}")
                break
            found = compare(reference, out)
            print(f"cycle {len(cycles)}: finished after {len(progress)} kills: {found}", file=sys.stderr)
            cycles.append({"records_at_each_kill": progress} | found)
            for name in ("lost", "extra", "duplicated", "differing"):
                totals[name] += found[name]
            totals["leftovers"] += found["leftovers"]
            totals["tables_equal"] &= found["tables_equal"]
        killed_wall = time.perf_counter() - start

    figures = (
        {
            "runs": total,
            "tasks": args.masses * -(-args.seeds // args.chunk),
            "seed": args.seed,
            "uninterrupted_s": round(wall, 1),
            "first_record_s": round(first, 1),
            "last_record_s": round(last, 1),
            "uninterrupted_twice_equal": again["differing"] == again["lost"] == 0 and again["tables_equal"],
            "kills": kills,
            "starts": starts,
            "cycles": len(cycles),
            "orphan_workers": orphans,
            "kills_with_records_partly_written": sum(0 < n < total for c in cycles for n in c["records_at_each_kill"]),
            "killed_and_resumed_s": round(killed_wall, 1),
        }
        | totals
        | {"per_cycle": cycles}
    )
    if args.json:
        print(json.dumps(figures, indent=2))
    else:
        print(
            f"{total} runs in {figures['tasks']} tasks; uninterrupted {figures['uninterrupted_s']} s "
            f"(records from {first:.1f} s to {last:.1f} s); killed and resumed: {killed_wall:.0f} s"
        )
        print(
            f"kills survived: {kills} in {len(cycles)} cycles, {starts} starts "
            f"({figures['kills_with_records_partly_written']} with the store part-written); "
            f"orphan workers: {orphans}"
        )
        for i, cycle in enumerate(cycles):
            print(f"  cycle {i}: records at each kill {cycle['records_at_each_kill']}")
        print(
            f"records lost: {totals['lost']}, extra: {totals['extra']}, duplicated: {totals['duplicated']}, "
            f"differing: {totals['differing']}; leftover files: {totals['leftovers'] or 'none'}; "
            f"results tables equal: {totals['tables_equal']}"
        )
    ok = (
        totals["lost"] == totals["extra"] == totals["duplicated"] == totals["differing"] == orphans == 0
        and not totals["leftovers"]
        and totals["tables_equal"]
    )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
