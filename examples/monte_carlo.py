"""Monte Carlo from Python: one scenario over many seeds, plant parameters drawn per run, summarised with NumPy.

Each seed draws the plant's mass (+-20 %) and viscous wheel friction (+-50 %) uniformly (the ``[randomize]``
section, here given as overrides) along with its disturbance and noise; ``ddtrack.monte_carlo`` runs the seeds
in vmapped batches and returns one row of metrics per run. The summary: the mean tracking error with its 95 %
confidence interval (``ddtrack.metrics.mean_ci``, inside [0, inf) for an error), and the error by friction tercile
(unmodelled friction is what makes backstepping lag its reference, docs/model.md §4.5).

    python examples/monte_carlo.py [--seeds N] [--scenario FILE]
"""

# test-args: --seeds 6
import argparse
from pathlib import Path

import numpy as np

import ddtrack
from ddtrack.metrics import mean_ci

ddtrack.enable_float64()  # ddtrack computes in float64: once, before any JAX array

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--seeds", type=int, default=32, help="runs, seeds 0 .. N-1")
parser.add_argument("--scenario", default=Path(__file__).resolve().parents[1] / "scenarios" / "paper_line.toml")
args = parser.parse_args()

draws = [
    'randomize.mass={distribution="uniform", relative=0.2}',
    'randomize.viscous_friction={distribution="uniform", relative=0.5}',
]
scenario = ddtrack.load_scenario(args.scenario, overrides=draws)
rows = ddtrack.monte_carlo(scenario, list(range(args.seeds)), chunk_size=16)  # chunks bound the memory

columns = ["plant_mass", "plant_viscous_friction", "e_tr_mean", "settling_time", "effort"]
print(f"{'':>8}" + "".join(f"{name:>24}" for name in columns))
for label, reduce in (("mean", np.mean), ("min", np.min), ("max", np.max)):
    values = [reduce([r[c] for r in rows if r[c] is not None]) for c in columns]
    print(f"{label:>8}" + "".join(f"{v:>24.5g}" for v in values))

ok = [r for r in rows if r["status"] == "ok"]
e = mean_ci([r["e_tr_mean"] for r in ok], domain="nonnegative")
print(
    f"\n{len(ok)} of {len(rows)} runs ok; e_tr_mean {e['mean']:.5f} m, 95 % CI [{e['ci_low']:.5f}, "
    f"{e['ci_high']:.5f}] m\n"
)
friction = np.array([r["plant_viscous_friction"] for r in ok])
errors = np.array([r["e_tr_mean"] for r in ok])
edges = np.quantile(friction, [1 / 3, 2 / 3])
tercile = np.searchsorted(edges, friction, side="right")  # 0, 1, 2
for index, name in enumerate(("low friction", "middle", "high friction")):
    chosen = errors[tercile == index]
    print(f"{name:<14} {len(chosen):>3} runs, mean e_tr {chosen.mean() if len(chosen) else float('nan'):.5f} m")
