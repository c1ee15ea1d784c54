"""Run folders as entries of ``ddtrack bench --scenario``: a run already made, ranked without being simulated again.

A run folder (``ddtrack run``'s, or ``ddtrack robot``'s, where a foreign controller drove a ddtrack plant over
``/cmd_vel``) holds one run: its resolved scenario (``scenario.toml``) and its metrics (``metrics.json``), scored
against the true pose. As a *recorded* entry it is that one run, at its scenario's ``simulation.seed``: the seed
from which the plant draw, disturbance and noise came, so it pairs with the bench's runs of that seed (common random
numbers). What drove it is the metrics' ``driven_by`` (``ddtrack robot`` writes it), else its scenario's controller.
A ``ddtrack drive`` folder is refused: its pose is what the robot's odometry reported, not the ground truth.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import ConfigError
from ..outdir import MARKER, read_marker
from ..scenario import Scenario, load_scenario

#: the warning code of a ``ddtrack drive`` folder (:data:`ddtrack.ros.measured.MEASURED_POSE`): its pose is the
#: odometry's, which bench refuses to rank
MEASURED = "measured_pose"
RUN_FILES = ("scenario.toml", "metrics.json")  #: what a run folder holds, besides its marker
_WRITERS = "give a folder written by `ddtrack run` or `ddtrack robot`"
#: how a ``ddtrack robot`` run ends before the scenario's end, and what it means
CUT_SHORT = {"stopped": "Ctrl-C or SIGTERM", "silent": "its driver stopped answering"}


@dataclass(frozen=True)
class RecordedRun:
    """A run folder's one run, as a ``bench --scenario`` entry takes it.

    Attributes
    ----------
    folder : Path
        The run folder.
    seed : int
        Its scenario's ``simulation.seed``: the bench's seed it pairs on.
    metrics : dict
        Its ``metrics.json``, as written.
    driver : str
        What drove it: ``COMMAND/MODE`` of its ``driven_by`` (e.g. ``ddtrack robot/lockstep``), else the
        scenario's controller kind.
    reproducible : bool
        False for a realtime run: the wall clock timed its commands, so no rerun gives the same bits.
    """

    folder: Path
    seed: int
    metrics: dict
    driver: str
    reproducible: bool


def _refused(folder: Path, why: str, hint: str = _WRITERS) -> ConfigError:
    """A run folder's problem, as ``--scenario``'s one line."""
    return ConfigError("--scenario", f"{folder}: {why}", hint)


def driven_by(metrics: Mapping[str, Any], controller_kind: str) -> tuple[str, bool]:
    """(what drove the run, whether it reproduces to the bit): ``driven_by``'s command and mode where the metrics
    have it (``ddtrack robot/lockstep``), else the scenario's ``controller_kind`` (a simulation, which reproduces);
    the label the bench's controller column, the run's figures and its report page give."""
    driver = metrics.get("driven_by")
    if not isinstance(driver, Mapping):
        return controller_kind, True
    mode = driver.get("mode")
    return f"{driver.get('command', 'unknown')}/{mode}", mode != "realtime"


def _read_metrics(folder: Path) -> dict:
    """``metrics.json`` of ``folder``, a JSON object with a ``status``."""
    try:
        metrics = json.loads((folder / "metrics.json").read_text())
    except (OSError, ValueError) as exc:
        raise _refused(folder, f"metrics.json cannot be read ({exc})") from None
    if not isinstance(metrics, dict) or not isinstance(metrics.get("status"), str):
        raise _refused(folder, "metrics.json has no status: not a run's metrics")
    return metrics


def _check_run_folder(folder: Path) -> None:
    """Refuse a folder ddtrack did not write, another command's folder, or one without a run's files."""
    if not (folder / MARKER).is_file():
        raise _refused(folder, f"ddtrack did not write this folder (no {MARKER})")
    command = (read_marker(folder) or {}).get("command")
    if command != "run":
        raise _refused(folder, f"a ddtrack {command} folder, not a run folder")
    for name in RUN_FILES:
        if not (folder / name).is_file():
            raise _refused(folder, f"no {name}: not a whole run folder")


def read_recorded(folder: Path) -> tuple[Scenario, RecordedRun]:
    """A run folder's scenario (validated) and its one run, or a :class:`ConfigError` naming ``--scenario``, the
    folder and why: not ddtrack's, not a run's, incomplete, or measured (``ddtrack drive``'s)."""
    _check_run_folder(folder)
    metrics = _read_metrics(folder)
    if any(isinstance(w, Mapping) and w.get("code") == MEASURED for w in metrics.get("warnings") or []):
        raise _refused(
            folder,
            "a ddtrack drive run: its e_tr is what the robot's odometry believed, not comparable with the true pose "
            "a simulation scores",
            "rank a `ddtrack robot` run instead: its plant knows the true pose",
        )
    driver = metrics.get("driven_by")
    driver = driver if isinstance(driver, Mapping) else {}
    if (cut := driver.get("ended")) in CUT_SHORT:  # its metrics cover part of the reference: no whole run's peer
        periods = driver.get("periods")
        raise _refused(
            folder,
            f"the run was cut short ({CUT_SHORT[cut]}, after {periods} periods): its metrics cover only part of the "
            "reference",
            "rank a run that went to the scenario's end",
        )
    try:
        scenario = load_scenario(folder / "scenario.toml")
    except ConfigError as exc:
        where = f"{exc.field}: " if exc.field else ""
        raise _refused(folder, f"scenario.toml: {where}{exc.message}", exc.suggestion) from None
    driver, reproducible = driven_by(metrics, scenario.controller.kind)
    return scenario, RecordedRun(folder, scenario.simulation.seed, metrics, driver, reproducible)


__all__ = ["CUT_SHORT", "MEASURED", "RUN_FILES", "RecordedRun", "driven_by", "read_recorded"]
