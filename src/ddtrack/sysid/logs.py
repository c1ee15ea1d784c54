"""Logs to identify from: a ROS 2 bag (the inputs on ``/cmd_vel``, or the wheel efforts of ``/joint_states``, and
the speeds of ``/odom``), or a table (CSV or Parquet) with the columns ``t, v, omega`` and the inputs ``v_cmd,
omega_cmd``, ``tau_r, tau_l`` or ``u_r, u_l`` (with the currents ``i_r, i_l``): a ``ddtrack run`` folder's
``timeseries.parquet``, or ``ddtrack export``'s CSV, whose ``name [unit]`` headers are read by name."""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError
from ..model.sensing import body_increments
from .fit import SpeedLog
from .motor import MotorLog

#: the input columns of a table, per model: velocity commands (lag), wheel torques (body), armature voltages (motor)
INPUT_COLUMNS = {"lag": ("v_cmd", "omega_cmd"), "body": ("tau_r", "tau_l"), "motor": ("u_r", "u_l")}
TWIST_TYPES = ("geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped")


def read_speed_log(
    path: Path,
    *,
    model: str = "lag",
    cmd_topic: str = "/cmd_vel",
    odom_topic: str = "/odom",
    joint_topic: str = "/joint_states",
    wheels: tuple[float, float] | None = None,
) -> SpeedLog:
    """The inputs (the lag model's velocity commands, or the body model's wheel torques) and measured speeds of
    ``path``: a bag (a folder, ``.mcap`` or ``.db3``), ``.csv`` or ``.parquet``; a run folder reads its
    ``timeseries.parquet``. A bag's speeds are its odometry's twist, or with ``wheels`` = (wheel radius, half axle)
    [m], the ones its wheel joints' speeds give (no slip)."""
    if path.is_dir() and (path / "timeseries.parquet").is_file():
        path = path / "timeseries.parquet"
    suffix = path.suffix.lower()
    if suffix in (".csv", ".parquet"):
        return _table_log(path, INPUT_COLUMNS[model])
    if not (path.is_dir() or suffix in (".mcap", ".db3")):
        raise ConfigError("LOG", f"'{path}' is neither a bag nor a .csv or .parquet table", "give one of those")
    from ..ros.reading import open_bag

    with open_bag(path) as reader:
        if model == "body":
            sent, values, sent_lag = _joint_efforts(reader, joint_topic)
            inputs = joint_topic
        else:
            sent, values, sent_lag = _commands(reader, cmd_topic)
            inputs = cmd_topic
        if wheels is None:
            measured_at, speeds, measured_lag = _odometry(reader, odom_topic)
            measured = odom_topic
        else:
            measured_at, speeds, measured_lag = _wheel_joint_speeds(reader, joint_topic, *wheels)
            measured = f"{joint_topic} speeds"
    notes: tuple[str, ...] = ()
    offset = measured_lag - sent_lag
    if abs(offset) > CLOCK_TOLERANCE:  # the streams were stamped on two clocks: put the speeds on the inputs'
        measured_at = measured_at + offset
        notes = (
            f"{measured}'s stamps run {offset / 1e9:.4g} s behind {inputs}'s clock (the least receive time minus "
            f"stamp, in the bag); they were moved onto it, so the fitted delay holds the least transport latency",
        )
    return _held_inputs(path, sent, values, measured_at, speeds, (inputs, measured), notes)


#: [ns] a gap between two streams' clocks beyond this is corrected (a network's least latency is below it)
CLOCK_TOLERANCE = 5_000_000


def _stamped(messages: list) -> np.ndarray:
    from ..ros.reading import header_or_bag_time

    return np.array([header_or_bag_time(bag_time, msg) for bag_time, msg in messages], dtype=np.int64)


def _clock_lag(messages: list, stamps: np.ndarray) -> int:
    """[ns] how far a stream's ``stamps`` (of its ``messages``) run behind the recorder's clock: the least receive
    time minus stamp (the clock offset plus the least transport latency); 0 for a stream stamped on receipt."""
    return int(np.min(np.array([bag_time for bag_time, _ in messages], dtype=np.int64) - stamps))


def _commands(reader: Any, topic: str) -> tuple[np.ndarray, np.ndarray, int]:
    """The stamps [ns] and (v*, omega*) of each velocity command, in stamp order (receive order can differ)."""
    from ..ros.reading import topic_messages

    commands = topic_messages(reader, topic, TWIST_TYPES, option="--cmd-topic")
    twists = [msg.twist if hasattr(msg, "header") else msg for _, msg in commands]
    values = np.array([[tw.linear.x, tw.angular.z] for tw in twists], dtype=float)
    sent = _stamped(commands)
    order = np.argsort(sent, kind="stable")
    return sent[order], values[order], _clock_lag(commands, sent)


def _wheel_joints(reader: Any, topic: str, field: str, missing: str) -> tuple[np.ndarray, np.ndarray, int]:
    """The stamps [ns] and the right and left wheels' ``field`` (effort or velocity) of each JointState, in stamp
    order; the right wheel is the joint whose name says "right" (else the first)."""
    from ..ros.reading import topic_messages

    joints = topic_messages(reader, topic, ("sensor_msgs/msg/JointState",), option="--joint-topic")
    names = list(joints[0][1].name)
    if len(getattr(joints[0][1], field)) < 2:
        raise ConfigError("--joint-topic", f"'{topic}' carries no wheel {field}", missing)
    right = next((i for i, name in enumerate(names) if "right" in name), 0)
    left = next((i for i, name in enumerate(names) if "left" in name), 1 - right)
    values = np.array([[getattr(msg, field)[right], getattr(msg, field)[left]] for _, msg in joints], dtype=float)
    sent = _stamped(joints)
    order = np.argsort(sent, kind="stable")
    return sent[order], values[order], _clock_lag(joints, sent)


def _joint_efforts(reader: Any, topic: str) -> tuple[np.ndarray, np.ndarray, int]:
    return _wheel_joints(reader, topic, "effort", "record the wheel torques")


def _wheel_joint_speeds(reader: Any, topic: str, radius: float, half: float) -> tuple[np.ndarray, np.ndarray, int]:
    """The stamps [ns] and (v, omega) of the wheels' speeds (no slip): the axle midpoint's per second."""
    missing = "record the wheel speeds, or measure with --speeds odom"
    stamps, rates, lag = _wheel_joints(reader, topic, "velocity", missing)
    return stamps, np.column_stack(body_increments(rates.T, radius, half)), lag


def _odometry(reader: Any, topic: str) -> tuple[np.ndarray, np.ndarray, int]:
    """The stamps [ns] and twist (v, omega) of each Odometry message."""
    from ..ros.reading import topic_messages

    odometry = topic_messages(reader, topic, ("nav_msgs/msg/Odometry",), option="--odom-topic")
    speeds = np.array([[m.twist.twist.linear.x, m.twist.twist.angular.z] for _, m in odometry], dtype=float)
    stamps = _stamped(odometry)
    return stamps, speeds, _clock_lag(odometry, stamps)


def _held_inputs(
    path: Path,
    sent: np.ndarray,
    values: np.ndarray,
    measured_at: np.ndarray,
    speeds: np.ndarray,
    topics: tuple[str, str],
    notes: tuple[str, ...] = (),
) -> SpeedLog:
    """The measurements at their stamps and the inputs at theirs (each held until the next), on one time base
    from the first measurement after the first input (earlier ones are dropped). ``topics``: (the inputs', the
    measurements'), which name each sample's messages in errors."""
    latest = np.searchsorted(sent, measured_at, side="right") - 1
    valid = latest >= 0
    if valid.sum() == 0:
        raise ConfigError("LOG", f"'{path}': every measurement comes before the first input", "")
    t = (measured_at[valid] - measured_at[valid][0]) / 1e9
    inputs, measured = topics
    rows = tuple(
        f"{measured} message {i + 1} (stamp {measured_at[i]} ns), under {inputs} message {latest[i] + 1} in stamp order"
        for i in np.flatnonzero(valid)
    )
    source = f"'{path}' ({inputs}, {measured})"
    sent_t = (sent - measured_at[valid][0]) / 1e9
    return SpeedLog(
        t=t, command=values[latest[valid]], speed=speeds[valid], source=source, rows=rows, sent_t=sent_t,
        sent=values, notes=notes,
    )  # fmt: skip


def read_motor_log(path: Path) -> MotorLog:
    """The armature voltages ``u_r, u_l`` [V], measured speeds and, where logged, currents ``i_r, i_l`` [A] of a
    table (CSV or Parquet) or a run folder (a motor plant's ``timeseries.parquet`` has them all). ROS 2 has no
    standard message for motor voltages, so a bag is refused."""
    if path.is_dir() and (path / "timeseries.parquet").is_file():
        path = path / "timeseries.parquet"
    if path.suffix.lower() not in (".csv", ".parquet"):
        raise ConfigError(
            "LOG",
            f"'{path}' is not a .csv or .parquet table: --model motor reads voltages, which no standard ROS 2 "
            "message carries",
            "write a table of t, u_r, u_l, v, omega (and i_r, i_l) from your driver's topics",
        )
    table = _table_columns(path)
    columns = table[0]
    speeds = _table_log(path, INPUT_COLUMNS["motor"], table)
    if "i_r" not in columns or "i_l" not in columns:
        return MotorLog(speeds)
    return MotorLog(speeds, np.column_stack([np.asarray(columns[name], dtype=float) for name in ("i_r", "i_l")]))


def _table_columns(path: Path) -> tuple[dict[str, np.ndarray], list[str]]:
    """A table's columns by name (``name [unit]`` headers read as ``name``), and where each row is ("line 12" of a
    CSV, "row 12" of a Parquet table, counting from 1)."""
    if not path.is_file():
        raise ConfigError("LOG", f"'{path}' does not exist", "give a bag, a .csv or a .parquet file")
    if path.suffix.lower() == ".parquet":
        import pyarrow.parquet as pq

        try:
            table = pq.read_table(path)
        except (OSError, ValueError) as exc:
            raise ConfigError("LOG", f"'{path}' cannot be read as Parquet ({exc})") from None
        columns = {name.split(" [")[0]: table.column(name).to_numpy() for name in table.column_names}
        return columns, [f"row {i + 1}" for i in range(table.num_rows)]
    return _csv_columns(path)


def _table_log(
    path: Path, inputs: tuple[str, str], table: tuple[dict[str, np.ndarray], list[str]] | None = None
) -> SpeedLog:
    columns, rows = _table_columns(path) if table is None else table
    missing = [name for name in ("t", *inputs, "v", "omega") if name not in columns]
    if missing:
        raise ConfigError(
            "LOG",
            f"'{path}' lacks the columns {', '.join(missing)}",
            f"a log needs t [s], {', '.join(inputs)} (the inputs) and v, omega (the measured speeds)",
        )
    column = lambda name: np.asarray(columns[name], dtype=float)  # noqa: E731
    return SpeedLog(
        t=column("t"),
        command=np.column_stack([column(inputs[0]), column(inputs[1])]),
        speed=np.column_stack([column("v"), column("omega")]),
        source=f"'{path}'",
        rows=tuple(rows),
    )


def _csv_columns(path: Path) -> tuple[dict[str, np.ndarray], list[str]]:
    """A CSV's columns by name (``name [unit]`` headers read as ``name``; ``#`` lines skipped), and each row's line
    in the file; a cell that is not a number, or a row of another length than the header, is named by its line."""
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError("LOG", f"'{path}' cannot be read ({exc})") from None
    reader = csv.reader(io.StringIO(text))
    numbered = [(reader.line_num, row) for row in reader if row and not row[0].lstrip().startswith("#")]
    if len(numbered) < 2:
        raise ConfigError("LOG", f"'{path}' has no data rows", "give a header line and one row per sample")
    names = [cell.split(" [")[0].strip() for cell in numbered[0][1]]
    values = np.empty((len(numbered) - 1, len(names)))
    for i, (line, row) in enumerate(numbered[1:]):
        if len(row) != len(names):
            raise ConfigError("LOG", f"'{path}', line {line}: {len(row)} cells under a header of {len(names)}")
        for j, cell in enumerate(row):
            try:
                values[i, j] = float(cell)
            except ValueError:
                raise ConfigError(
                    "LOG", f"'{path}', line {line}, column {names[j]}: '{cell}' is not a number"
                ) from None
    return {name: values[:, i] for i, name in enumerate(names)}, [f"line {line}" for line, _ in numbered[1:]]
