"""Batch throughput: robot control steps per second of a vmapped batch, at several batch sizes.

    python bench/batch.py [--json] [--sizes 64,256,1024] [--repeats 2] [--devices N] [--series]

The paper's line case (4000 control periods of 10 RK4 substeps), backstepping and NN-adaptive backstepping.
What is timed is ``studies.batches.batch_metrics``, the path of ``ddtrack mc`` and ``ddtrack sweep``: the vmapped
simulation keeping only the series the metrics read, then the metrics. ``--series`` times ``simulate_batch``
instead, which records every time series. The NN runs skip identification (``controller.identification=false``):
this measures the control loop itself, emulator training and gain law included. ``--devices N`` gives JAX N CPU
devices (default: one per core, as the ``ddtrack`` command does), over which the batch is split.
Compile is excluded (one warm-up call per batch size); the figure is the best of ``repeats`` timed calls.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from datetime import UTC, datetime
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
KINDS = {"backstepping": [], "nn_adaptive_backstepping": ["controller.identification=false"]}


def throughput(kind: str, size: int, repeats: int, series: bool = False) -> dict:
    """Robot control steps per second of one batch of ``size`` paper line-case runs of controller ``kind``."""
    import jax

    import ddtrack

    ddtrack.enable_float64()
    from ddtrack.runner import prepare_batch, run_setup
    from ddtrack.studies.batches import batch_metrics

    scenario = ddtrack.load_scenario(ROOT / "scenarios" / "paper_line.toml", overrides=KINDS[kind], controller=kind)
    setup, draws = prepare_batch(scenario, list(range(size)))

    def call():
        if series:
            jax.block_until_ready(run_setup(scenario, setup, draws, batched=True))
        else:
            batch_metrics(scenario, setup, draws)

    start = time.perf_counter()
    call()
    compile_s = time.perf_counter() - start
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    best = min(times)
    return {
        "controller": kind,
        "batch": size,
        "series": series,
        "compile_and_first_s": compile_s,
        "best_s": best,
        "robot_steps_per_s": size * scenario.simulation.n_steps / best,
    }


def best_throughput(sizes: list[int], repeats: int, series: bool = False) -> dict:
    """Every (controller, size) row, and the best size per controller."""
    rows = [throughput(kind, size, repeats, series) for kind in KINDS for size in sizes]
    best = {
        kind: max((r for r in rows if r["controller"] == kind), key=lambda r: r["robot_steps_per_s"]) for kind in KINDS
    }
    return {"rows": rows, "best": best}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--sizes", default="64,256,1024")
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--devices", type=int, default=len(os.sched_getaffinity(0)))
    parser.add_argument("--series", action="store_true", help="time simulate_batch with every series recorded")
    args = parser.parse_args()
    import jax

    jax.config.update("jax_num_cpu_devices", args.devices)  # before JAX's first operation
    report = {
        "date": datetime.now(UTC).isoformat(timespec="seconds"),
        "python": platform.python_version(),
        "jax": jax.__version__,
        "cores": len(os.sched_getaffinity(0)),
        "devices": len(jax.devices()),
        "load_average_start": list(os.getloadavg()),
    }
    report |= best_throughput([int(s) for s in args.sizes.split(",")], args.repeats, args.series)
    report["load_average_end"] = list(os.getloadavg())
    if args.json:
        print(json.dumps(report, indent=2))
        return
    for r in report["rows"]:
        print(
            f"{r['controller']:<26} batch {r['batch']:>5}: {r['best_s']:7.3f} s, "
            f"{r['robot_steps_per_s'] / 1e6:6.2f} M robot-steps/s (compile+first {r['compile_and_first_s']:.1f} s)"
        )


if __name__ == "__main__":
    main()
