"""Throughput of the slip plant against the no-slip plants: a batch of runs, same robot, same controller.

    python bench/slip_throughput.py [--json] [--batch 256] [--duration 10] [--repeats 2]

Cases (backstepping, or kinematic backstepping where named, at 10 ms, ``simulation.substeps = 10``; the no-slip plants
with the same wheel inertia):

* ``turtlebot3_burger``: the circle of ``scenarios/burger_sized_20hz.toml`` on the preset with its motors;
  ``motor_torque`` (no slip, motors through the current driver) and ``dynamic`` against ``slip`` (RK4, its sub-steps
  chosen from the contact stiffness);
* ``paper_geared``: the paper's line case (``scenarios/paper_line.toml``) with J_w = 0.005 kg m^2; ``dynamic``
  against ``slip`` (RK4);
* ``paper_light_wheel``: the same with a 0.1 kg wheel, J_w = 1.25e-4 kg m^2; ``dynamic`` against ``slip`` (the
  Rosenbrock step);
* ``turtlebot3_burger_cmd_vel``: the Burger's circle under kinematic backstepping over its PI wheel-speed loop,
  ``motor_velocity`` (no slip) against ``slip_velocity``.

What is timed is ``studies.batches.batch_metrics`` (the path of ``ddtrack mc``), compile excluded (one warm-up
call), best of ``repeats``. Prints robot control steps per second and the ratio slip / no-slip.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
COMMON = ["simulation.control_period=0.01", "simulation.substeps=10"]
BURGER = ['robot.preset="turtlebot3_burger"', "plant.com_offset=-0.01"]
#: case: (scenario file, overrides, slip model, no-slip models, controller)
CASES = {
    "turtlebot3_burger": ("burger_sized_20hz.toml", BURGER, "slip", ("motor_torque", "dynamic"), "backstepping"),
    "paper_geared": ("paper_line.toml", ["plant.wheel_inertia=0.005"], "slip", ("dynamic",), "backstepping"),
    "paper_light_wheel": ("paper_line.toml", ["plant.wheel_inertia=0.000125"], "slip", ("dynamic",), "backstepping"),
    "turtlebot3_burger_cmd_vel": (
        "burger_sized_20hz.toml",
        BURGER,
        "slip_velocity",
        ("motor_velocity",),
        "kinematic_backstepping",
    ),
}


def throughput(
    file: str, overrides: list[str], model: str, controller: str, batch: int, duration: float, repeats: int
) -> dict:
    """Robot control steps per second of ``batch`` runs of scenario ``file`` on plant ``model``."""
    import ddtrack

    ddtrack.enable_float64()
    from ddtrack.runner import prepare_batch
    from ddtrack.studies.batches import batch_metrics

    sets = [*COMMON, *overrides, f"plant.model={model}", f"simulation.duration={duration}"]
    sets.append(f"simulation.metric_window=[0, {duration}]")
    scenario = ddtrack.load_scenario(ROOT / "scenarios" / file, overrides=sets, controller=controller)
    setup, draws = prepare_batch(scenario, list(range(batch)))
    plant = setup.plant
    start = time.perf_counter()
    metrics = batch_metrics(scenario, setup, draws)
    compile_s = time.perf_counter() - start
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        batch_metrics(scenario, setup, draws)
        times.append(time.perf_counter() - start)
    best = min(times)
    return {
        "model": model,
        "scheme": getattr(plant, "scheme", "rk4"),
        "substeps": max(scenario.simulation.substeps, getattr(plant, "substeps", 0)),
        "compile_and_first_s": compile_s,
        "best_s": best,
        "robot_steps_per_s": batch * scenario.simulation.n_steps / best,
        "e_tr_mean": float(sum(m["e_tr_mean"] for m in metrics) / len(metrics)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--batch", type=int, default=256)
    parser.add_argument("--duration", type=float, default=10.0)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--cases", default=",".join(CASES))
    args = parser.parse_args()
    report: dict = {"machine": {"cpus": len(os.sched_getaffinity(0)), "processor": platform.processor()}}
    for case in args.cases.split(","):
        file, overrides, slip_model, references, controller = CASES[case]
        slip = throughput(file, overrides, slip_model, controller, args.batch, args.duration, args.repeats)
        rows = {slip_model: slip}
        for model in references:
            rows[model] = throughput(file, overrides, model, controller, args.batch, args.duration, args.repeats)
            rows[model]["slip_ratio"] = slip["robot_steps_per_s"] / rows[model]["robot_steps_per_s"]
        report[case] = rows
        if not args.json:
            for model, row in rows.items():
                ratio = f"  slip / this = {row['slip_ratio']:.2f}" if "slip_ratio" in row else ""
                print(
                    f"{case:18s} {model:13s} {row['scheme']:10s} {row['substeps']:3d} sub-steps  "
                    f"{row['robot_steps_per_s']:12.0f} steps/s  (e_tr mean {row['e_tr_mean']:.4f} m){ratio}",
                    flush=True,
                )
    if args.json:
        print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
