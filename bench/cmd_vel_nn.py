"""The paper's NN-adaptive law over cmd_vel on a TurtleBot3 Burger (docs/benchmarks.md).

Runs ``scenarios/burger_cmd_vel_figure8.toml`` for kinematic backstepping, backstepping with ``inner = "none"`` and
the NN-adaptive law with ``inner = "none"`` on common seeds, with the scenario's latency and odometry (heading from
the gyro, as shipped, and from the wheels) and without them, and prints each one's mean e_tr over the metric window
per seed, the identification's NMSE and how the NN-adaptive gains moved::

    python bench/cmd_vel_nn.py            # --seeds 5
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

import ddtrack
from ddtrack import load_scenario
from ddtrack.runner import prepare_batch, run_setup
from ddtrack.studies.batches import batch_metrics

SCENARIO = Path(__file__).resolve().parents[1] / "scenarios" / "burger_cmd_vel_figure8.toml"
CASES = {
    "latency and odometry": [],
    "latency and odometry turning by the wheels": ["sensing.heading=encoders"],
    "neither": ["sensing.actuation_delay=0", "sensing.odometry=false", "sensing.encoder_counts=0"],
}
CONTROLLERS = {
    "kinematic_backstepping": ("kinematic_backstepping", []),
    "backstepping, inner none": ("backstepping", ["controller.inner=none"]),
    "nn_adaptive_backstepping, inner none": ("nn_adaptive_backstepping", ["controller.inner=none"]),
}


def measure(overrides: list[str], kind: str, seeds: list[int]) -> dict:
    """Mean e_tr per seed; for the NN-adaptive law, its identification's NMSE and its gains' path."""
    scenario = load_scenario(SCENARIO, overrides=overrides, controller=kind)
    setup, draws = prepare_batch(scenario, seeds)
    row: dict = {"e_tr_mean": [m["e_tr_mean"] for m in batch_metrics(scenario, setup, draws)]}
    if setup.identification is not None:
        gains = run_setup(scenario, setup, draws, batched=True).logs
        path = np.stack([np.asarray(gains[name]) for name in ("kx", "ky", "ktheta")], axis=-1)  # (runs, N, 3)
        row |= {
            "nmse_worst": float(np.max(setup.identification.nmse)),
            "gains_final_mean": path[:, -1].mean(axis=0).round(3).tolist(),
            "gains_range": [path.min(axis=(0, 1)).round(3).tolist(), path.max(axis=(0, 1)).round(3).tolist()],
        }
    row["mean"] = float(np.mean(row["e_tr_mean"]))
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    seeds = list(range(parser.parse_args().seeds))
    ddtrack.enable_float64()
    for case, overrides in CASES.items():
        for label, (kind, keys) in CONTROLLERS.items():
            print(f"{case} | {label} | {json.dumps(measure([*overrides, *keys], kind, seeds))}", flush=True)


if __name__ == "__main__":
    main()
