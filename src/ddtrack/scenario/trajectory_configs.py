"""The ``[trajectory]`` section, one model per kind, and waypoint files read inside the scenario's folder."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, ModelWrapValidatorHandler, PrivateAttr, ValidationInfo, model_validator

from ..trajectories import Circle, FigureEight, Line, Sinusoid, Trajectory, polyline_path, square, timed_path
from ..trajectories.curves import CircleParameters, FigureEightParameters, LineParameters, SinusoidParameters
from ._base import (
    FieldError,
    Length,
    NonNegative,
    Position,
    Positive,
    _Section,
)
from .waypoint_rows import WaypointRows, read_waypoint_rows, tidy_rows

# --- [trajectory] --------------------------------------------------------------------------------


class _TrajectorySection(_Section):
    """The root of a ``[trajectory]`` kind whose parameters are declared with its curve: ``kind`` stays first."""

    kind: str


class LineTrajectory(LineParameters, _TrajectorySection):
    """Straight line at constant speed (the paper's y = x is heading = pi/4)."""

    kind: Literal["line"]

    def build(self) -> Trajectory:
        return Line(start=self.start, heading=self.heading, speed=self.speed)


class SquareTrajectory(_Section):
    """The paper's square, counter-clockwise from ``corner`` with heading 0 (model.md §4.3)."""

    kind: Literal["square"]
    corner: Position = Field((10.0, 0.0), description="Starting corner C0 [m].")
    side: Length = Field(10.0, description="Side S [m].")
    speed: Positive = Field(0.5, description="v_r [m/s].")
    corner_radius: NonNegative = Field(0.0, description="Fillet radius at C1..C3 [m]; 0 = sharp corners.")

    @model_validator(mode="after")
    def _fits(self) -> SquareTrajectory:
        if 2.0 * self.corner_radius > self.side:
            raise FieldError(
                "corner_radius",
                f"{self.corner_radius:g} m does not fit on a side of {self.side:g} m; use at most side / 2",
            )
        try:
            self.build()
        except ValueError as exc:  # a side too small for distinct corners (5e-324 m)
            raise FieldError("side", f"{self.side:g} m is too small for distinct corners ({exc})") from None
        return self

    def build(self) -> Trajectory:
        return square(corner=self.corner, side=self.side, speed=self.speed, corner_radius=self.corner_radius)


class CircleTrajectory(CircleParameters, _TrajectorySection):
    """Circle at constant speed."""

    kind: Literal["circle"]

    def build(self) -> Trajectory:
        return Circle(
            center=self.center,
            radius=self.radius,
            speed=self.speed,
            start_angle=self.start_angle,
            clockwise=self.clockwise,
        )


class FigureEightTrajectory(FigureEightParameters, _TrajectorySection):
    """Lemniscate of Gerono (speed between 0.66*size*w and 1.41*size*w, w = 2 pi / period: it never stops)."""

    kind: Literal["figure_eight"]

    def build(self) -> Trajectory:
        return FigureEight(center=self.center, size=self.size, period=self.period)


class SinusoidTrajectory(SinusoidParameters, _TrajectorySection):
    """A sine wave about a straight axis run at constant speed."""

    kind: Literal["sinusoid"]

    def build(self) -> Trajectory:
        return Sinusoid(
            start=self.start,
            heading=self.heading,
            speed=self.speed,
            amplitude=self.amplitude,
            wavelength=self.wavelength,
        )


class WaypointsTrajectory(_Section):
    """A polyline through waypoints at constant speed with rounded corners, or, with times, a timed path that is at
    each point at its time (built by ``ddtrack.trajectories.timed_path``).

    ``file`` is a CSV of rows (an optional header naming the columns from t, x, y, yaw, v), relative to the scenario
    file and inside its folder tree (an absolute path, or a ``..`` or symlink leading out, is an error); the
    resolved scenario holds the rows inline instead. A row at the same point as the row before is dropped, with a
    warning (a timed path keeps it when its time is later: a stop).
    """

    kind: Literal["waypoints"]
    file: str | None = Field(
        None,
        description="CSV file of x,y rows, or columns t, x, y, yaw, v under a header, relative to the scenario file.",
    )
    points: list[Position] | None = Field(None, description="Inline [[x, y], ...] instead of a file [m].")
    times: list[float] | None = Field(
        None, description="Time of each point [s], increasing: a timed path (ignores speed and takes no corner_radius)."
    )
    yaws: list[float] | None = Field(
        None, description="Heading held where a timed path stands still, one per point [rad]."
    )
    speeds: list[NonNegative] | None = Field(
        None, description="Speed at each point [m/s]: the times by the trapezoid rule when times is not given."
    )
    speed: Positive = Field(0.5, description="v_r of an untimed path [m/s].")
    corner_radius: NonNegative = Field(0.0, description="Fillet radius at interior waypoints of an untimed path [m].")
    loop: bool = Field(False, description="Repeat an untimed path; otherwise the reference stops at the end.")
    _notes: tuple[str, ...] = PrivateAttr(default=())

    @model_validator(mode="wrap")
    @classmethod
    def _read_rows(
        cls, data: Any, handler: ModelWrapValidatorHandler[WaypointsTrajectory], info: ValidationInfo
    ) -> Any:
        note = None
        if isinstance(data, dict):
            data, note = _tidied(data, Path((info.context or {}).get("base_dir", ".")))
        model = handler(data)
        if note is not None:
            model._notes = (note,)
        return model

    @model_validator(mode="after")
    def _valid_path(self) -> WaypointsTrajectory:
        if self.points is None:
            raise FieldError("points", "give 'file' (a CSV of x,y rows) or 'points' ([[x, y], ...])")
        if self.file is not None:
            raise FieldError("file", "give only one of 'file' and 'points'")
        for name in ("times", "yaws", "speeds"):
            column = getattr(self, name)
            if column is not None and len(column) != len(self.points):
                raise FieldError(name, f"has {len(column)} values for {len(self.points)} points; give one per point")
        if self.times is not None and self.corner_radius > 0.0:
            raise FieldError(
                "corner_radius",
                "a timed path (t or v column, or times) passes through each point at its time and has no fillets",
                "remove corner_radius, or the t and v columns for a path at constant speed",
            )
        if self.times is not None and self.loop:
            raise FieldError("loop", "a timed path does not repeat", "remove loop, or the t and v columns")
        try:
            self.build()
        except ValueError as exc:  # names the bad point or leg
            raise FieldError("points" if self.times is None else "times", str(exc)) from None
        return self

    @property
    def load_warnings(self) -> list[dict]:
        """What loading changed, each ``{"code", "message"}`` (repeated points dropped)."""
        return [{"code": "waypoints_repeated", "message": note} for note in self._notes]

    def build(self) -> Trajectory:
        assert self.points is not None, "a waypoint file is read into points when the scenario loads"
        if self.times is not None:
            return timed_path(self.times, self.points, yaws=self.yaws, speeds=self.speeds)
        return polyline_path(self.points, speed=self.speed, corner_radius=self.corner_radius, loop=self.loop)


def _tidied(data: dict[str, Any], base: Path) -> tuple[dict[str, Any], str | None]:
    """``data`` with its file read into rows, repeated points dropped and times derived from speeds (see
    :func:`tidy_rows`), and the note on what was dropped; malformed inline values pass through for the fields'
    own errors."""
    name = data.get("file")
    if name is not None and data.get("points") is None:
        if not isinstance(name, str):
            return data, None  # the type error is reported by the field
        try:
            read, note = tidy_rows(read_waypoint_rows(_contained(base, name)), f"waypoints file '{name}'")
        except ValueError as exc:
            message = str(exc)
            if not message.startswith("waypoints file") and not message.startswith("'"):
                message = f"waypoints file '{name}' {message}"
            raise FieldError("file", message) from None
        return {**data, **_inline(read), "file": None}, note
    inline = _inline_rows(data)
    if inline is None:  # TOML arrays -> [x, y] tuples, for the fields' own errors
        points = data.get("points")
        if isinstance(points, list):
            data = {**data, "points": [tuple(p) if isinstance(p, list) else p for p in points]}
        return data, None
    try:
        tidy, note = tidy_rows(inline, "trajectory.points")
    except ValueError as exc:
        raise FieldError("times" if "times" in data else "speeds", str(exc)) from None
    return {**data, **_inline(tidy)}, note


def _inline(rows: WaypointRows) -> dict[str, Any]:
    return {"points": rows.points, "times": rows.times, "yaws": rows.yaws, "speeds": rows.speeds}


def _inline_rows(data: dict[str, Any]) -> WaypointRows | None:
    """The inline rows of ``data``, or None where a value is malformed (its field reports it)."""

    def numbers(value: Any) -> bool:
        return isinstance(value, list | tuple) and all(
            isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in value
        )

    points = data.get("points")
    if not isinstance(points, list) or not all(numbers(p) and len(p) == 2 for p in points):
        return None
    columns = [data.get(name) for name in ("times", "yaws", "speeds")]
    if not all(c is None or (numbers(c) and len(c) == len(points)) for c in columns):
        return None
    if data.get("speeds") is not None and any(v < 0.0 for v in data["speeds"]):
        return None
    pairs = [(float(p[0]), float(p[1])) for p in points]
    times, yaws, speeds = ([float(v) for v in c] if c is not None else None for c in columns)
    return WaypointRows(pairs, times, yaws, speeds)


def _contained(base: Path, name: str, *, what: str = "a waypoints file") -> Path:
    """``base / name``, refused (ValueError, calling the file ``what``) unless it stays inside ``base``'s folder tree
    once ``..`` and symlinks are resolved: a scenario, perhaps from someone else, can make ddtrack read only files
    beside it or below it."""
    if Path(name).is_absolute():
        raise ValueError(
            f"'{name}' is an absolute path; {what} is read relative to the scenario file, "
            "inside its folder: copy the CSV beside the scenario and give its file name"
        )
    path = base / name
    if not path.resolve().is_relative_to(base.resolve()):
        raise ValueError(
            f"'{name}' leads outside the scenario's folder ('..' or a symlink); copy the CSV beside "
            "the scenario and give its file name"
        )
    return path
