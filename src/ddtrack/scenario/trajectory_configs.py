"""The ``[trajectory]`` section, one model per kind, and waypoint files read inside the scenario's folder."""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field, ValidationInfo, model_validator

from ..trajectories import Circle, FigureEight, Line, Sinusoid, Trajectory, polyline_path, square
from ._base import (
    MAX_COORDINATE,
    FieldError,
    Length,
    NonNegative,
    Pair,
    Position,
    Positive,
    _Section,
    read_input,
)

# --- [trajectory] --------------------------------------------------------------------------------


class LineTrajectory(_Section):
    """Straight line at constant speed (the paper's y = x is heading = pi/4)."""

    kind: Literal["line"]
    speed: Positive = Field(0.5, description="v_r [m/s].")
    start: Position = Field((0.0, 0.0), description="Position at t = 0 [m].")
    heading: float = Field(0.0, description="Direction [rad].")

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


class CircleTrajectory(_Section):
    """Circle at constant speed."""

    kind: Literal["circle"]
    center: Position = Field((0.0, 0.0), description="Centre [m].")
    radius: Length = Field(2.0, description="Radius [m].")
    speed: Positive = Field(0.5, description="v_r [m/s].")
    start_angle: float = Field(-math.pi / 2, description="Polar angle of the start point about the centre [rad].")
    clockwise: bool = Field(False, description="Direction of travel.")

    def build(self) -> Trajectory:
        return Circle(
            center=self.center,
            radius=self.radius,
            speed=self.speed,
            start_angle=self.start_angle,
            clockwise=self.clockwise,
        )


class FigureEightTrajectory(_Section):
    """Lemniscate of Gerono (speed between 0.66*size*w and 1.41*size*w, w = 2 pi / period: it never stops)."""

    kind: Literal["figure_eight"]
    center: Position = Field((0.0, 0.0), description="Crossing point [m].")
    size: Length = Field(3.0, description="Half-width [m].")
    period: Positive = Field(60.0, description="Time for both lobes [s].")

    def build(self) -> Trajectory:
        return FigureEight(center=self.center, size=self.size, period=self.period)


class SinusoidTrajectory(_Section):
    """A sine wave about a straight axis run at constant speed."""

    kind: Literal["sinusoid"]
    start: Position = Field((0.0, 0.0), description="Position at t = 0 [m].")
    heading: float = Field(0.0, description="Direction of the axis [rad].")
    speed: Positive = Field(0.5, description="Speed along the axis [m/s].")
    amplitude: Annotated[float, Field(ge=0.0, le=MAX_COORDINATE)] = Field(1.0, description="Lateral amplitude [m].")
    wavelength: Length = Field(10.0, description="Wavelength along the axis [m].")

    def build(self) -> Trajectory:
        return Sinusoid(
            start=self.start,
            heading=self.heading,
            speed=self.speed,
            amplitude=self.amplitude,
            wavelength=self.wavelength,
        )


class WaypointsTrajectory(_Section):
    """A polyline through waypoints at constant speed with rounded corners.

    ``file`` is a CSV of x,y rows (an optional header line), relative to the scenario file and inside its
    folder tree (an absolute path, or a ``..`` or symlink leading out, is an error); the resolved scenario
    holds the points inline instead.
    """

    kind: Literal["waypoints"]
    file: str | None = Field(None, description="CSV file of x,y rows, relative to the scenario file.")
    points: list[Position] | None = Field(None, description="Inline [[x, y], ...] instead of a file [m].")
    speed: Positive = Field(0.5, description="v_r [m/s].")
    corner_radius: NonNegative = Field(0.0, description="Fillet radius at interior waypoints [m].")
    loop: bool = Field(False, description="Repeat the path; otherwise the reference stops at the end.")

    @model_validator(mode="before")
    @classmethod
    def _read_file(cls, data: Any, info: ValidationInfo) -> Any:
        if isinstance(data, dict) and data.get("file") is not None and data.get("points") is None:
            if not isinstance(data["file"], str):
                return data  # the type error is reported by the field
            base = Path((info.context or {}).get("base_dir", "."))
            try:
                data = {**data, "points": read_waypoints(_contained(base, data["file"])), "file": None}
            except ValueError as exc:
                raise FieldError("file", str(exc)) from None
        if isinstance(data, dict) and isinstance(data.get("points"), list):  # TOML arrays -> [x, y] tuples
            data = {**data, "points": [tuple(p) if isinstance(p, list) else p for p in data["points"]]}
        return data

    @model_validator(mode="after")
    def _valid_path(self) -> WaypointsTrajectory:
        if self.points is None:
            raise FieldError("points", "give 'file' (a CSV of x,y rows) or 'points' ([[x, y], ...])")
        if self.file is not None:
            raise FieldError("file", "give only one of 'file' and 'points'")
        try:
            self.build()
        except ValueError as exc:  # names the bad point or leg
            raise FieldError("points", str(exc)) from None
        return self

    def build(self) -> Trajectory:
        assert self.points is not None, "a waypoint file is read into points when the scenario loads"
        return polyline_path(self.points, speed=self.speed, corner_radius=self.corner_radius, loop=self.loop)


def _contained(base: Path, name: str) -> Path:
    """``base / name``, refused (ValueError) unless it stays inside ``base``'s folder tree once ``..`` and symlinks
    are resolved: a scenario, perhaps from someone else, can make ddtrack read only files beside it or below it."""
    if Path(name).is_absolute():
        raise ValueError(
            f"'{name}' is an absolute path; a waypoints file is read relative to the scenario file, "
            "inside its folder: copy the CSV beside the scenario and give its file name"
        )
    path = base / name
    if not path.resolve().is_relative_to(base.resolve()):
        raise ValueError(
            f"'{name}' leads outside the scenario's folder ('..' or a symlink); copy the CSV beside "
            "the scenario and give its file name"
        )
    return path


def read_waypoints(path: Path) -> list[Pair]:
    """Read x,y rows from a CSV file: ``#`` comment lines and blank lines anywhere, then one optional header line
    before the first point (``x,y``)."""
    try:
        text = read_input(path).decode("utf-8")
    except FileNotFoundError:
        raise ValueError(f"waypoints file '{path}' does not exist") from None
    except UnicodeDecodeError:
        raise ValueError(f"waypoints file '{path}' is not UTF-8 text; give a CSV of x,y rows") from None
    except OSError as exc:
        raise ValueError(f"waypoints file '{path}' cannot be read ({exc.strerror})") from None
    points, header_seen = [], False
    for number, row in enumerate(csv.reader(text.splitlines()), start=1):
        if not row or all(not cell.strip() for cell in row) or row[0].lstrip().startswith("#"):
            continue  # a blank line or a comment
        try:
            if len(row) != 2:
                raise ValueError
            points.append((float(row[0]), float(row[1])))
        except ValueError:
            if not points and not header_seen:
                header_seen = True
                continue  # a header line
            raise ValueError(
                f"waypoints file '{path}' line {number}: expected two numbers 'x,y', got {','.join(row)[:40]!r}"
            ) from None
    return points
