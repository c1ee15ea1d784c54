"""Load a run's time series with pandas: ``ddtrack run`` into a temporary folder, then read its Parquet file.

``timeseries.parquet`` has one row per control period (t, the pose and velocities, the reference, the errors,
the commands, the wheel torques, the gains and any other logged scalar; docs/guide.md lists them), and
``metrics.json`` the run's statistics. The same works on any run folder, e.g. ``runs/paper_line``.

    python examples/load_parquet.py [SCENARIO] [--set SECTION.KEY=VALUE ...]
"""
import json
import sys
import tempfile
from pathlib import Path

import pandas as pd

from ddtrack.cli import main

args = sys.argv[1:]
if not args or args[0].startswith("--"):  # no scenario given: the paper's straight-line case
    args = [str(Path(__file__).resolve().parents[1] / "scenarios" / "paper_line.toml"), *args]
with tempfile.TemporaryDirectory() as tmp:
    folder = Path(tmp) / "run"
    if main(["run", *args, "--out", str(folder)]) != 0:  # prints the run's summary; 1: diverged, 2: bad input
        sys.exit("the run failed")
    series = pd.read_parquet(folder / "timeseries.parquet").set_index("t")
    metrics = json.loads((folder / "metrics.json").read_text())

print(f"\n{len(series)} rows x {series.shape[1]} columns, t = {series.index[0]:g} .. {series.index[-1]:g} s")
print(series[["x", "y", "v", "e_tr", "tau_r", "tau_l"]].describe().loc[["mean", "min", "max"]].round(4).to_string())
settled = series.index[series["e_tr"] < 0.1]  # first time the robot came within 10 cm of its reference
print(f"first within 0.1 m at t = {settled[0]:.2f} s" if len(settled) else "never within 0.1 m")
peak = series[["tau_r", "tau_l"]].abs().max()
print(f"peak |torque|: right {peak['tau_r']:.2f} N m, left {peak['tau_l']:.2f} N m; "
      f"e_tr_mean {metrics['e_tr_mean']:.4f} m over {metrics['window']} s")
