"""What an animation shows: the run read back, the frames chosen, the robot's footprint, and the figure (map,
magnified view, gains) whose moving artists each frame updates.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.colors import to_rgba
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Polygon

from .._format import significant
from ..errors import ConfigError
from ..plotting import ADAPTIVE, REFERENCE, ROBOT
from ..scenario import Scenario, load_scenario

Columns = Mapping[str, np.ndarray]
GAINS = ("kx", "ky", "ktheta")
MAX_FRAMES = 600  #: default bound on the frame count: a GIF of 600 frames is a few MB
TRAIL_SECONDS = 8.0  #: how far back the fading trail reaches [s]
TRAIL_POINTS = 100  #: samples of the trail drawn per frame (enough for a smooth fade)
ZOOM_BEYOND = 40  #: a magnified view is added when the map spans more than this many half axles (the body
#: is then under about 25 pixels wide)
ZOOM_SIZE = 0.36  #: side of the magnified view, as a fraction of the map's
SUFFIXES = (".gif", ".mp4")
WHEEL = "#222222"


@dataclass(frozen=True)
class AnimationInfo:
    """What :func:`animate` wrote.

    Attributes
    ----------
    path : Path
        The animation file.
    frames : int
        Number of frames.
    fps : float
        Frames per second of the file [1/s].
    speed : float
        Simulated seconds per second of playback; above the requested speed when ``max_frames`` bound the
        frame count.
    """

    path: Path
    frames: int
    fps: float
    speed: float


def read_run(folder: str | Path) -> tuple[dict[str, np.ndarray], Scenario]:
    """The time-series columns and the resolved scenario of a run folder (``ddtrack run --out DIR``).

    Parameters
    ----------
    folder : str or Path
        A run folder holding ``timeseries.parquet`` and ``scenario.toml``.

    Returns
    -------
    columns : dict of str to ndarray
        Every column of ``timeseries.parquet``, float64.
    scenario : Scenario
        ``scenario.toml``, validated.

    Raises
    ------
    ConfigError
        Naming what is missing or unreadable.
    """
    import pyarrow.parquet as pq

    folder = Path(folder)
    if not folder.is_dir():
        raise ConfigError("", f"'{folder}' is not a folder", "give a run folder written by `ddtrack run --out DIR`")
    missing = [name for name in ("timeseries.parquet", "scenario.toml") if not (folder / name).is_file()]
    if missing:
        raise ConfigError(
            "",
            f"'{folder}' is not a run folder: {' and '.join(missing)} missing",
            "give a folder written by `ddtrack run --out DIR`",
        )
    try:
        table = pq.read_table(folder / "timeseries.parquet")
    except (OSError, ValueError) as exc:  # pyarrow's ArrowInvalid is a ValueError
        raise ConfigError("", f"'{folder / 'timeseries.parquet'}' cannot be read as Parquet ({exc})") from None
    columns = {name: table.column(name).to_numpy().astype(float) for name in table.column_names}
    needed = [name for name in ("t", "x", "y", "theta", "x_ref", "y_ref", "theta_ref", "e_tr") if name not in columns]
    if needed:
        raise ConfigError("", f"'{folder / 'timeseries.parquet'}' lacks the columns {', '.join(needed)}")
    if columns["t"].size == 0:
        raise ConfigError("", f"'{folder / 'timeseries.parquet'}' holds no rows")
    return columns, load_scenario(folder / "scenario.toml")


def frame_indices(t: np.ndarray, *, fps: float, speed: float, max_frames: int = MAX_FRAMES) -> tuple[np.ndarray, float]:
    """Rows of the time series shown by each frame, and the playback speed they give.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times, increasing [s].
    fps : float
        Frames per second of playback [1/s], > 0.
    speed : float
        Simulated seconds per second of playback, > 0 (1 is real time).
    max_frames : int
        Bound on the frame count, >= 2; a run that would need more plays faster.

    Returns
    -------
    indices : ndarray of int, shape (n_frames,)
        Non-decreasing rows, the first and the last included: the row whose time is nearest each frame's time.
    speed : float
        The playback speed of those frames (``speed``, or higher when ``max_frames`` bound them).
    """
    t = np.asarray(t, dtype=float)
    if t.size == 0:
        raise ValueError("the time series is empty")
    if not (fps > 0 and speed > 0 and max_frames >= 2):
        raise ValueError(f"need fps > 0, speed > 0, max_frames >= 2 (got {fps}, {speed}, {max_frames})")
    duration = float(t[-1] - t[0])
    step = speed / fps  # simulated seconds per frame
    n = int(np.floor(duration / step + 1e-9)) + 1
    if n > max_frames:
        n, step = max_frames, duration / (max_frames - 1)
    times = t[0] + step * np.arange(n)
    if duration > 0 and times[-1] < t[-1] - 1e-9:
        times = np.append(times, t[-1])  # the last frame shows how the run ended
        if times.size > max_frames:
            times = np.linspace(t[0], t[-1], max_frames)
            step = duration / (max_frames - 1)
    right = np.clip(np.searchsorted(t, times), 0, t.size - 1)
    left = np.maximum(right - 1, 0)
    rows = np.where(np.abs(t[left] - times) <= np.abs(t[right] - times), left, right)
    return rows, step * fps  # a row may repeat (a slow-motion frame rate above the sampling rate)


def footprint(x: float, y: float, theta: float, *, half_axle: float, wheel_radius: float) -> dict[str, np.ndarray]:
    """Outline of the robot at pose (x, y, theta) in world coordinates.

    Parameters
    ----------
    x, y : float
        Position of the axle midpoint [m].
    theta : float
        Heading [rad].
    half_axle : float
        L, half the wheel separation [m] (the wheels' mid-planes are at +-L).
    wheel_radius : float
        R [m]; a wheel is drawn 2R long and R/2 wide.

    Returns
    -------
    dict
        ``body`` (4, 2) corners of the chassis, ``right_wheel`` and ``left_wheel`` (4, 2) corners of the
        wheels [m], ``arrow`` (2, 2): the heading arrow's tail and tip [m].
    """
    L, R = half_axle, wheel_radius
    wheel_w = 0.5 * R
    body_half_width = max(L - wheel_w, 0.5 * L)  # inside the wheels
    rear, front = -0.7 * L, 0.9 * L

    def box(x0: float, x1: float, y0: float, y1: float) -> np.ndarray:
        return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])

    c, s = np.cos(theta), np.sin(theta)
    rotation = np.array([[c, -s], [s, c]])

    def world(points: np.ndarray) -> np.ndarray:
        return points @ rotation.T + np.array([x, y])

    return {
        "body": world(box(rear, front, -body_half_width, body_half_width)),
        "right_wheel": world(box(-R, R, -L - wheel_w / 2, -L + wheel_w / 2)),
        "left_wheel": world(box(-R, R, L - wheel_w / 2, L + wheel_w / 2)),
        "arrow": world(np.array([[0.0, 0.0], [1.6 * L, 0.0]])),
    }


def gains_moved(columns: Columns) -> bool:
    """True when the columns hold ``kx, ky, ktheta`` and at least one of them changed during the run."""
    return all(name in columns for name in GAINS) and any(np.ptp(np.asarray(columns[n], float)) > 0 for n in GAINS)


def _limits(columns: Columns, margin: float) -> tuple[tuple[float, float], tuple[float, float]]:
    xs = np.concatenate([columns["x"], columns["x_ref"]])
    ys = np.concatenate([columns["y"], columns["y_ref"]])
    xs, ys = xs[np.isfinite(xs)], ys[np.isfinite(ys)]
    return (xs.min() - margin, xs.max() + margin), (ys.min() - margin, ys.max() + margin)


def _figure_size(aspect: float, with_gains: bool, dpi: float) -> tuple[float, float]:
    """Width and height [in]: 6.4 wide for the map alone, its height following the map's aspect (height / width)
    within limits; 10.8 x 5.6 with the gains panel. Whole pixels, an even number of them (as H.264 needs)."""
    width, height = (10.8, 5.6) if with_gains else (6.4, 1.4 + 4.6 * min(max(aspect, 0.45), 1.2))
    return 2 * round(width * dpi / 2) / dpi, 2 * round(height * dpi / 2) / dpi


def _emptiest_corner(
    c: Columns, x_lim: tuple[float, float], y_lim: tuple[float, float], *, size: float
) -> tuple[float, float, float, float]:
    """Where, in axes fractions, a square inset of side ``size`` covers the fewest points of either path: a
    corner, an edge's middle or the centre (the inside of a square path), preferring the lower right."""
    points = np.concatenate([np.column_stack([c["x"], c["y"]]), np.column_stack([c["x_ref"], c["y_ref"]])])
    points = points[np.all(np.isfinite(points), axis=1)]
    fraction = (points - [x_lim[0], y_lim[0]]) / [np.ptp(x_lim), np.ptp(y_lim)]
    pad = 0.02
    places = [(a, b) for b in (pad, (1 - size) / 2, 1 - size - pad) for a in (1 - size - pad, pad, (1 - size) / 2)]
    covered = [
        np.count_nonzero(
            np.all((fraction >= [a - pad, b - pad]) & (fraction <= [a + size + pad, b + size + pad]), axis=1)
        )
        for a, b in places
    ]
    a, b = places[int(np.argmin(covered))]  # argmin keeps the first of equals: the preferred order above
    return (a, b, size, size)


class _Robot:
    """The patches of one footprint, moved by :meth:`place`."""

    def __init__(self, ax: Axes, *, half_axle: float, wheel_radius: float, color: str, outline: bool) -> None:
        self.geometry = {"half_axle": half_axle, "wheel_radius": wheel_radius}
        style = (
            {"fill": False, "ec": color, "lw": 1.0, "ls": "--"}
            if outline
            else {"fc": to_rgba(color, 0.55), "ec": color, "lw": 1.2}
        )
        zero = np.zeros((4, 2))
        self.body = Polygon(zero, closed=True, zorder=4, **style)
        wheel_style = style if outline else {"fc": WHEEL, "ec": WHEEL, "lw": 0.8}
        self.wheels = [Polygon(zero, closed=True, zorder=5, **wheel_style) for _ in range(2)]
        for patch in (self.body, *self.wheels):
            ax.add_patch(patch)
        self.arrow = None if outline else ax.add_line(Line2D([], [], color=color, lw=1.6, zorder=6))
        self.tip = None if outline else ax.add_line(Line2D([], [], marker=(3, 0, 0), ms=6, color=color, zorder=6))

    def place(self, x: float, y: float, theta: float) -> None:
        shape = footprint(x, y, theta, **self.geometry)
        self.body.set_xy(shape["body"])
        self.wheels[0].set_xy(shape["right_wheel"])
        self.wheels[1].set_xy(shape["left_wheel"])
        if self.arrow is not None and self.tip is not None:
            self.arrow.set_data(shape["arrow"][:, 0], shape["arrow"][:, 1])
            self.tip.set_data([shape["arrow"][1, 0]], [shape["arrow"][1, 1]])
            self.tip.set_marker((3, 0, np.degrees(theta) - 90.0))  # a triangle pointing along the heading

    @property
    def artists(self) -> list:
        """Every artist of the footprint, in drawing order."""
        return [self.body, *self.wheels, *(a for a in (self.arrow, self.tip) if a is not None)]


@dataclass
class _Scene:
    fig: Figure
    canvas: FigureCanvasAgg  #: the figure's own Agg canvas, which blitting needs
    draw: Callable[[int], None]  #: updates every moving artist to a row of the time series
    moving: list  #: the artists draw() changes, in drawing order


def _scene(columns: Columns, *, half_axle: float, wheel_radius: float, title: str, zoom: bool, dpi: float) -> _Scene:
    missing = [name for name in ("t", "x", "y", "theta", "x_ref", "y_ref", "theta_ref", "e_tr") if name not in columns]
    if missing:
        raise ValueError(f"the time series lacks the columns {', '.join(missing)}")
    c = {name: np.asarray(value, dtype=float) for name, value in columns.items()}
    t = c["t"]
    with_gains = gains_moved(c)
    x_lim, y_lim = _limits(c, margin=2.5 * half_axle)
    # a figure of its own on an Agg canvas, outside pyplot: blitting needs Agg, whatever the user's backend
    fig = Figure(figsize=_figure_size(np.ptp(y_lim) / np.ptp(x_lim), with_gains, dpi), dpi=dpi, layout="constrained")
    canvas = FigureCanvasAgg(fig)
    if with_gains:
        grid = fig.add_gridspec(3, 2, width_ratios=(1.35, 1.0))
        ax = fig.add_subplot(grid[:, 0])
        gain_axes = [fig.add_subplot(grid[i, 1]) for i in range(3)]
    else:
        ax, gain_axes = fig.add_subplot(), []
    if title:
        fig.suptitle(title, fontsize=11)

    ax.set(xlim=x_lim, ylim=y_lim, aspect="equal", xlabel="x [m]", ylabel="y [m]")
    ax.grid(alpha=0.25)
    ax.plot(c["x_ref"], c["y_ref"], "--", color=REFERENCE, lw=1.0, label="reference", zorder=1)
    views = [ax]
    zoom_ax = None
    if zoom and max(np.ptp(x_lim), np.ptp(y_lim)) > ZOOM_BEYOND * half_axle:
        zoom_ax = ax.inset_axes(_emptiest_corner(c, x_lim, y_lim, size=ZOOM_SIZE))
        zoom_ax.set(aspect="equal", xticks=[], yticks=[])
        zoom_ax.set_facecolor("#fbfbfb")
        for side in zoom_ax.spines.values():
            side.set_color("#999999")
        zoom_ax.plot(c["x_ref"], c["y_ref"], "--", color=REFERENCE, lw=1.0, zorder=1)
        zoom_ax.text(0.03, 0.97, "zoom", transform=zoom_ax.transAxes, ha="left", va="top", fontsize=7, color="#777777")
        views.append(zoom_ax)

    travelled = [view.plot(c["x"][:1], c["y"][:1], color=ROBOT, lw=0.6, alpha=0.35, zorder=2)[0] for view in views]
    trails = [LineCollection([], lw=2.2, zorder=3) for _ in views]
    for view, trail in zip(views, trails, strict=True):
        view.add_collection(trail)
    ghosts = [
        _Robot(view, half_axle=half_axle, wheel_radius=wheel_radius, color=REFERENCE, outline=True) for view in views
    ]
    robots = [
        _Robot(view, half_axle=half_axle, wheel_radius=wheel_radius, color=ROBOT, outline=False) for view in views
    ]
    ax.plot([], [], color=ROBOT, lw=2.2, label="robot and its trail")  # legend entries for the patches
    ax.plot([], [], ls="none", marker="s", mfc="none", mec=REFERENCE, label="reference pose")
    fig.legend(loc="outside lower center", ncols=3, fontsize=8, frameon=False)  # off the map: a robot never hides it
    clock = ax.text(0.0, 1.015, "", transform=ax.transAxes, ha="left", va="bottom", fontsize=9, family="monospace")

    cursors = []
    for gain_ax, name, label in zip(gain_axes, GAINS, ("$K_x$", "$K_y$", r"$K_\theta$"), strict=False):
        gain_ax.plot(t, c[name], color=ADAPTIVE, lw=0.9, alpha=0.3)
        (done,) = gain_ax.plot(t[:1], c[name][:1], color=ADAPTIVE, lw=1.6)
        cursors.append((gain_ax.axvline(t[0], color="#555555", lw=0.8), done, c[name]))
        gain_ax.set_ylabel(label)
        gain_ax.set_xlim(t[0], max(t[-1], t[0] + 1e-9))  # a one-row run has no time span
        gain_ax.grid(alpha=0.3)
    if gain_axes:
        gain_axes[0].set_title("adapted gains", fontsize=10)
        for gain_ax in gain_axes[:-1]:
            gain_ax.tick_params(labelbottom=False)
        gain_axes[-1].set_xlabel("t [s]")

    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    trail_rows = max(round(TRAIL_SECONDS / dt), 2)
    zoom_half = 4.0 * half_axle
    robot_color = np.asarray(to_rgba(ROBOT))

    def draw(row: int) -> None:
        first = max(row - trail_rows, 0)
        rows = np.arange(row, first - 1, -max((row - first) // TRAIL_POINTS, 1))[::-1]
        points = np.column_stack([c["x"][rows], c["y"][rows]])
        segments = np.stack([points[:-1], points[1:]], axis=1)
        colors = np.tile(robot_color, (len(segments), 1))
        colors[:, 3] = np.linspace(0.05, 1.0, len(segments))  # fading towards the past
        for line, trail in zip(travelled, trails, strict=True):
            line.set_data(c["x"][: row + 1], c["y"][: row + 1])
            trail.set_segments(list(segments))
            trail.set_color(colors)  # type: ignore[arg-type]  # an (N, 4) RGBA array, as LineCollection documents
        for ghost, robot in zip(ghosts, robots, strict=True):
            ghost.place(c["x_ref"][row], c["y_ref"][row], c["theta_ref"][row])
            robot.place(c["x"][row], c["y"][row], c["theta"][row])
        if zoom_ax is not None:
            zoom_ax.set_xlim(c["x"][row] - zoom_half, c["x"][row] + zoom_half)
            zoom_ax.set_ylim(c["y"][row] - zoom_half, c["y"][row] + zoom_half)
        clock.set_text(f"t = {t[row]:6.2f} s    e_tr = {significant(c['e_tr'][row])} m")
        for cursor, done, values in cursors:
            cursor.set_xdata([t[row], t[row]])
            done.set_data(t[: row + 1], values[: row + 1])

    draw(0)
    main = [travelled[0], trails[0], *ghosts[0].artists, *robots[0].artists]
    moving = [
        *main,
        *([zoom_ax] if zoom_ax is not None else []),
        clock,
        *(artist for cursor, done, _ in cursors for artist in (done, cursor)),
    ]
    return _Scene(fig, canvas, draw, moving)


def animation_figure(
    columns: Columns, *, half_axle: float, wheel_radius: float, title: str = "", zoom: bool = True, dpi: float = 100
) -> tuple[Figure, Callable[[int], None]]:
    """The animation's figure and ``draw(row)``, which shows the run at that row of the time series.

    Parameters
    ----------
    columns : mapping of str to ndarray
        Time-series columns of a run: at least ``t, x, y, theta, x_ref, y_ref, theta_ref, e_tr`` [s, m, rad];
        ``kx, ky, ktheta`` add the gains panel when they moved.
    half_axle, wheel_radius : float
        The robot's L and R [m], as in its scenario's ``[plant]`` (or ``[robot]``).
    title : str
        Figure title, e.g. the scenario name and the controller.
    zoom : bool
        Add a magnified view following the robot when the path is much larger than the robot.
    dpi : float
        Resolution [dots per inch]; the figure is 6.4 inches wide, its height following the map's aspect;
        10.8 x 5.6 inches with the gains panel.

    Returns
    -------
    fig : Figure
        The figure, showing the first row.
    draw : callable
        ``draw(row)`` moves every artist to row ``row`` (0 <= row < N); then ``fig.savefig`` a frame.
    """
    scene = _scene(columns, half_axle=half_axle, wheel_radius=wheel_radius, title=title, zoom=zoom, dpi=dpi)
    return scene.fig, scene.draw
