"""Reference trajectories: pure functions of time returning a :class:`Reference` (model.md §2.1, 4.2, 4.3)."""

from .base import ParametricCurve, Reference, Trajectory
from .curves import Circle, FigureEight, Line, Sinusoid
from .paths import PiecewisePath, polyline_path, square
from .sampled import SampledTrajectory, unicycle_reference
from .timed import TimedPath, timed_path, trapezoid_times

__all__ = [
    "Circle",
    "FigureEight",
    "Line",
    "ParametricCurve",
    "PiecewisePath",
    "Reference",
    "SampledTrajectory",
    "Sinusoid",
    "TimedPath",
    "Trajectory",
    "polyline_path",
    "square",
    "timed_path",
    "trapezoid_times",
    "unicycle_reference",
]
