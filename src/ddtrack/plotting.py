"""Figures of a run, from its time-series columns (:func:`ddtrack.sim.timeseries` or a Parquet file).

Every function takes ``ax``/``axes=None``, returns the figure and never calls ``show()``.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import matplotlib

matplotlib.use("Agg")  # headless by default; a user's explicit backend choice before import still wins
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

Columns = Mapping[str, np.ndarray]
ROBOT, REFERENCE, ADAPTIVE = "#1f77b4", "#444444", "#d62728"


def _axes(ax: Axes | None, **figure) -> tuple[Figure, Axes]:
    if ax is None:
        fig, ax = plt.subplots(**figure)
        return fig, ax
    return ax.figure, ax


def _stack(axes: Sequence[Axes] | None, n: int) -> tuple[Figure, Sequence[Axes]]:
    if axes is None:
        fig, axes = plt.subplots(n, 1, sharex=True, figsize=(7, 1.9 * n + 0.6), layout="constrained")
        return fig, list(np.atleast_1d(axes))
    return axes[0].figure, axes


def plot_path(columns: Columns, ax: Axes | None = None, *, title: str = "", label: str = "robot",
              color: str = ROBOT, reference: bool = True) -> Figure:
    """The robot's path against the reference in the plane (the paper's Figs. 10 and 14).

    Call again with ``ax`` and ``reference=False`` to overlay another run.
    """
    new = ax is None
    fig, ax = _axes(ax, figsize=(6, 6), layout="constrained")
    if reference:
        ax.plot(columns["x_ref"], columns["y_ref"], "--", color=REFERENCE, lw=1.2, label="reference")
        ax.plot(columns["x_ref"][0], columns["y_ref"][0], "s", color=REFERENCE, ms=5, mfc="none")
        ax.plot(columns["x"][0], columns["y"][0], "o", color=color, ms=6, label="start")
    ax.plot(columns["x"], columns["y"], color=color, lw=1.6, label=label)
    ax.set(xlabel="x [m]", ylabel="y [m]", aspect="equal")
    if title or new:  # an overlay keeps the figure's title
        ax.set_title(title or "path")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    return fig


def plot_states(columns: Columns, axes: Sequence[Axes] | None = None, *, label: str = "robot", color: str = ROBOT,
                reference: bool = True) -> Figure:
    """x, y and theta against time, with the reference (the paper's Figs. 11 and 15)."""
    fig, axes = _stack(axes, 3)
    for ax, (name, unit) in zip(axes, (("x", "m"), ("y", "m"), ("theta", "rad")), strict=True):
        if reference:
            ax.plot(columns["t"], columns[f"{name}_ref"], "--", color=REFERENCE, lw=1.2, label="reference")
        ax.plot(columns["t"], columns[name], color=color, lw=1.4, label=label)
        ax.set_ylabel(f"{name} [{unit}]")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="best", fontsize=8)
    axes[-1].set_xlabel("t [s]")
    return fig


def plot_errors(columns: Columns, axes: Sequence[Axes] | None = None, *,
                window: tuple[float, float] | None = None, label: str = "robot", color: str = ROBOT) -> Figure:
    """Posture errors e_x, e_y, e_theta and e_tr against time (the paper's Figs. 12 and 16);
    the metric window is shaded."""
    fig, axes = _stack(axes, 4)
    for ax, (name, unit) in zip(axes, (("e_x", "m"), ("e_y", "m"), ("e_theta", "rad"), ("e_tr", "m")), strict=True):
        ax.plot(columns["t"], columns[name], color=color, lw=1.2, label=label)
        ax.set_ylabel(f"{name} [{unit}]")
        ax.grid(alpha=0.3)
        if window is not None:
            ax.axvspan(*window, color="#2ca02c", alpha=0.08)
    if np.all(columns["e_tr"] > 0):  # the transient and the steady state differ by orders of magnitude
        axes[-1].set_yscale("log")
    axes[-1].set_xlabel("t [s]")
    return fig


def plot_torques(columns: Columns, axes: Sequence[Axes] | None = None, *, max_torque: float | None = None) -> Figure:
    """Wheel torques tau_R and tau_L against time, with the actuator limit."""
    fig, axes = _stack(axes, 2)
    for ax, name in zip(axes, ("tau_r", "tau_l"), strict=True):
        ax.plot(columns["t"], columns[name], color=ROBOT, lw=1.0)
        if max_torque is not None:
            for limit in (-max_torque, max_torque):
                ax.axhline(limit, color="#d62728", lw=0.8, ls=":")
        ax.set_ylabel(f"{name} [N m]")
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("t [s]")
    return fig


def plot_gains(columns: Columns, axes: Sequence[Axes] | None = None, *, label: str = "gains",
               color: str = ADAPTIVE) -> Figure:
    """The gains Kx, Ky, Ktheta against time (the paper's Figs. 13 and 17)."""
    fig, axes = _stack(axes, 3)
    for ax, name in zip(axes, ("kx", "ky", "ktheta"), strict=True):
        ax.plot(columns["t"], columns[name], color=color, lw=1.4, label=label)
        ax.set_ylabel(name.replace("k", "K_", 1))
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("t [s]")
    return fig
