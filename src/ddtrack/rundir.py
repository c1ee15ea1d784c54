"""The run folder (docs/guide.md): ``scenario.toml``, ``timeseries.parquet``, ``metrics.json``, ``figures/``.

Every file is written under a temporary name in the same folder and renamed into place, so the
folder never holds a half-written file.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from functools import partial
from pathlib import Path
from typing import IO

import matplotlib.pyplot as plt
import numpy as np
import numpy.typing as npt
import pyarrow as pa
import pyarrow.parquet as pq
import tomli_w

from .outdir import atomic_write
from .plotting import plot_errors, plot_gains, plot_path, plot_states, plot_torques
from .scenario import Scenario, to_toml_dict
from .studies.recorded import driven_by


def float64_array(values: npt.ArrayLike) -> pa.Array:
    """A float64 Arrow array over the values' buffer.

    ``pa.array`` would import pandas (0.25 s) only to check whether the values are a Series.
    """
    values = np.ascontiguousarray(values, dtype=np.float64)
    return pa.Array.from_buffers(pa.float64(), len(values), [None, pa.py_buffer(values)])


def write_run(
    folder: Path,
    scenario: Scenario,
    columns: Mapping[str, np.ndarray],
    metrics: dict,
    identification: dict | None = None,
) -> list[Path]:
    """Write a run folder; return the paths written. ``identification`` (the NN emulator's pre-training:
    loss per epoch, prediction NMSE) goes to ``identification.json``."""
    folder = Path(folder)
    written = []

    def put(name: str, write: Callable[[IO[bytes]], object]) -> None:
        atomic_write(folder / name, write)
        written.append(folder / name)

    put("scenario.toml", lambda f: f.write(tomli_w.dumps(to_toml_dict(scenario)).encode()))
    table = pa.table({name: float64_array(values) for name, values in columns.items()})
    put("timeseries.parquet", lambda f: pq.write_table(table, f))
    put("metrics.json", lambda f: f.write((json.dumps(metrics, indent=2, allow_nan=False) + "\n").encode()))
    if identification is not None:
        put(
            "identification.json",
            lambda f: f.write((json.dumps(identification, indent=2, allow_nan=False) + "\n").encode()),
        )
    window = tuple(metrics["window"])
    driver, _ = driven_by(metrics, scenario.controller.kind)  # a live robot's driver, not the scenario's controller
    title = f"{scenario.name}: {driver} on {scenario.trajectory.kind}"
    figures = {
        "path.png": plot_path(columns, title=title),
        "states.png": plot_states(columns, title=title),
        "errors.png": plot_errors(columns, window=window, title=title),
    }
    if not np.all(np.isnan(columns["tau_r"])):  # a velocity-input (kinematic) plant has no torques to show
        figures["torques.png"] = plot_torques(columns, max_torque=scenario.plant_params().max_torque, title=title)
    if any(name in columns and np.ptp(columns[name]) > 0 for name in ("kx", "ky", "ktheta")):
        figures["gains.png"] = plot_gains(columns, title=title)  # gains that moved (the paper's Figs. 13 and 17)
    for name, fig in figures.items():
        put(f"figures/{name}", partial(fig.savefig, format="png", dpi=110))
        plt.close(fig)
    return written
