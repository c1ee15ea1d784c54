"""Batch throughput: robot control steps per second of ``simulate_batch`` at several batch sizes.

    python bench/batch.py [--json] [--sizes 10,100,400,1000] [--repeats 3]

The paper's line case (4000 control periods of 10 RK4 substeps), backstepping and NN-adaptive backstepping.
The NN runs skip identification (``controller.identification=false``): this measures the control loop
itself, emulator training and gain law included; identification is a separate, one-off cost per run.
Compile is excluded (one warm-up call per batch size); the figure is the best of ``repeats`` timed calls.
"""
from __future__ import annotations

import argparse
import json
import platform
import time
from datetime import datetime, timezone
from pathlib import Path

import jax

import ddtrack
from ddtrack.model import DynamicPlant
from ddtrack.runner import prepare_batch
from ddtrack.sim import simulate_batch

ROOT = Path(__file__).resolve().parents[1]
KINDS = {"backstepping": [], "nn_adaptive_backstepping": ["controller.identification=false"]}


def throughput(kind: str, overrides: list[str], size: int, repeats: int) -> dict:
    scenario = ddtrack.load_scenario(ROOT / "scenarios" / "paper_line.toml", overrides=overrides, controller=kind)
    setup, draws = prepare_batch(scenario, list(range(size)))
    sim = scenario.simulation

    def call():
        result = simulate_batch(DynamicPlant(setup.plant_params), setup.controller, setup.trajectory, setup.x0, draws,
                                setup.disturbance, setup.noise, n_steps=sim.n_steps,
                                control_period=sim.control_period, substeps=sim.substeps,
                                divergence_error=sim.divergence_error)
        jax.block_until_ready(result)

    start = time.perf_counter()
    call()
    compile_s = time.perf_counter() - start
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    best = min(times)
    return {"controller": kind, "batch": size, "compile_and_first_s": compile_s, "best_s": best,
            "robot_steps_per_s": size * sim.n_steps / best}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--sizes", default="10,100,400,1000")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    rows = [throughput(kind, overrides, int(size), args.repeats)
            for kind, overrides in KINDS.items() for size in args.sizes.split(",")]
    report = {"date": datetime.now(timezone.utc).isoformat(timespec="seconds"), "python": platform.python_version(),
              "jax": jax.__version__, "cores": len(__import__("os").sched_getaffinity(0)), "rows": rows,
              "best": {kind: max((r for r in rows if r["controller"] == kind), key=lambda r: r["robot_steps_per_s"])
                       for kind in KINDS}}
    if args.json:
        print(json.dumps(report, indent=2))
        return
    for r in rows:
        print(f"{r['controller']:<26} batch {r['batch']:>5}: {r['best_s']:7.3f} s, "
              f"{r['robot_steps_per_s'] / 1e6:6.2f} M robot-steps/s (compile+first {r['compile_and_first_s']:.1f} s)")


if __name__ == "__main__":
    main()
