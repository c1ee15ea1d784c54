"""Figures of a run, from its time-series columns (:func:`ddtrack.sim.timeseries` or a Parquet file).

Every function takes ``ax``/``axes=None``, returns the figure and never calls ``show()``. Importing this module
leaves Matplotlib's backend alone (a notebook keeps its inline one); the ``ddtrack`` command draws headless
(``MPLBACKEND=Agg`` unless you set another).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

Columns = Mapping[str, np.ndarray]
ROBOT, REFERENCE, ADAPTIVE = "#1f77b4", "#444444", "#d62728"


#: fixed margins in inches (left, right, bottom, top: the title and the legend row), set once per figure: a layout
#: engine would measure every label on every draw (constrained layout took about a third of the drawing time)
MARGINS = (0.85, 0.2, 0.5, 0.75)
PANEL_GAP = 0.25  #: between stacked panels [in]


def _fixed_margins(fig: Figure, gap: float = PANEL_GAP) -> None:
    width, height = fig.get_size_inches()
    left, right, bottom, top = MARGINS
    fig.subplots_adjust(
        left=left / width,
        right=1 - right / width,
        bottom=bottom / height,
        top=1 - top / height,
        hspace=gap / ((height - top - bottom) / max(1, len(fig.axes)) - gap),
    )


def root_figure(ax: Axes) -> Figure:
    """The top-level figure holding ``ax`` (the one to save), also when ``ax`` sits in a subfigure."""
    return ax.figure.figure  # a Figure's .figure is itself, a SubFigure's is its root


def _axes(ax: Axes | None, *, figsize: tuple[float, float]) -> tuple[Figure, Axes]:
    if ax is None:
        fig, ax = plt.subplots(figsize=figsize)
        _fixed_margins(fig)
        return fig, ax
    return root_figure(ax), ax


def _stack(axes: Sequence[Axes] | None, n: int, title: str = "") -> tuple[Figure, Sequence[Axes]]:
    if axes is None:
        fig, grid = plt.subplots(n, 1, sharex=True, figsize=(7, 1.9 * n + 0.6), squeeze=False)
        _fixed_margins(fig)
        if title:
            fig.suptitle(title, fontsize=11, y=1 - 0.12 / fig.get_size_inches()[1], va="top")
        return fig, list(grid[:, 0])
    return root_figure(axes[0]), axes


def _legend_above(ax: Axes, columns: int = 4) -> None:
    """The legend in one row above the axes, where it hides no data (nor the path's start marker)."""
    ax.legend(loc="lower left", bbox_to_anchor=(0.0, 1.01), ncol=columns, fontsize=8, frameon=False, borderaxespad=0.0)


def plot_path(
    columns: Columns,
    ax: Axes | None = None,
    *,
    title: str = "",
    label: str = "robot",
    color: str = ROBOT,
    reference: bool = True,
) -> Figure:
    """The robot's path against the reference in the plane (the paper's Figs. 10 and 14).

    Call again with ``ax`` and ``reference=False`` to overlay another run.
    """
    new = ax is None
    fig, ax = _axes(ax, figsize=(6, 6.4))
    if reference:
        ax.plot(columns["x_ref"], columns["y_ref"], "--", color=REFERENCE, lw=1.2, label="reference")
        ax.plot(columns["x_ref"][0], columns["y_ref"][0], "s", color=REFERENCE, ms=5, mfc="none")
        ax.plot(columns["x"][0], columns["y"][0], "o", color=color, ms=6, label="start")
    ax.plot(columns["x"], columns["y"], color=color, lw=1.6, label=label)
    ax.set(xlabel="x [m]", ylabel="y [m]", aspect="equal")
    if new:  # above the legend row; an overlay keeps the figure's title
        fig.suptitle(title or "path", fontsize=11, y=1 - 0.12 / fig.get_size_inches()[1], va="top")
    elif title:  # the user's own axes, perhaps one of several
        ax.set_title(title)
    ax.grid(alpha=0.3)
    _legend_above(ax)
    return fig


STATES = (("x", "m"), ("y", "m"), ("theta", "rad"), ("v", "m/s"), ("omega", "rad/s"))


def plot_states(
    columns: Columns,
    axes: Sequence[Axes] | None = None,
    *,
    label: str = "robot",
    color: str = ROBOT,
    reference: bool = True,
    title: str = "",
) -> Figure:
    """x, y, theta (continuous), v and omega against time, with their references (the paper's Figs. 11 and 15,
    and the velocities the dynamic layer tracks); the states a column set lacks are left out."""
    shown = [(name, unit) for name, unit in STATES if name in columns]
    fig, axes = _stack(axes, len(shown), title)
    for ax, (name, unit) in zip(axes, shown, strict=False):
        if reference and f"{name}_ref" in columns:
            ax.plot(columns["t"], columns[f"{name}_ref"], "--", color=REFERENCE, lw=1.2, label="reference")
        ax.plot(columns["t"], columns[name], color=color, lw=1.4, label=label)
        ax.set_ylabel(f"{name} [{unit}]")
        ax.grid(alpha=0.3)
    _legend_above(axes[0])
    axes[-1].set_xlabel("t [s]")
    return fig


def plot_errors(
    columns: Columns,
    axes: Sequence[Axes] | None = None,
    *,
    window: tuple[float, float] | None = None,
    label: str = "robot",
    color: str = ROBOT,
    title: str = "",
) -> Figure:
    """Posture errors e_x, e_y, e_theta and e_tr against time (the paper's Figs. 12 and 16);
    the metric window is shaded, with a legend entry."""
    fig, axes = _stack(axes, 4, title)
    for ax, (name, unit) in zip(axes, (("e_x", "m"), ("e_y", "m"), ("e_theta", "rad"), ("e_tr", "m")), strict=True):
        ax.plot(columns["t"], columns[name], color=color, lw=1.2, label=label)
        ax.set_ylabel(f"{name} [{unit}]")
        ax.grid(alpha=0.3)
        if window is not None:
            ax.axvspan(*window, color="#2ca02c", alpha=0.08, label=f"metric window [{window[0]:g}, {window[1]:g}] s")
    if np.all(columns["e_tr"] > 0):  # the transient and the steady state differ by orders of magnitude
        axes[-1].set_yscale("log")
    _legend_above(axes[0])
    axes[-1].set_xlabel("t [s]")
    return fig


def plot_torques(
    columns: Columns, axes: Sequence[Axes] | None = None, *, max_torque: float | None = None, title: str = ""
) -> Figure:
    """Wheel torques tau_R and tau_L against time. The actuator limit is drawn (with a legend entry) when the
    torques come within half of it; otherwise the axis fits the torques and the legend says the limit is off scale."""
    fig, axes = _stack(axes, 2, title)
    peak = float(np.nanmax(np.abs([columns["tau_r"], columns["tau_l"]]))) if len(columns["t"]) else 0.0
    for ax, name in zip(axes, ("tau_r", "tau_l"), strict=True):
        ax.plot(columns["t"], columns[name], color=ROBOT, lw=1.0, label="applied torque")
        if max_torque is not None and np.isfinite(max_torque):
            if peak >= 0.5 * max_torque:
                for sign in (-1.0, 1.0):
                    ax.axhline(
                        sign * max_torque,
                        color="#d62728",
                        lw=0.8,
                        ls=":",
                        label=f"limit ±{max_torque:.3g} N m" if sign > 0 else None,
                    )
            else:  # a limit far above the torques would flatten them to a line
                ax.plot([], [], color="#d62728", lw=0.8, ls=":", label=f"limit ±{max_torque:.3g} N m (off scale)")
        ax.set_ylabel(f"{name} [N m]")
        ax.grid(alpha=0.3)
    _legend_above(axes[0])
    axes[-1].set_xlabel("t [s]")
    return fig


def plot_gains(
    columns: Columns,
    axes: Sequence[Axes] | None = None,
    *,
    label: str = "gains",
    color: str = ADAPTIVE,
    title: str = "",
) -> Figure:
    """The gains Kx, Ky, Ktheta against time (the paper's Figs. 13 and 17)."""
    fig, axes = _stack(axes, 3, title)
    for ax, name in zip(axes, ("kx", "ky", "ktheta"), strict=True):
        ax.plot(columns["t"], columns[name], color=color, lw=1.4, label=label)
        ax.set_ylabel(name.replace("k", "K_", 1))
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("t [s]")
    return fig
