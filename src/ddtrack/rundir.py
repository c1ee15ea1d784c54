"""The run folder (DESIGN 4): ``scenario.toml``, ``timeseries.parquet``, ``metrics.json``, ``figures/``.

Every file is written under a temporary name in the same folder and renamed into place, so the
folder never holds a half-written file.
"""
from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import IO

import matplotlib.pyplot as plt
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import tomli_w

from .errors import RunError
from .plotting import plot_errors, plot_gains, plot_path, plot_states, plot_torques
from .scenario import Scenario, to_toml_dict


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write(path: Path, write: Callable[[IO[bytes]], None]) -> None:
    """Write ``path`` through ``write(file)`` on a temporary sibling, then rename it into place.

    A write that fails midway (a full disk, a folder that went read-only) removes its temporary and
    raises :class:`RunError` naming ``path`` and the cause (``No space left on device``): the folder
    keeps only the files that were whole before, and the command line prints one line, exit code 2.
    """
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise RunError(f"cannot write '{path}' ({exc.strerror or exc})") from exc
    try:
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp's 0600 would hide results from the user's group
        with os.fdopen(fd, "wb") as file:
            write(file)
            file.flush()
            os.fsync(file.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        Path(tmp).unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise RunError(f"cannot write '{path}' ({exc.strerror or exc}); "
                           "nothing partial was left: free some space or choose another --out") from exc
        raise


def check_writable(folder: Path) -> None:
    """Fail early, before any simulation, if ``folder`` cannot be created or written. Creates nothing: a
    command that fails later (an unreachable scheduler, a diverged case) leaves no empty folder behind."""
    existing = Path(folder).absolute()
    while not existing.exists():
        existing = existing.parent
    try:
        if not existing.is_dir():
            raise NotADirectoryError(20, "Not a directory", str(existing))
        with tempfile.TemporaryFile(dir=existing):
            pass
    except OSError as exc:
        raise RunError(f"output folder '{folder}' cannot be written ({exc.strerror or exc}); "
                       "choose another with --out") from None


def float64_array(values) -> pa.Array:
    """A float64 Arrow array over the values' buffer (``pa.array`` would import pandas, 0.25 s, to look for a Series)."""
    values = np.ascontiguousarray(values, dtype=np.float64)
    return pa.Array.from_buffers(pa.float64(), len(values), [None, pa.py_buffer(values)])


def write_run(folder: Path, scenario: Scenario, columns: Mapping[str, np.ndarray], metrics: dict,
              identification: dict | None = None) -> list[Path]:
    """Write a run folder; return the paths written. ``identification`` (the NN emulator's pre-training:
    loss per epoch, prediction NMSE) goes to ``identification.json``."""
    folder = Path(folder)
    written = []

    def put(name: str, write: Callable[[IO[bytes]], None]) -> None:
        atomic_write(folder / name, write)
        written.append(folder / name)

    put("scenario.toml", lambda f: f.write(tomli_w.dumps(to_toml_dict(scenario)).encode()))
    table = pa.table({name: float64_array(values) for name, values in columns.items()})
    put("timeseries.parquet", lambda f: pq.write_table(table, f))
    put("metrics.json", lambda f: f.write((json.dumps(metrics, indent=2, allow_nan=False) + "\n").encode()))
    if identification is not None:
        put("identification.json",
            lambda f: f.write((json.dumps(identification, indent=2, allow_nan=False) + "\n").encode()))
    window = tuple(metrics["window"])
    figures = {
        "path.png": plot_path(columns, title=scenario.name),
        "states.png": plot_states(columns),
        "errors.png": plot_errors(columns, window=window),
        "torques.png": plot_torques(columns, max_torque=scenario.plant_params().max_torque),
    }
    if any(name in columns and np.ptp(columns[name]) > 0 for name in ("kx", "ky", "ktheta")):
        figures["gains.png"] = plot_gains(columns)  # gains that moved (the paper's Figs. 13 and 17)
    for name, fig in figures.items():
        put(f"figures/{name}", lambda f, fig=fig: fig.savefig(f, format="png", dpi=110))
        plt.close(fig)
    return written
