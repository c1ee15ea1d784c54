"""Does the NN-adaptive controller work on small and large robots, at usual control rates?

For a TurtleBot3 Burger-like robot (1 kg), a 3 kg robot and the paper's 10 kg robot, at 10, 20, 50 and
100 Hz, run backstepping and NN-adaptive backstepping on the same seeds (the true mass drawn within
+-20 % per seed, and each seed its own identification run) and print the mean tracking error over the
metric window of each, the paired improvement of the NN-adaptive controller, and the emulator's worst
identification NMSE. Each robot tracks a circle at about 0.7 of its speed clamp, starting 20 % of the
radius outside it.

    python bench/nn_scaling.py [--seeds 3] [--rates 10,20,50,100] [--robots burger,3kg,10kg]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from ddtrack import enable_float64
from ddtrack.metrics import improvement
from ddtrack.runner import enable_compilation_cache, prepare_batch
from ddtrack.scenario import load_scenario
from ddtrack.studies.batches import batch_metrics

BASE = Path(__file__).resolve().parent.parent / "scenarios" / "burger_sized_20hz.toml"


def _circle(radius: float, speed: float) -> list[str]:
    return [f"trajectory.radius={radius}", f"trajectory.speed={speed}", f"initial.pose=[0.0, {-1.2 * radius}, 0.0]"]


#: Overrides of scenarios/burger_sized_20hz.toml per robot: [robot], [plant] (+20 % mass, +25 % inertia), clamps,
#: circle.
ROBOTS = {
    "burger": _circle(0.5, 0.15),
    "3kg": [
        "robot.mass=3.0",
        "robot.inertia=0.03",
        "robot.wheel_radius=0.05",
        "robot.half_axle=0.12",
        "robot.max_torque=3.0",
        "plant.mass=3.6",
        "plant.inertia=0.0375",
        "plant.com_offset=0.02",
        "plant.viscous_friction=0.001",
        "plant.coulomb_friction=0.01",
        "controller.max_velocity=0.5",
        "controller.max_yaw_rate=3.0",
        *_circle(1.0, 0.35),
    ],
    "10kg": [
        "robot.mass=10.0",
        "robot.inertia=0.56",
        "robot.com_offset=0.05",
        "robot.wheel_radius=0.05",
        "robot.half_axle=0.25",
        "robot.max_torque=10.0",
        "plant.mass=12.0",
        "plant.inertia=0.70",
        "plant.com_offset=0.08",
        "plant.viscous_friction=0.005",
        "plant.coulomb_friction=0.05",
        "controller.max_velocity=2.0",
        "controller.max_yaw_rate=4.0",
        *_circle(3.0, 0.5),
    ],
}
MASS_SPREAD = 'randomize.mass={distribution="uniform", relative=0.2}'


def measure(robot: str, rate: float, seeds: list[int]) -> dict:
    """Per-seed e_tr means of both controllers and the emulator's worst NMSE, for one robot and rate."""
    period = 1.0 / rate
    overrides = [
        *ROBOTS[robot],
        MASS_SPREAD,
        f"simulation.control_period={period!r}",
        f"simulation.substeps={max(1, round(period / 1e-3))}",
    ]
    found = {}
    for kind in ("backstepping", "nn_adaptive_backstepping"):
        spec = load_scenario(BASE, overrides=overrides, controller=kind)
        setup, draws = prepare_batch(spec, seeds)
        found[kind] = [m["e_tr_mean"] for m in batch_metrics(spec, setup, draws)]
        if setup.identification is not None:
            found["nmse"] = float(np.max(np.asarray(setup.identification.nmse)))
    paired = [improvement(b, n) for b, n in zip(found["backstepping"], found["nn_adaptive_backstepping"], strict=True)]
    return {
        "bs": float(np.mean(found["backstepping"])),
        "nn": float(np.mean(found["nn_adaptive_backstepping"])),
        "improvement": float(np.mean(paired)),
        "worst": float(np.min(paired)),
        "nmse": found["nmse"],
    }


def main() -> None:
    enable_float64()
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--rates", default="10,20,50,100", help="control rates [Hz], comma-separated")
    parser.add_argument("--robots", default=",".join(ROBOTS))
    args = parser.parse_args()
    enable_compilation_cache()
    seeds = list(range(args.seeds))
    print(
        f"{args.seeds} seeds; e_tr = mean tracking error over the metric window [20, 60] s; improvement = "
        "mean over seeds of 100 (1 - e_NN / e_BS) %, worst seed in brackets\n"
    )
    print("| robot | rate | backstepping e_tr [m] | NN-adaptive e_tr [m] | improvement (worst seed) | worst NMSE |")
    print("|---|---|---|---|---|---|")
    for robot in args.robots.split(","):
        for rate in (float(r) for r in args.rates.split(",")):
            start = time.perf_counter()
            r = measure(robot, rate, seeds)
            print(
                f"| {robot} | {rate:g} Hz | {r['bs']:.3g} | {r['nn']:.3g} | {r['improvement']:.0f} % "
                f"({r['worst']:.0f} %) | {r['nmse']:.2g} |",
                flush=True,
            )
            print(f"<!-- {time.perf_counter() - start:.0f} s -->", flush=True)


if __name__ == "__main__":
    main()
