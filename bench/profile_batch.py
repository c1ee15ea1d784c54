"""Where a batched robot control step spends its time (the profile behind docs/benchmarks.md).

    python bench/profile_batch.py [--json] [--batch 1024]

On one CPU device, per robot control step of the paper's line case (10 RK4 substeps, so 40 plant evaluations):

* ``plant_only_ns``: the plant alone, integrated under a constant torque (no controller, nothing recorded);
* ``full_step_ns`` / ``metrics_step_ns``: the whole closed loop of ``simulate_batch`` (every series recorded) and of
  ``studies.batches.batch_metrics`` (only what the metrics read), backstepping;
* ``<op>_ns``: one float64 (and float32) elementwise transcendental on a batch, per element, in a ``fori_loop``,
  against a multiply-add: the plant needs a sine, a cosine and two tanh per evaluation.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp

import ddtrack
from ddtrack.runner import prepare_batch, run_setup
from ddtrack.sim import rk4
from ddtrack.studies.batches import batch_metrics

ddtrack.enable_float64()  # ddtrack computes in float64: once, before any JAX array

ROOT = Path(__file__).resolve().parents[1]


def best_time(fn, repeats: int = 3) -> float:
    jax.block_until_ready(fn())  # compile
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - start)
    return min(times)


def elementwise_ns(op, dtype, size: int, iterations: int = 2000) -> float:
    """Nanoseconds per element of ``op`` applied in a loop to a batch of ``size`` values."""
    x = jnp.linspace(0.1, 1.0, size).astype(dtype)
    loop = jax.jit(lambda x: jax.lax.fori_loop(0, iterations, lambda i, x: op(x), x))
    return 1e9 * best_time(lambda: loop(x)) / (iterations * size)


def profile(size: int) -> dict:
    scenario = ddtrack.load_scenario(ROOT / "scenarios" / "paper_line.toml")
    sim = scenario.simulation
    setup, draws = prepare_batch(scenario, list(range(size)))
    per_step = 1e9 / (size * sim.n_steps)

    def plant_only(plant, x0):
        torque, disturbance = jnp.array([0.5, 0.5]), jnp.zeros(2)

        def period(x, _):
            return rk4(
                lambda z: plant.derivative(z, torque, disturbance),
                plant.hold(x, torque),
                sim.control_period,
                sim.substeps,
            ), None

        return jax.lax.scan(period, x0, None, length=sim.n_steps, unroll=4)[0]

    plants = jax.jit(jax.vmap(plant_only))
    figures = {
        "batch": size,
        "plant_only_ns": per_step * best_time(lambda: plants(setup.plant, setup.x0)),
        "full_step_ns": per_step * best_time(lambda: run_setup(scenario, setup, draws, batched=True)),
        "metrics_step_ns": per_step * best_time(lambda: batch_metrics(scenario, setup, draws) and 0),
    }
    ops = {"multiply_add": lambda x: x * 0.999 + 0.001, "sin": jnp.sin, "cos": jnp.cos, "tanh": jnp.tanh}
    for name, op in ops.items():
        figures[f"{name}_ns"] = elementwise_ns(op, jnp.float64, size)
        figures[f"{name}_f32_ns"] = elementwise_ns(op, jnp.float32, size)
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--batch", type=int, default=1024)
    args = parser.parse_args()
    figures = profile(args.batch)
    if args.json:
        print(json.dumps(figures, indent=2))
        return
    for key, value in figures.items():
        print(f"{key:<22} {value:10.2f}")


if __name__ == "__main__":
    main()
