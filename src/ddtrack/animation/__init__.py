"""Animations of a run: the robot's footprint following the reference (``ddtrack animate``).

A frame shows, in the plane at true scale, the reference path, a dashed outline of the robot at the
reference pose, the robot itself (body, both wheels, heading arrow) with its fading trail, the time and the
tracking error; on a large map, a magnified view follows the robot, whose footprint is then small. When the
gains moved during the run (NN-adaptive runs), a second panel plots Kx, Ky and Ktheta against time with
a cursor at the frame's time. The input is the run's time-series columns (``timeseries.parquet`` of a run
folder, or :func:`ddtrack.timeseries`) and its geometry (half axle L, wheel radius R).

Frames sample the run at ``fps / speed`` frames per simulated second, at most ``max_frames`` of them (a
longer run plays faster). GIF is written with Pillow through matplotlib's :class:`PillowWriter`, on one
palette for every frame (no flicker, a fraction of the memory); MP4 through ffmpeg where it is on PATH.
"""

from __future__ import annotations

from .scene import GAINS as GAINS
from .scene import MAX_FRAMES as MAX_FRAMES
from .scene import SUFFIXES as SUFFIXES
from .scene import TRAIL_POINTS as TRAIL_POINTS
from .scene import TRAIL_SECONDS as TRAIL_SECONDS
from .scene import WHEEL as WHEEL
from .scene import ZOOM_BEYOND as ZOOM_BEYOND
from .scene import ZOOM_SIZE as ZOOM_SIZE
from .scene import AnimationInfo as AnimationInfo
from .scene import Columns as Columns
from .scene import animation_figure as animation_figure
from .scene import footprint as footprint
from .scene import frame_indices as frame_indices
from .scene import gains_moved as gains_moved
from .scene import read_run as read_run
from .writers import _BlitPillowWriter as _BlitPillowWriter
from .writers import _write_atomically as _write_atomically
from .writers import animate as animate
