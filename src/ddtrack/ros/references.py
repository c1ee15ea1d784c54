"""``ddtrack import``: a reference for a scenario from a ROS 2 bag, a planner's path or a driven trajectory.

The result is a waypoints CSV (docs/scenarios.md) that ``[trajectory] kind = "waypoints"`` reads: ``x,y`` rows
timed at a constant speed given by the user, or ``t,x,y,yaw[,v]`` rows timed by the bag's stamps, ``t`` in seconds
from the first pose.
"""

from __future__ import annotations

import math
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from ..errors import ConfigError
from .messages import NANOSECONDS, quaternion_yaw, stamp_nanoseconds
from .reading import header_or_bag_time, open_bag, topic_messages

PATH_TYPE = "nav_msgs/msg/Path"
ODOMETRY_TYPE = "nav_msgs/msg/Odometry"


@dataclass(frozen=True)
class ImportedReference:
    """A reference read from a bag: its columns (``t`` [s] when timed, ``x, y`` [m], ``yaw`` [rad], ``v``
    [m/s]), where it came from, and what was changed on the way (dropped duplicates)."""

    columns: Mapping[str, np.ndarray]
    source: str  #: e.g. "/plan (nav_msgs/msg/Path, frame 'map', message 3 of 3)"
    notes: tuple[str, ...] = field(default=())

    @property
    def timed(self) -> bool:
        return "t" in self.columns

    @property
    def duration(self) -> float | None:
        return float(self.columns["t"][-1]) if self.timed else None


def reference_from_path(bag: Path, topic: str, *, speed: float | None = None) -> ImportedReference:
    """The last ``nav_msgs/msg/Path`` on ``topic`` (a planner's latest plan) as a reference: timed by its poses'
    stamps, or, with ``speed`` [m/s], an untimed polyline that the scenario runs at that speed.

    Consecutive repeated points are dropped (untimed), as are exact repeats of a pose and its stamp (timed); a
    repeated point with a later stamp is a stop and stays. Poses without stamps need ``speed``.
    """
    with open_bag(bag) as reader:
        messages = topic_messages(reader, topic, (PATH_TYPE,), option="--path-topic")
    plan = messages[-1][1]
    poses = list(plan.poses)
    source = f"{topic} ({PATH_TYPE}, frame '{plan.header.frame_id}', message {len(messages)} of {len(messages)})"
    if len(poses) < 2:
        raise ConfigError("--path-topic", f"the last path on '{topic}' has {len(poses)} poses", "a path needs two")
    x = np.array([p.pose.position.x for p in poses], dtype=float)
    y = np.array([p.pose.position.y for p in poses], dtype=float)
    yaw = np.array([quaternion_yaw(p.pose.orientation) for p in poses], dtype=float)
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise ConfigError("--path-topic", f"the path on '{topic}' has a NaN or infinite position", "")
    if speed is not None:
        keep = np.concatenate([[True], (np.diff(x) != 0.0) | (np.diff(y) != 0.0)])
        notes = _dropped(keep, "repeated point")
        if keep.sum() < 2:
            raise ConfigError("--path-topic", f"the path on '{topic}' has fewer than two distinct points", "")
        return ImportedReference({"x": x[keep], "y": y[keep]}, source, notes)
    stamps = np.array([stamp_nanoseconds(p.header) for p in poses], dtype=np.int64)
    if np.all(stamps == stamps[0]):
        raise ConfigError(
            "--path-topic",
            f"the poses of the path on '{topic}' all have the same stamp, so they do not time it",
            "give --speed V to run the path at V m/s",
        )
    keep = _timed_rows(stamps, x, y, option="--path-topic", what=f"the path on '{topic}': pose")
    t = (stamps[keep] - stamps[keep][0]) / NANOSECONDS
    return ImportedReference({"t": t, "x": x[keep], "y": y[keep], "yaw": yaw[keep]}, source, _dropped(keep, "repeat"))


def reference_from_odometry(bag: Path, topic: str) -> ImportedReference:
    """The trajectory a robot drove, from its ``nav_msgs/msg/Odometry`` on ``topic``, as a timed reference:
    ``t`` from the header stamps (the bag's receive times where unstamped), pose and forward speed."""
    with open_bag(bag) as reader:
        messages = topic_messages(reader, topic, (ODOMETRY_TYPE,), option="--odom-topic")
    if len(messages) < 2:
        raise ConfigError("--odom-topic", f"topic '{topic}' holds {len(messages)} message", "a trajectory needs two")
    stamps = np.array([header_or_bag_time(bag_time, msg) for bag_time, msg in messages], dtype=np.int64)
    x = np.array([msg.pose.pose.position.x for _, msg in messages], dtype=float)
    y = np.array([msg.pose.pose.position.y for _, msg in messages], dtype=float)
    yaw = np.array([quaternion_yaw(msg.pose.pose.orientation) for _, msg in messages], dtype=float)
    v = np.array([msg.twist.twist.linear.x for _, msg in messages], dtype=float)
    keep = _timed_rows(stamps, x, y, option="--odom-topic", what=f"'{topic}' message")
    frame = messages[0][1].header.frame_id
    source = f"{topic} ({ODOMETRY_TYPE}, frame '{frame}', {len(messages)} messages)"
    t = (stamps[keep] - stamps[keep][0]) / NANOSECONDS
    return ImportedReference(
        {"t": t, "x": x[keep], "y": y[keep], "yaw": yaw[keep], "v": v[keep]}, source, _dropped(keep, "repeat")
    )


def _timed_rows(stamps: np.ndarray, x: np.ndarray, y: np.ndarray, *, option: str, what: str) -> np.ndarray:
    """Rows to keep of a stamped series: exact repeats (same stamp, same point) go; a stamp that goes back, or a
    repeated stamp at another point, is refused naming the row."""
    step = np.diff(stamps)
    same_point = (np.diff(x) == 0.0) & (np.diff(y) == 0.0)
    bad = np.flatnonzero((step < 0) | ((step == 0) & ~same_point))
    if bad.size:
        k = int(bad[0]) + 1
        problem = "goes back in time" if step[k - 1] < 0 else "repeats the stamp of the one before at another point"
        raise ConfigError(
            option,
            f"{what} {k} (stamp {stamps[k] / NANOSECONDS:.9f} s) {problem}",
            "stamps must increase: fix the recording clock, or re-record",
        )
    return np.concatenate([[True], step > 0])


def _dropped(keep: np.ndarray, what: str) -> tuple[str, ...]:
    dropped = np.flatnonzero(~keep)
    if not dropped.size:
        return ()
    shown = ", ".join(map(str, dropped[:10])) + (", ..." if dropped.size > 10 else "")
    return (f"dropped {dropped.size} {what}{'s' if dropped.size > 1 else ''} (rows {shown})",)


def write_reference_csv(reference: ImportedReference, file: IO[bytes], *, comment: str) -> None:
    """The reference as a waypoints CSV: ``#`` comment lines (``comment``, then the notes), a header, and rows
    with the 17 significant digits that give each float64 back."""
    lines = [f"# {line}" for line in (comment, *reference.notes)]
    names = list(reference.columns)
    table = np.column_stack([reference.columns[name] for name in names])
    lines.append(",".join(names))
    lines.extend(",".join(map(repr, map(float, row))) for row in table)
    file.write(("\n".join(lines) + "\n").encode())


def reference_from_path_message(path_message: Any, topic: str) -> ImportedReference:
    """A received ``nav_msgs/msg/Path`` as a timed reference, re-timed exactly as ``ddtrack import`` does: the message
    goes through a temporary bag and :func:`reference_from_path`, so a live path and an imported one cannot differ.

    Refuses, naming ``--path-topic``, a path with a NaN or infinite position or with fewer than two poses (a live
    path is checked before the bag, so the refusal names the topic as the user gave it).
    """
    from .export import write_bag  # export imports much of ros/; imported here, not at load

    poses = list(path_message.poses)
    finite = all(math.isfinite(p.pose.position.x) and math.isfinite(p.pose.position.y) for p in poses)
    if not finite:
        raise ConfigError("--path-topic", f"the path on '{topic}' has a NaN or infinite position", "")
    if len(poses) < 2:
        raise ConfigError("--path-topic", f"the path on '{topic}' has {len(poses)} poses", "a path needs two")
    with tempfile.TemporaryDirectory(prefix="ddtrack-path-") as scratch:
        bag = Path(scratch) / "path.mcap"
        write_bag(bag, [(topic, PATH_TYPE, 1, path_message)])
        return reference_from_path(bag, topic)


def path_scenario_data(data: dict[str, Any], reference: ImportedReference) -> dict[str, Any]:
    """A scenario's data (a dict as ``model_dump(mode="json")`` gives it) with its trajectory replaced by a timed
    ``reference`` (waypoints at its stamps and yaws), its duration and metric window the reference's whole span: the
    run then follows, and is scored against, the path. Everything else is kept, the ``[initial]`` section included."""
    columns = reference.columns
    duration = float(columns["t"][-1])
    data = dict(data)
    data["trajectory"] = {
        "kind": "waypoints",
        "points": [[float(x), float(y)] for x, y in zip(columns["x"], columns["y"], strict=True)],
        "times": [float(t) for t in columns["t"]],
        "yaws": [float(yaw) for yaw in columns["yaw"]],
    }
    simulation = dict(data.get("simulation", {}))
    simulation.update(duration=duration, metric_window=[0.0, duration])
    data["simulation"] = simulation
    return data
