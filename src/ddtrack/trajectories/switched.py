"""One program for a study's trajectories of different kinds: each run carries every kind the study uses and a
traced index picks its own (docs/benchmarks.md, "What a study compiles").

A trajectory's class is part of a compiled program's structure, so a study whose cells follow a figure eight and a
square compiled every controller and plant twice. :class:`Switched` holds one trajectory of each kind in the study
(the run's own, and a stand-in of every other kind) and evaluates them all, keeping the chosen one's reference with
an elementwise select: the chosen values are computed by the same operations as the trajectory alone. Piecewise
paths are padded to the study's longest, with segments that are never reached.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from .._pytree import pytree_dataclass
from .base import Reference, Trajectory
from .paths import PiecewisePath


@pytree_dataclass
class Switched:
    """The reference of ``options[chosen]`` (``chosen`` traced: runs on different trajectories share a program)."""

    options: tuple[Any, ...]
    chosen: Array | int

    def __call__(self, t: Array | float) -> Reference:
        references = [option(t) for option in self.options]
        which = jnp.asarray(self.chosen, jnp.int32)
        return Reference(*(jax.lax.select_n(which, *values) for values in zip(*references, strict=True)))


def pad_path(path: PiecewisePath, segments: int) -> PiecewisePath:
    """``path`` with ``segments`` segments (its own first, along the last axis of a batch): the added ones start at
    an infinite arc length, so the segment search never reaches them and the reference is the path's own."""
    extra = segments - np.shape(path.offsets)[-1]
    if extra <= 0:
        return path

    def pad(leaf: Array, value: float, trailing: int = 0) -> Array:
        widths = [(0, 0)] * (np.ndim(leaf) - 1 - trailing) + [(0, extra)] + [(0, 0)] * trailing
        return jnp.pad(jnp.asarray(leaf), widths, constant_values=value)

    return replace(
        path,
        starts=pad(path.starts, 0.0, trailing=1),
        headings=pad(path.headings, 0.0),
        curvatures=pad(path.curvatures, 0.0),
        offsets=pad(path.offsets, np.inf),
    )


def _kind(trajectory: Trajectory) -> Any:
    """What must match for two trajectories to share a program: their tree structure (class and static fields)."""
    return jax.tree_util.tree_structure(trajectory)


@dataclass(frozen=True)
class TrajectoryFrame:
    """The kinds of trajectory a study's runs follow, one stand-in of each (unbatched), and the segments every
    piecewise path is padded to."""

    stand_ins: tuple[Any, ...]
    segments: int

    def place(self, trajectory: Trajectory, runs: int) -> Switched:
        """A batch of ``runs`` runs' ``trajectory`` (a leading batch axis) as a :class:`Switched` of the study's
        kinds, the stand-ins of the other kinds broadcast to the batch."""
        own = self._padded(trajectory)
        index = [_kind(stand_in) for stand_in in self.stand_ins].index(_kind(own))
        options = tuple(
            own
            if i == index
            else jax.tree_util.tree_map(lambda leaf: jnp.broadcast_to(leaf, (runs, *np.shape(leaf))), stand_in)
            for i, stand_in in enumerate(self.stand_ins)
        )
        return Switched(options, jnp.full(runs, index, jnp.int32))

    def _padded(self, trajectory: Trajectory) -> Any:
        return pad_path(trajectory, self.segments) if isinstance(trajectory, PiecewisePath) else trajectory


def trajectory_frame(trajectories: Sequence[Trajectory]) -> TrajectoryFrame | None:
    """The frame that lets ``trajectories`` (a study's, one per cell) share programs; ``None`` when they are all
    of one kind already (the runs keep their own trajectory: nothing changes)."""
    paths = [np.shape(t.offsets)[-1] for t in trajectories if isinstance(t, PiecewisePath)]
    frame = TrajectoryFrame((), max(paths, default=0))
    stand_ins: dict[Any, Any] = {}
    for trajectory in trajectories:
        padded = frame._padded(trajectory)
        stand_ins.setdefault(_kind(padded), padded)
    if len(stand_ins) < 2:
        return None
    return replace(frame, stand_ins=tuple(stand_ins.values()))
