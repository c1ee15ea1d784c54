"""Load a run's time series: ``ddtrack run`` into a temporary folder, then read its Parquet file with pyarrow.

``timeseries.parquet`` has one row per control period (t, the pose and velocities, the reference, the errors,
the commands, the wheel torques, the gains and any other logged scalar; docs/guide.md lists them), and
``metrics.json`` the run's statistics. The same works on any run folder, e.g. ``runs/paper_line``; with pandas
installed, ``pandas.read_parquet`` reads the same file.

    python examples/load_parquet.py [SCENARIO] [--set SECTION.KEY=VALUE ...]
"""

import json
import sys
import tempfile
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from ddtrack.cli import main

args = sys.argv[1:]
if not args or args[0].startswith("--"):  # no scenario given: the paper's straight-line case
    args = [str(Path(__file__).resolve().parents[1] / "scenarios" / "paper_line.toml"), *args]
with tempfile.TemporaryDirectory() as tmp:
    folder = Path(tmp) / "run"
    if main(["run", *args, "--out", str(folder)]) != 0:  # prints the run's summary; 1: diverged, 2: bad input
        sys.exit("the run failed")
    table = pq.read_table(folder / "timeseries.parquet")
    metrics = json.loads((folder / "metrics.json").read_text())

series = {name: table.column(name).to_numpy() for name in table.column_names}
t = series["t"]
print(f"\n{table.num_rows} rows x {table.num_columns} columns, t = {t[0]:g} .. {t[-1]:g} s")
for name in ("x", "y", "v", "e_tr", "tau_r", "tau_l"):
    values = series[name]
    print(f"{name:>6}: mean {values.mean():>9.4f}, min {values.min():>9.4f}, max {values.max():>9.4f}")
settled = t[series["e_tr"] < 0.1]  # first time the robot came within 10 cm of its reference
print(f"first within 0.1 m at t = {settled[0]:.2f} s" if len(settled) else "never within 0.1 m")
peak_r, peak_l = np.abs(series["tau_r"]).max(), np.abs(series["tau_l"]).max()
print(
    f"peak |torque|: right {peak_r:.2f} N m, left {peak_l:.2f} N m; "
    f"e_tr_mean {metrics['e_tr_mean']:.4f} m over {metrics['window']} s"
)
