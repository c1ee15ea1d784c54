"""Waypoint rows: a CSV file's columns (t, x, y, yaw, v in any order, under a header) read with the line of each
row, and the rows tidied for a path: repeated points dropped with a note, times derived from speeds. The reader
takes any columns of numbers (:func:`read_csv_columns`), so other files of rows (a replay plan) read alike."""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..trajectories import trapezoid_times
from ._base import Pair, read_input

COLUMNS = ("t", "x", "y", "yaw", "v")  #: [s], [m], [m], [rad], [m/s]


@dataclass(frozen=True)
class WaypointRows:
    """Waypoint rows, one entry per row in each column given (None: a column not given); ``numbers`` name the rows
    in messages as ``f"{word} {number}"`` (the file's line numbers, or the inline points' indices)."""

    points: list[Pair]
    times: list[float] | None = None
    yaws: list[float] | None = None
    speeds: list[float] | None = None
    numbers: tuple[int, ...] = ()
    word: str = "point"

    @property
    def timed(self) -> bool:
        """Whether the rows set the time of each point (a t or a v column)."""
        return self.times is not None or self.speeds is not None

    def labels(self) -> list[str]:
        return [f"{self.word} {n}" for n in self.numbers]

    def keep(self, rows: np.ndarray) -> WaypointRows:
        """Only the rows at the indices ``rows``."""

        def pick(column: list | None) -> list | None:
            return None if column is None else [column[i] for i in rows]

        return WaypointRows(
            [self.points[i] for i in rows],
            pick(self.times),
            pick(self.yaws),
            pick(self.speeds),
            tuple(self.numbers[i] for i in rows),
            self.word,
        )


@dataclass(frozen=True)
class CsvColumns:
    """The columns a CSV file of numbers may name in its header line (what messages call it, ``what``)."""

    what: str  #: e.g. "waypoints file"
    names: tuple[str, ...]  #: the columns a header may name, in the order messages list them
    units: str  #: their units, as messages give them, e.g. "(t [s], v [m/s], omega [rad/s])"
    required: tuple[str, ...]  #: the columns a header must name
    headless: tuple[str, ...] | None = None  #: the columns of a file without a header; None: a header is required


WAYPOINT_COLUMNS = CsvColumns(
    "waypoints file", COLUMNS, "(t [s], x and y [m], yaw [rad], v [m/s])", ("x", "y"), headless=("x", "y")
)


def read_csv_columns(path: Path, table: CsvColumns) -> tuple[dict[str, list[float]], tuple[int, ...]]:
    """Read the numbers of a CSV file by column: ``#`` comment lines and blank lines anywhere, then a header line
    before the first row naming the columns (any order, from ``table.names``), optional where ``table.headless``
    gives the columns of a file without one. Returns name -> column, and the file's line number of each row.

    Raises
    ------
    ValueError
        Naming the file, the line and the fix: an unreadable file, a missing, unknown or repeated column, a row
        with another number of cells, or a cell that is not a finite number.
    """
    try:
        text = read_input(path).decode("utf-8")
    except FileNotFoundError:
        raise ValueError(f"{table.what} '{path}' does not exist") from None
    except UnicodeDecodeError:
        shape = ",".join(table.headless or table.required)
        raise ValueError(f"{table.what} '{path}' is not UTF-8 text; give a CSV of {shape} rows") from None
    except OSError as exc:
        raise ValueError(f"{table.what} '{path}' cannot be read ({exc.strerror})") from None
    names: list[str] | None = None
    rows: list[list[float]] = []
    numbers: list[int] = []
    for number, row in enumerate(csv.reader(text.splitlines()), start=1):
        if not row or all(not cell.strip() for cell in row) or row[0].lstrip().startswith("#"):
            continue  # a blank line or a comment
        where = f"{table.what} '{path}' line {number}"
        if not rows and names is None and not all(_is_number(cell) for cell in row):
            names = _header(row, where, table)
            continue
        if names is None and table.headless is None:
            raise ValueError(
                f"{where}: a header line naming the columns {', '.join(table.required)} (any order) must come "
                f"before the first row {table.units}"
            )
        expected = names or list(table.headless or ())
        if len(row) != len(expected) or not all(_is_number(cell) for cell in row):
            raise ValueError(
                f"{where}: expected {len(expected)} numbers {','.join(expected)!r}, got {','.join(row)[:40]!r}"
            )
        values = [float(cell) for cell in row]
        if not all(math.isfinite(value) for value in values):
            raise ValueError(f"{where}: {','.join(row)[:40]!r} holds NaN or inf; every cell must be a finite number")
        rows.append(values)
        numbers.append(number)
    columns = names or list(table.headless or table.required)
    return {name: [r[i] for r in rows] for i, name in enumerate(columns)}, tuple(numbers)


def read_waypoint_rows(path: Path) -> WaypointRows:
    """Read waypoint rows from a CSV file (:func:`read_csv_columns`): an optional header line naming the columns
    (any order, from t, x, y, yaw, v; x and y required); without a header the rows are x,y.

    Raises
    ------
    ValueError
        Naming the file, the line and the fix (see :func:`read_csv_columns`).
    """
    columns, numbers = read_csv_columns(path, WAYPOINT_COLUMNS)
    return WaypointRows(
        points=list(zip(columns["x"], columns["y"], strict=True)),
        times=columns.get("t"),
        yaws=columns.get("yaw"),
        speeds=columns.get("v"),
        numbers=numbers,
        word="line",
    )


def read_waypoints(path: Path) -> list[Pair]:
    """The (x, y) points [m] of a waypoints file (see :func:`read_waypoint_rows`)."""
    return read_waypoint_rows(path).points


def _is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


def _header(row: list[str], where: str, table: CsvColumns) -> list[str]:
    """The column names of a header row, checked against ``table``."""
    names = [cell.strip().lower() for cell in row]
    unknown = [name for name in names if name not in table.names]
    if unknown:
        raise ValueError(
            f"{where}: unknown column {unknown[0]!r}; a header names columns from {', '.join(table.names)} "
            f"{table.units}, and a data row holds numbers only"
        )
    repeated = [name for name in table.names if names.count(name) > 1]
    if repeated:
        raise ValueError(f"{where}: column {repeated[0]!r} is named twice; name each column once")
    missing = [name for name in table.required if name not in names]
    if missing:
        required = ", ".join(table.required[:-1]) + f" and {table.required[-1]}"
        raise ValueError(f"{where}: the header has no {missing[0]!r} column; {required} are required")
    return names


def tidy_rows(rows: WaypointRows, source: str) -> tuple[WaypointRows, str | None]:
    """The rows a path is built from, and a note on what was dropped (None: nothing), naming ``source``.

    An untimed path (no t, no v) and a path timed by its speeds drop each row at the same point as the row before
    (the first is kept); a path timed by t drops a row equal to the one before in every column, and keeps a row at
    the same point at a later time (a stop). Speeds without times become the times of :func:`trapezoid_times`.

    Raises
    ------
    ValueError
        Naming the row: a time not after the one before, or a leg whose two speeds are both 0.
    """
    rows = replace(rows, numbers=rows.numbers or tuple(range(len(rows.points))))
    if rows.times is not None:
        columns = [c for c in (rows.times, rows.yaws, rows.speeds) if c is not None]
        same = [tuple(c[i] for c in columns) == tuple(c[i - 1] for c in columns) for i in range(1, len(rows.points))]
    else:
        same = [rows.points[i] == rows.points[i - 1] for i in range(1, len(rows.points))]
    repeated = [i for i in range(1, len(rows.points)) if same[i - 1] and rows.points[i] == rows.points[i - 1]]
    note = None
    if repeated:
        dropped = ", ".join(str(rows.numbers[i]) for i in repeated)
        plural = "s" if len(repeated) > 1 else ""
        note = f"{source}: dropped {len(repeated)} repeated point{plural} ({rows.word}{plural} {dropped})"
        rows = rows.keep(np.setdiff1d(np.arange(len(rows.points)), repeated))
    if rows.times is None and rows.speeds is not None and len(rows.points) == len(rows.speeds):
        times = trapezoid_times(rows.points, rows.speeds, labels=rows.labels())
        rows = replace(rows, times=[float(t) for t in times])
    if rows.times is not None:
        late = [i for i in range(1, len(rows.times)) if not rows.times[i] > rows.times[i - 1]]
        if late:
            i = late[0]
            raise ValueError(
                f"{rows.labels()[i]}: t = {rows.times[i]:g} s is not after {rows.times[i - 1]:g} s; times must "
                "increase row by row (a stop repeats the point at a later time)"
            )
    return rows, note
