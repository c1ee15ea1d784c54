"""``ddtrack report DIR``: one self-contained HTML page for a run, ``reproduce``, ``mc`` or ``bench`` folder.

The folder's kind is read from the files it holds (:data:`KINDS`). The figures are drawn again from the
folder's data (``timeseries.parquet``, ``runs.parquet``, ``results.parquet``, ``table1.json``) with
:mod:`ddtrack.plotting` and matplotlib, and inlined as SVG; a ``reproduce`` folder keeps no time series, so its
PNG figures are inlined as ``data:`` images. The page has inline CSS, no script and no external URL, and its
Content-Security-Policy forbids both: it opens offline, and nothing from a user file can run in it.

Trust boundary: the Jinja2 environment escapes every value the template prints (``autoescape=True``, not chosen
by file name). The only markup printed unescaped is what this module wraps in :class:`markupsafe.Markup`: the
SVG that matplotlib writes (matplotlib escapes the text it draws, including names and labels taken from user
files) and the ``<img>`` of a PNG read from the folder as base64. The template holds no ``|safe``.
"""

from __future__ import annotations

import base64
import datetime as dt
import io
import itertools
import json
import math
import re
import tomllib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from jinja2 import Environment, FileSystemLoader, StrictUndefined
from markupsafe import Markup
from matplotlib.colors import LogNorm

from ._format import significant
from .errors import RunError
from .metrics import improvement
from .outdir import atomic_write, check_writable
from .plotting import ADAPTIVE, ROBOT, plot_errors, plot_gains, plot_path, plot_states, plot_torques, plt, root_figure
from .sim import REMEDIES

#: folder kind -> the files that identify it (all must be present); checked in this order
KINDS: dict[str, tuple[str, ...]] = {
    "bench": ("leaderboard.json", "results.parquet"),
    "reproduce": ("table1.json",),
    "mc": ("summary.json", "runs.parquet"),
    "run": ("scenario.toml", "metrics.json", "timeseries.parquet"),
}
DESCRIPTIONS = {
    "run": "a run folder (ddtrack run)",
    "reproduce": "a reproduce folder (ddtrack reproduce)",
    "mc": "an mc folder (ddtrack mc)",
    "bench": "a bench folder (ddtrack bench)",
}
TEMPLATES = Path(__file__).resolve().parent / "templates"
MAX_POINTS = 1500  #: samples per plotted series: a 40 s run at T_c = 0.01 s has 4001; SVG grows with every vertex
MAX_RUN_ROWS = 200  #: rows of the per-run table of an mc folder (all runs stay in runs.csv)
MAX_PNG_BYTES = 5_000_000  #: a larger PNG in a reproduce folder is left out (the page would not stay light)
PALETTE = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf", "#7f7f7f", "#bcbd22")
METRICS = (  # metrics.json key, label, unit, scale
    ("e_tr_mean", "mean e_tr", "m", 1.0),
    ("e_tr_rms", "RMS e_tr", "m", 1.0),
    ("e_tr_max", "max e_tr", "m", 1.0),
    ("e_tr_final", "final e_tr", "m", 1.0),
    ("settling_time", "settling time", "s", 1.0),
    ("effort", "effort (integral of tau_R² + tau_L²)", "N² m² s", 1.0),
    ("saturation_fraction", "time saturated", "%", 100.0),
    ("failure_time", "failure time", "s", 1.0),
)
GAIN_NAMES = ("Kx", "Ky", "Kθ")


# --- the page model: what the template prints (every str is escaped by the template) -------------------------


@dataclass(frozen=True)
class Cell:
    """A table cell with a second, smaller line (a confidence interval)."""

    text: str
    detail: str = ""


@dataclass(frozen=True)
class Table:
    """A table; the first ``left`` columns are text (left-aligned), the others numbers (right-aligned)."""

    id: str
    head: tuple[str, ...]
    rows: tuple[tuple[str | Cell, ...], ...]
    caption: str = ""
    left: int = 1
    collapsed: bool = False  #: inside a closed <details> (long tables)
    nowrap: int = 1  #: leading columns kept on one line (names)


@dataclass(frozen=True)
class Figure:
    """A figure and its caption; ``markup`` is trusted (made by :func:`svg` or :func:`png`)."""

    id: str
    caption: str
    markup: Markup  #: an <svg> drawn here or an <img> with a data: URI; never text from a file
    wide: bool = False  #: across the whole section (several panels)


@dataclass(frozen=True)
class Section:
    """One titled part of the page: notes, tables, figures, and optionally a file shown verbatim."""

    id: str
    title: str
    notes: tuple[str, ...] = ()
    tables: tuple[Table, ...] = ()
    figures: tuple[Figure, ...] = ()
    code: str = ""  #: preformatted text (the scenario TOML), shown in a closed <details>
    code_title: str = ""
    layout: str = ""  #: "" (stacked), "grid" (small tables side by side), "side" (tables left, figures right)


@dataclass(frozen=True)
class Card:
    """A headline number at the top of the page."""

    label: str
    value: str
    tone: str = ""  #: "", "good" or "bad" (a CSS class chosen here, never a string from a file)


@dataclass(frozen=True)
class Page:
    """Everything the template prints: the header (what, where, when, which version), cards and sections."""

    kind: str
    title: str
    subtitle: str
    folder: str
    written: str
    generated: str
    version: str
    cards: tuple[Card, ...] = ()
    sections: tuple[Section, ...] = ()


# --- reading the folder ------------------------------------------------------------------------------------


def detect_kind(folder: Path) -> str:
    """The kind of result folder ``folder`` is: ``run``, ``reproduce``, ``mc`` or ``bench``.

    Raises
    ------
    RunError
        When ``folder`` is missing or holds none of the sets of files in :data:`KINDS`; the message lists them.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise RunError(f"'{folder}' is not a folder; give a run, reproduce, mc or bench folder")
    for kind, files in KINDS.items():
        if all((folder / name).is_file() for name in files):
            return kind
    if (folder / "records").is_dir() and (folder / "results.parquet").is_file():  # a sweep has no page of its own
        raise RunError(
            f"'{folder}' is a sweep folder (ddtrack sweep): `ddtrack report` renders run, reproduce, mc "
            "and bench folders, not sweeps\n  hint: a sweep's results are one row per run in "
            f"{folder / 'results.csv'} (and results.parquet); `ddtrack bench` is the sweep with a report"
        )
    expected = "; ".join(f"{DESCRIPTIONS[kind]}: {', '.join(files)}" for kind, files in KINDS.items())
    partial = [kind for kind, files in KINDS.items() if any((folder / name).is_file() for name in files)]
    hint = ""
    if partial:
        kind = partial[0]
        missing = [name for name in KINDS[kind] if not (folder / name).is_file()]
        hint = f"; it looks like {DESCRIPTIONS[kind]} but lacks {', '.join(missing)}"
    raise RunError(f"'{folder}' is not a ddtrack result folder{hint}\n  expected {expected}")


def _read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise RunError(f"cannot read {path}: {exc}") from None


def _read_toml(path: Path) -> tuple[str, dict]:
    try:
        text = path.read_text(encoding="utf-8")
        return text, tomllib.loads(text)
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise RunError(f"cannot read {path}: {exc}") from None


def _read_table(path: Path, required: Sequence[str]) -> pa.Table:
    try:
        table = pq.read_table(path)
    except (OSError, pa.ArrowException) as exc:
        raise RunError(f"cannot read {path}: {exc}") from None
    missing = [name for name in required if name not in table.column_names]
    if missing:
        raise RunError(f"{path} lacks the columns {', '.join(missing)}; was it written by ddtrack?")
    return table


def _field(data: Any, *keys: str, path: Path) -> Any:
    """``data[k1][k2]...``, or a RunError naming the file and the missing key."""
    for key in keys:
        if not isinstance(data, Mapping) or key not in data:
            raise RunError(f"{path} has no '{'.'.join(keys)}'; was it written by ddtrack?")
        data = data[key]
    return data


# --- numbers as text -----------------------------------------------------------------------------------------


def fmt(value: Any, digits: int = 4, scale: float = 1.0) -> str:
    """A value as table text: ``digits`` significant digits (:func:`ddtrack._format.significant`), '–' for a missing
    value."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return significant(value * scale, digits)
    if isinstance(value, list | tuple):
        return _short_list(value)
    return str(value)


def _short_list(values: Sequence[Any], limit: int = 8) -> str:
    shown = ", ".join(fmt(v) for v in values[:limit])
    return f"[{shown}, … {len(values)} items]" if len(values) > limit else f"[{shown}]"


def fmt_ci(stat: Mapping[str, Any] | None, digits: int = 4, scale: float = 1.0) -> str:
    """``mean [ci_low, ci_high]`` of a :func:`ddtrack.metrics.mean_ci` summary; what is missing, said."""
    if not stat or stat["mean"] is None:
        return "–" if not stat or not stat["missing"] else f"n/a ({stat['missing']} missing)"
    text = fmt(stat["mean"], digits, scale)
    if stat["ci_low"] is not None:
        text += f" [{fmt(stat['ci_low'], digits, scale)}, {fmt(stat['ci_high'], digits, scale)}]"
    if stat["missing"]:
        text += f" ({stat['missing']} missing)"
    return text


def ci_cell(stat: Mapping[str, Any] | None, digits: int = 4, scale: float = 1.0) -> Cell:
    """:func:`fmt_ci` as a cell: the mean, and the interval (or what is missing) below it."""
    text = fmt_ci(stat, digits, scale)
    mean, _, rest = text.partition(" ")
    return Cell(mean, rest) if stat and stat["mean"] is not None else Cell(text)


def _mpl(text: str, limit: int = 32) -> str:
    """A string from a file as matplotlib text: at most ``limit`` characters (a long label would squeeze the axes to
    nothing; the tables carry the whole name), and '$' escaped (it would start mathtext, and a bad formula raises)."""
    text = str(text)
    text = text if len(text) <= limit else text[: limit - 1] + "…"
    return text.replace("$", r"\$")


# --- figures as inline SVG -----------------------------------------------------------------------------------


def decimate(columns: Mapping[str, np.ndarray], keys: Sequence[str], max_points: int = MAX_POINTS) -> dict:
    """At most about ``max_points`` samples of every column: per bucket of time, the samples where each of
    ``keys`` is lowest and highest, so peaks (a torque at its limit, an error spike) survive; plus both ends."""
    n = len(columns["t"])
    if n <= max_points:
        return dict(columns)
    buckets = max(1, max_points // (2 * len(keys)))
    edges = np.linspace(0, n, buckets + 1).astype(int)
    keep = {0, n - 1}
    for key in keys:
        values = np.asarray(columns[key], dtype=float)
        for start, stop in itertools.pairwise(edges):
            part = values[start:stop]
            if part.size == 0 or np.all(np.isnan(part)):
                keep.add(int(start))
                continue
            keep.update((start + int(np.nanargmin(part)), start + int(np.nanargmax(part))))
    index = np.array(sorted(keep))
    return {name: np.asarray(values)[index] for name, values in columns.items()}


def _prefix_ids(tag: str, prefix: str) -> str:
    """One SVG tag with its id and its references to ids (``href="#..."``, ``url(#...)``) prefixed."""
    tag = re.sub(r'(\sid=")([^"]+)"', lambda m: f'{m.group(1)}{prefix}-{m.group(2)}"', tag)
    return re.sub(r'(href="#|url\(#)([^")]+)', lambda m: f"{m.group(1)}{prefix}-{m.group(2)}", tag)


def svg(fig: plt.Figure, name: str, label: str) -> Markup:
    """``fig`` as inline SVG markup (closes the figure).

    Text stays text (``svg.fonttype = none``: small, and matplotlib escapes it); the XML prolog, the metadata
    and the comments are dropped; every id gets the prefix ``name`` so several SVGs share one page. ``label``
    (escaped here) becomes the ``aria-label``.
    """
    buffer = io.StringIO()
    with plt.rc_context({"svg.fonttype": "none", "svg.hashsalt": name}):  # deterministic ids
        fig.savefig(buffer, format="svg", metadata={"Date": None})
    plt.close(fig)
    text = buffer.getvalue()
    text = text[text.index("<svg") :]
    text = re.sub(r"<metadata>.*?</metadata>\s*", "", text, flags=re.S)
    text = re.sub(r"<!--.*?-->", "", text, flags=re.S)  # matplotlib's comments repeat the text it draws
    text = re.sub(r"<[^<>]+>", lambda tag: _prefix_ids(tag.group(0), name), text)  # tags only: text stays as drawn
    head_end = text.index(">")
    size = re.search(r'\swidth="([0-9.]+)pt"', text[:head_end])
    if size is None:
        raise ValueError("matplotlib's SVG has no width in pt")  # our own figure: a programming error, not input
    width = float(size.group(1)) * 4 / 3  # [px] CSS: 96 px per 72 pt
    head = re.sub(r'\s(width|height)="[^"]*"', "", text[:head_end])  # the page sizes it; the viewBox keeps its shape
    return (
        Markup(head)
        + Markup(' style="max-width: {:.0f}px" role="img" aria-label="{}"').format(width, label)
        + Markup(text[head_end:].strip())
    )


def png(path: Path, label: str) -> Markup | None:
    """A PNG file as an ``<img>`` with a ``data:`` URI; None if it is not a PNG or too large."""
    data = path.read_bytes()
    if not data.startswith(b"\x89PNG\r\n\x1a\n") or len(data) > MAX_PNG_BYTES:
        return None
    width = int.from_bytes(data[16:20], "big")  # the IHDR chunk comes first: width, height [px]
    uri = "data:image/png;base64," + base64.b64encode(data).decode("ascii")
    return Markup('<img src="{}" alt="{}" style="max-width: {}px">').format(uri, label, width)


def _positive_log(ax: plt.Axes, values: np.ndarray) -> None:
    """Log scale when every value is positive and they span more than a decade."""
    values = values[np.isfinite(values)]
    if values.size and np.all(values > 0) and values.max() > 10 * values.min():
        ax.set_yscale("log")


def plot_distributions(
    groups: Mapping[str, Sequence[float]],
    ax: plt.Axes | None = None,
    *,
    ylabel: str,
    title: str = "",
    reference: float | None = None,
) -> plt.Figure:
    """A box per group with its values as points over it (spread sideways in run order, no randomness).

    The group names are shortened and escaped for matplotlib here; ``title`` is used as given (see :func:`_mpl`).
    """
    if ax is None:
        fig, ax = plt.subplots(figsize=(max(4.5, 0.9 * len(groups) + 2.0), 3.8), layout="constrained")
    else:
        fig = root_figure(ax)
    names = list(groups)
    data = [np.asarray([v for v in groups[name] if v is not None and math.isfinite(v)], dtype=float) for name in names]
    positions = np.arange(1, len(names) + 1)
    present = [i for i, values in enumerate(data) if values.size]
    if present:
        ax.boxplot(
            [data[i] for i in present],
            positions=positions[present],
            widths=0.55,
            showfliers=False,
            medianprops={"color": "#111111"},
            boxprops={"color": "#555555"},
            whiskerprops={"color": "#555555"},
            capprops={"color": "#555555"},
        )
    for i, values in enumerate(data):
        offsets = np.linspace(-0.18, 0.18, values.size) if values.size > 1 else np.zeros(values.size)
        ax.plot(positions[i] + offsets, values, "o", ms=4, alpha=0.75, color=PALETTE[i % len(PALETTE)])
    if reference is not None:
        ax.axhline(reference, color="#888888", lw=0.8, ls="--")
    crowded = len(names) > 3 or (len(names) > 1 and max(len(name) for name in names) > 12)
    ax.set_xticks(
        positions,
        [_mpl(name) for name in names],
        rotation=30 if crowded else 0,
        ha="right" if crowded else "center",
        rotation_mode="anchor" if crowded else "default",
    )
    ax.set_xlim(0.4, len(names) + 0.6)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    ax.grid(axis="y", alpha=0.3)
    _positive_log(ax, np.concatenate([*data, [np.nan]]))
    return fig


# --- run folder ----------------------------------------------------------------------------------------------

SERIES = (
    "t",
    "x",
    "y",
    "theta",
    "v",
    "omega",
    "x_ref",
    "y_ref",
    "theta_ref",
    "v_ref",
    "omega_ref",
    "e_x",
    "e_y",
    "e_theta",
    "e_tr",
    "tau_r",
    "tau_l",
)


def _scenario_section(text: str, data: Mapping[str, Any], path: str) -> Section:
    """The resolved scenario: a small table per TOML section (top-level keys first), and the file itself."""
    top = tuple((str(key), _toml_value(value)) for key, value in data.items() if not isinstance(value, Mapping))
    tables = [Table("scenario-top", ("key", "value"), top, left=2)] if top else []
    for i, (section, values) in enumerate((k, v) for k, v in data.items() if isinstance(v, Mapping)):
        rows = tuple((str(key), _toml_value(value)) for key, value in values.items()) or (("(none)", ""),)
        tables.append(Table(f"scenario-{i}", (f"[{section}]", "value"), rows, left=2))
    return Section(
        "scenario",
        "Scenario",
        (f"As stored in {path}, fully resolved (defaults included).",),
        tables=tuple(tables),
        code=text,
        code_title=f"{path} as written",
        layout="grid",
    )


def _toml_value(value: Any) -> str:
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{k} = {_toml_value(v)}" for k, v in value.items()) + "}"
    if isinstance(value, list) and value and isinstance(value[0], list):
        return _short_list(value, limit=4)
    return fmt(value, digits=10)


def _written(folder: Path, names: Sequence[str]) -> str:
    times = [(folder / name).stat().st_mtime for name in names if (folder / name).is_file()]
    return _utc(max(times)) if times else "unknown"


def _utc(timestamp: float) -> str:
    return dt.datetime.fromtimestamp(timestamp, dt.UTC).strftime("%Y-%m-%d %H:%M UTC")


def _run_page(folder: Path) -> dict:
    text, scenario = _read_toml(folder / "scenario.toml")
    metrics_path, toml_path = folder / "metrics.json", folder / "scenario.toml"
    metrics = _read_json(metrics_path)
    table = _read_table(folder / "timeseries.parquet", SERIES)
    columns = {
        name: table.column(name).to_numpy(zero_copy_only=False).astype(np.float64) for name in table.column_names
    }
    name = str(_field(scenario, "name", path=toml_path))
    controller = _field(scenario, "controller", path=toml_path)
    kind = str(_field(controller, "kind", path=toml_path))
    trajectory = str(_field(scenario, "trajectory", "kind", path=toml_path))
    seed, duration = (_field(scenario, "simulation", key, path=toml_path) for key in ("seed", "duration"))
    status = str(_field(metrics, "status", path=metrics_path))
    window = tuple(_field(metrics, "window", path=metrics_path))

    rows = [("status", status, ""), ("metric window", f"[{fmt(window[0])}, {fmt(window[1])}]", "s")]
    for key, label, unit, scale in METRICS:
        if key in metrics:  # failure_time only where the run failed
            rows.append((label, fmt(metrics[key], scale=scale), unit))
    known = {"status", "window", "final_gains", *(m[0] for m in METRICS)}
    rows += [(key, fmt(value), "") for key, value in metrics.items() if key not in known]
    notes = []
    if status != "ok":
        when = f" at t = {fmt(metrics['failure_time'])} s" if "failure_time" in metrics else ""
        remedy = f" To try: {REMEDIES[status]}." if REMEDIES.get(status) else ""
        notes.append(f"The run stopped{when}: {status}.{remedy}")
    sections = [
        Section(
            "metrics",
            "Metrics",
            (
                *notes,
                "Tracking error e_tr (paper eq. 35) over the metric window; "
                "settling time, effort and saturation over the whole run.",
            ),
            tables=(Table("metrics-table", ("metric", "value", "unit"), tuple(rows)),),
        )
    ]

    figures = [
        Figure(
            "fig-path",
            "Path in the plane: the robot against the reference (dashed).",
            svg(plot_path(decimate(columns, ("x", "y", "x_ref", "y_ref"))), "path", "path in the plane"),
        ),
        Figure(
            "fig-states",
            "x, y, θ, v and ω against time, with the reference (dashed).",
            svg(
                plot_states(
                    decimate(
                        columns, ("x", "y", "theta", "v", "omega", "x_ref", "y_ref", "theta_ref", "v_ref", "omega_ref")
                    )
                ),
                "states",
                "states against time",
            ),
        ),
        Figure(
            "fig-errors",
            "Posture errors and e_tr; the metric window is shaded.",
            svg(
                plot_errors(decimate(columns, ("e_x", "e_y", "e_theta", "e_tr")), window=window),
                "errors",
                "posture errors",
            ),
        ),
    ]
    if np.any(np.isfinite(columns["tau_r"])):  # a velocity-input (kinematic) plant has no torques
        figures.append(
            Figure(
                "fig-torques",
                "Wheel torques; dotted: the actuator limit.",
                svg(
                    plot_torques(decimate(columns, ("tau_r", "tau_l")), max_torque=_max_torque(scenario)),
                    "torques",
                    "wheel torques",
                ),
            )
        )
    sections.append(Section("figures", "Figures", figures=tuple(figures)))

    if "final_gains" in metrics and metrics["final_gains"] is not None:  # only controllers with gains have them
        sections.append(_gains_section(controller, metrics["final_gains"], columns))
    if (folder / "identification.json").is_file():
        sections.append(
            _identification_section(_read_json(folder / "identification.json"), folder / "identification.json")
        )
    sections.append(_scenario_section(text, scenario, "scenario.toml"))

    settle = metrics["settling_time"] if "settling_time" in metrics else None
    cards = (
        Card("status", status, "good" if status == "ok" else "bad"),
        Card("controller", kind),
        Card("trajectory", trajectory),
        Card("mean e_tr", "–" if metrics["e_tr_mean"] is None else f"{fmt(metrics['e_tr_mean'])} m"),
        Card("settling time", f"{fmt(settle)} s" if settle is not None else "never" if status == "ok" else "–"),
    )
    return {
        "title": name,
        "subtitle": f"{kind} on {trajectory}, seed {fmt(seed)}, {fmt(duration)} s",
        "cards": cards,
        "sections": sections,
        "written": _written(folder, KINDS["run"]),
    }


def _gains_section(controller: Mapping[str, Any], final: Sequence[float], columns: Mapping[str, np.ndarray]) -> Section:
    """Initial (scenario) and final (metrics) gains, and the gains figure when they moved."""
    initial = controller["gains"] if "gains" in controller else [None] * len(final)
    rows = []
    for label, start, end in zip(GAIN_NAMES, initial, final, strict=True):
        change = 100.0 * (end - start) / start if isinstance(start, int | float) and start else None
        rows.append((label, fmt(start), fmt(end), fmt(change, 3)))
    moved = all(k in columns for k in ("kx", "ky", "ktheta")) and any(
        np.nanmax(columns[k]) > np.nanmin(columns[k]) for k in ("kx", "ky", "ktheta")
    )
    figures = (
        (
            Figure(
                "fig-gains",
                "The gains against time (the paper's Figs. 13 and 17).",
                svg(plot_gains(decimate(columns, ("kx", "ky", "ktheta"))), "gains", "gains against time"),
            ),
        )
        if moved
        else ()
    )
    return Section(
        "gains",
        "Gains",
        (
            "Initial gains from the scenario, final gains at the end of the run."
            + ("" if moved else " They did not move."),
        ),
        tables=(Table("gains-table", ("gain", "initial", "final", "change [%]"), tuple(rows)),),
        figures=figures,
        layout="side" if figures else "",
    )


def _max_torque(scenario: Mapping[str, Any]) -> float | None:
    """The plant's torque limit: a key left out of [plant] takes the [robot] value (docs/guide.md)."""
    for section in ("plant", "robot"):
        if section in scenario and "max_torque" in scenario[section]:
            return float(scenario[section]["max_torque"])
    return None


def _identification_section(found: Mapping[str, Any], path: Path) -> Section:
    losses = np.asarray(_field(found, "epoch_loss", path=path), dtype=float)
    rows = [
        ("samples", fmt(_field(found, "samples", path=path))),
        ("epochs", fmt(_field(found, "epochs", path=path))),
        ("final loss", fmt(float(losses[-1]) if losses.size else None)),
    ]
    rows += [(f"prediction NMSE, {key}", fmt(value)) for key, value in _field(found, "nmse", path=path).items()]
    fig, ax = plt.subplots(figsize=(6.0, 3.0), layout="constrained")
    ax.plot(np.arange(1, losses.size + 1), losses, color=ROBOT, lw=1.4)
    ax.set(xlabel="epoch", ylabel="mean loss")
    _positive_log(ax, losses)
    ax.grid(alpha=0.3)
    return Section(
        "identification",
        "Emulator identification",
        ("The neural emulator's pre-training before the run: loss per epoch and the prediction NMSE.",),
        tables=(Table("identification-table", ("quantity", "value"), tuple(rows)),),
        figures=(
            Figure("fig-identification", "Training loss per epoch.", svg(fig, "identification", "identification loss")),
        ),
        layout="side",
    )


# --- reproduce folder ----------------------------------------------------------------------------------------


def _reproduce_page(folder: Path) -> dict:
    path = folder / "table1.json"
    table = _read_json(path)
    cases, seeds = _field(table, "cases", path=path), _field(table, "seeds", path=path)
    rows, gain_rows, cards = [], [], [Card("seeds per case", fmt(seeds)), Card("cases", str(len(cases)))]
    for _name, entry in cases.items():
        title, paper, gains = str(entry["title"]), entry["paper"], entry["improvement"]
        for variant, stats in entry["controllers"].items():
            gain = gains[variant] if variant in gains else None  # the baseline has none
            rows.append(
                (
                    title,
                    str(variant),
                    ci_cell(stats["e_tr_mean"]),
                    fmt(paper[variant]) if variant in paper else "",
                    ci_cell(stats["e_tr_rms"]),
                    ci_cell(stats["e_tr_max"]),
                    ci_cell(stats["settling_time"], 3),
                    ci_cell(gain, 3) if gain else "",
                    fmt(paper["improvement"]) if variant == "nn_adaptive" else "",
                )
            )
            for seed, final in enumerate(stats["final_gains"] if "final_gains" in stats else []):
                gain_rows.append((title, str(variant), str(seed), *(fmt(g) for g in (final or [None] * 3))))
        if "nn_adaptive" in gains:
            ours = gains["nn_adaptive"]
            cards.append(
                Card(
                    f"NN-adaptive vs backstepping, {title}",
                    f"{fmt_ci(ours, 3)} % (paper {fmt(paper['improvement'])} %)",
                    "good" if ours["mean"] is not None and ours["mean"] > 0 else "bad",
                )
            )
    windows = ", ".join(f"{entry['title']} {fmt_window(entry['window'])}" for entry in cases.values())
    table1 = Table(
        "table1",
        (
            "case",
            "controller",
            "mean e_tr [m]",
            "paper [m]",
            "RMS e_tr [m]",
            "max e_tr [m]",
            "settling [s]",
            "improvement [%]",
            "paper [%]",
        ),
        tuple(rows),
        left=2,
        nowrap=2,
        caption=f"Ours: mean [95 % CI] over {seeds} seed(s); the paper's Table 1 beside it.",
    )
    sections = [
        Section(
            "table-1",
            "Table 1, reproduced",
            (
                f"Statistic: mean of e_tr over each case's metric window (model.md §4.4): {windows}. "
                "Improvement: 100 (E_BS − E_NN) / E_BS, paired by seed.",
            ),
            tables=(table1,),
            figures=(
                Figure(
                    "fig-table1",
                    "Mean e_tr: ours (bars: mean over seeds; points: each seed) against the paper's (black diamonds).",
                    svg(_table1_figure(cases), "table1", "table 1 as a figure"),
                ),
            ),
        )
    ]
    if gain_rows:
        sections.append(
            Section(
                "gains",
                "Final gains",
                ("The adapted gains at the end of each seed's run.",),
                tables=(Table("gains-table", ("case", "controller", "seed", *GAIN_NAMES), tuple(gain_rows), left=2),),
            )
        )
    images: list[Figure] = []
    files = sorted((folder / "figures").glob("*.png"), key=_figure_order) if (folder / "figures").is_dir() else []
    for file in files:
        markup = png(file, file.stem)
        if markup is not None:
            images.append(Figure(f"png-{len(images)}", _png_caption(file.stem, cases), markup))
    if images:
        sections.append(
            Section(
                "figures",
                "Figures (seed 0)",
                (
                    "A reproduce folder keeps no time series: these "
                    "are its PNG figures (the paper's Figs. 10-17), inlined.",
                ),
                figures=tuple(images),
            )
        )
    subtitle = f"the paper's Table 1 and Figs. 10-17, both controllers on common random numbers, {seeds} seed(s)" + (
        ", with ablations" if table["ablations"] else ""
    )
    return {
        "title": "Reproduction of the paper",
        "subtitle": subtitle,
        "cards": tuple(cards),
        "sections": sections,
        "written": _written(folder, ("table1.json",)),
    }


def fmt_window(window: Any) -> str:
    """A metric window ``[start, end]`` [s] as text."""
    return f"[{fmt(window[0])}, {fmt(window[1])}] s"


def _figure_order(path: Path) -> tuple:
    """Per case: path, states, errors, gains (the paper's order)."""
    kinds = ("path", "states", "errors", "gains")
    case, _, kind = path.stem.rpartition("_")
    return case, kinds.index(kind) if kind in kinds else len(kinds), path.stem


def _png_caption(stem: str, cases: Mapping[str, Any]) -> str:
    words = {
        "path": "path in the plane",
        "states": "states against time",
        "errors": "posture errors",
        "gains": "gains against time",
    }
    case, _, kind = stem.rpartition("_")
    if case in cases and kind in words:
        return f"{cases[case]['title']}: {words[kind]}, backstepping and NN-adaptive backstepping."
    return stem


def _table1_figure(cases: Mapping[str, Any]) -> plt.Figure:
    fig, axes = plt.subplots(1, len(cases), figsize=(3.6 * len(cases) + 0.8, 3.6), layout="constrained", squeeze=False)
    for ax, entry in zip(axes.flat, cases.values(), strict=True):
        paper, variants = entry["paper"], list(entry["controllers"])
        for i, variant in enumerate(variants):
            stat = entry["controllers"][variant]["e_tr_mean"]
            values = np.asarray([v for v in stat["values"] if v is not None], dtype=float)
            color = ROBOT if variant == "backstepping" else ADAPTIVE if variant == "nn_adaptive" else "#7f7f7f"
            if stat["mean"] is not None:
                ax.bar(i, stat["mean"], width=0.6, color=color, alpha=0.45)
            offsets = np.linspace(-0.12, 0.12, values.size) if values.size > 1 else np.zeros(values.size)
            ax.plot(i + offsets, values, "o", ms=4, color=color)
            if variant in paper:
                ax.plot(i, paper[variant], "D", ms=7, color="black", label="paper" if i == 0 else None)
        ax.set_xticks(
            range(len(variants)),
            [_mpl(v) for v in variants],
            rotation=30 if len(variants) > 2 else 0,
            ha="right" if len(variants) > 2 else "center",
        )
        ax.set_title(_mpl(entry["title"]))
        ax.set_ylabel("mean e_tr [m]")
        ax.grid(axis="y", alpha=0.3)
        if any(v in paper for v in variants):
            ax.legend(loc="best", fontsize=8)
    return fig


# --- mc folder -----------------------------------------------------------------------------------------------

MC_STATISTICS = (
    ("e_tr_mean", "mean e_tr [m]"),
    ("e_tr_rms", "RMS e_tr [m]"),
    ("e_tr_max", "max e_tr [m]"),
    ("settling_time", "settling [s]"),
    ("effort", "effort [N² m² s]"),
    ("saturation_fraction", "saturated [%]"),
)
MC_COLUMNS = (
    "controller",
    "seed",
    "status",
    "e_tr_mean",
    "e_tr_max",
    "settling_time",
    "window_start",
    "window_end",
    "final_kx",
    "final_ky",
    "final_ktheta",
)


def _mc_page(folder: Path) -> dict:
    path = folder / "summary.json"
    summary = _read_json(path)
    controllers = _field(summary, "controllers", path=path)
    baseline = str(_field(summary, "improvement_over", path=path))
    gains = _field(summary, "improvement", path=path)
    runs = _read_table(folder / "runs.parquet", MC_COLUMNS).to_pylist()
    by_controller: dict[str, list[dict]] = {str(name): [] for name in controllers}
    for row in runs:
        by_controller.setdefault(str(row["controller"]), []).append(row)
    rows: tuple[tuple[str | Cell, ...], ...] = tuple(
        (
            str(name),
            fmt(len(by_controller[str(name)])),
            fmt(stats["failures"]),
            *(ci_cell(stats[key], scale=100.0 if key == "saturation_fraction" else 1.0) for key, _ in MC_STATISTICS),
        )
        for name, stats in controllers.items()
    )
    tables = [
        Table(
            "mc-table",
            ("controller", "runs", "failures", *(label for _, label in MC_STATISTICS)),
            rows,
            caption="Mean [95 % CI] over runs; failed runs are left out of the means.",
        )
    ]
    if gains:
        tables.append(
            Table(
                "improvement-table",
                ("controller", "over", "improvement [%]", "paired runs"),
                tuple(
                    (str(name), baseline, ci_cell(stat, 3), fmt(stat["paired_runs"])) for name, stat in gains.items()
                ),
                left=2,
                caption="Paired by seed: 100 (E_baseline − E) / E_baseline over the seeds where both runs succeeded.",
            )
        )
    figures = [
        Figure(
            "fig-etr",
            "Mean e_tr of each run, per controller (box: quartiles; points: runs).",
            svg(
                plot_distributions(
                    {n: [r["e_tr_mean"] for r in rs] for n, rs in by_controller.items()},
                    ylabel="mean e_tr per run [m]",
                    title="tracking error",
                ),
                "etr",
                "distribution of the mean tracking error",
            ),
            wide=len(by_controller) > 4,
        )
    ]
    paired = _paired_improvements(by_controller, baseline)
    if any(paired.values()):
        figures.append(
            Figure(
                "fig-improvement",
                f"Improvement of each run over {baseline} on the same seed.",
                svg(
                    plot_distributions(
                        paired,
                        ylabel="improvement [%]",
                        reference=0.0,
                        title=f"paired improvement over {_mpl(baseline)}",
                    ),
                    "improvement",
                    "distribution of the paired improvement",
                ),
                wide=len(by_controller) > 5,
            )
        )
    gain_figure = _final_gains_figure(by_controller)
    if gain_figure is not None:
        figures.append(
            Figure(
                "fig-final-gains",
                "Final gains of each run, for the controllers that have gains.",
                svg(gain_figure, "final-gains", "final gains"),
            )
        )
    sections = [
        Section("summary", "Per controller", tables=tuple(tables)),
        Section("distributions", "Distributions", figures=tuple(figures)),
    ]
    shown = (
        "controller",
        "seed",
        "status",
        "e_tr_mean",
        "e_tr_max",
        "settling_time",
        "final_kx",
        "final_ky",
        "final_ktheta",
    )
    note = (
        f"The first {MAX_RUN_ROWS} of {len(runs)} runs; every run is in runs.csv."
        if len(runs) > MAX_RUN_ROWS
        else "Every run (also in runs.csv and runs.parquet)."
    )
    sections.append(
        Section(
            "runs",
            "Runs",
            (note,),
            tables=(
                Table(
                    "runs-table",
                    shown,
                    tuple(tuple(fmt(r[c]) for c in shown) for r in runs[:MAX_RUN_ROWS]),
                    left=3,
                    nowrap=3,
                    collapsed=True,
                ),
            ),
        )
    )
    if (folder / "scenario.toml").is_file():
        text, scenario = _read_toml(folder / "scenario.toml")
        sections.append(_scenario_section(text, scenario, "scenario.toml"))
    else:
        windows = sorted({(r["window_start"], r["window_end"]) for r in runs if r["window_start"] is not None})
        sections.append(
            Section(
                "scenario",
                "Scenario",
                (
                    "An mc folder does not store its scenario (see the command that wrote it); metric window "
                    + ", ".join(fmt_window(w) for w in windows)
                    + ".",
                ),
            )
        )
    n = max((len(v) for v in by_controller.values()), default=0)
    failures = sum(int(stats["failures"]) for stats in controllers.values())
    cards = [
        Card("runs per controller", fmt(n)),
        Card("controllers", str(len(controllers))),
        Card("baseline", baseline),
    ]
    for name, stat in gains.items():
        cards.append(
            Card(
                f"{name} vs {baseline}",
                f"{fmt_ci(stat, 3)} %",
                "good" if stat["mean"] is not None and stat["mean"] > 0 else "bad",
            )
        )
    cards.append(Card("failed runs", str(failures), "good" if failures == 0 else "bad"))
    return {
        "title": "Monte Carlo",
        "subtitle": f"{n} seeds per controller on common random numbers: " + ", ".join(str(c) for c in controllers),
        "cards": tuple(cards),
        "sections": sections,
        "written": _written(folder, KINDS["mc"]),
    }


def _paired_improvements(by_controller: Mapping[str, list[dict]], baseline: str) -> dict[str, list[float]]:
    """Per controller, 100 (E_baseline - E) / E_baseline for each seed where both have a result."""
    if baseline not in by_controller:
        return {}
    base = {
        r["seed"]: r["e_tr_mean"] for r in by_controller[baseline] if r["e_tr_mean"] is not None and r["e_tr_mean"] > 0
    }
    return {
        name: [
            improvement(base[r["seed"]], r["e_tr_mean"])
            for r in runs
            if r["e_tr_mean"] is not None and r["seed"] in base
        ]
        for name, runs in by_controller.items()
        if name != baseline
    }


def _final_gains_figure(by_controller: Mapping[str, list[dict]]) -> plt.Figure | None:
    keys = ("final_kx", "final_ky", "final_ktheta")
    having = {name: runs for name, runs in by_controller.items() if any(r[k] is not None for r in runs for k in keys)}
    if not having:
        return None
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(max(4.5, 0.9 * len(having) + 2.0), 6.4), layout="constrained")
    for ax, key, label in zip(axes, keys, GAIN_NAMES, strict=True):
        plot_distributions(
            {name: [r[key] for r in runs] for name, runs in having.items()}, ax=ax, ylabel=f"final {label}"
        )
    for ax in axes[:-1]:
        ax.tick_params(labelbottom=False)  # the names once, under the last panel
    return fig


# --- bench folder --------------------------------------------------------------------------------------------

BENCH_COLUMNS = ("controller", "seed", "status", "e_tr_mean", "label.study", "label.trajectory", "label.level")


def _bench_page(folder: Path) -> dict:
    path = folder / "leaderboard.json"
    summary = _read_json(path)
    board = _field(summary, "leaderboard", path=path)
    suite = _field(summary, "suite", path=path)
    table = _read_table(folder / "results.parquet", BENCH_COLUMNS)
    results = table.to_pylist()
    controllers = [str(e["controller"]) for e in board]
    references = sorted(
        {key.removeprefix("improvement_over_") for e in board for key in e if key.startswith("improvement_over_")}
    )
    rows: tuple[tuple[str | Cell, ...], ...] = tuple(
        (
            str(rank),
            str(e["controller"]),
            ci_cell(e["e_tr_mean"]),  # the other statistics' CIs: leaderboard.md
            *(fmt(e[key]["mean"], 3) for key in ("e_tr_rms", "e_tr_max", "effort")),
            fmt(e["saturation_fraction"]["mean"], 2, scale=100.0),
            f"{e['failures']}/{e['runs']}",
            *(ci_cell(e[f"improvement_over_{r}"], 3) for r in references),
        )
        for rank, e in enumerate(board, start=1)
    )
    leaderboard = Table(
        "leaderboard-table",
        (
            "rank",
            "controller",
            "mean e_tr [m]",
            "RMS e_tr [m]",
            "max e_tr [m]",
            "effort [N² m² s]",
            "saturated [%]",
            "failures",
            *(f"vs {r} [%]" for r in references),
        ),
        rows,
        left=2,
        nowrap=2,
        caption="Ranked by mean tracking error: mean [95 % CI] over every leaderboard run (the other "
        "statistics: means); improvements paired by trajectory, uncertainty level and seed.",
    )
    ok = [
        r for r in results if r["label.study"] == "leaderboard" and r["status"] == "ok" and r["e_tr_mean"] is not None
    ]
    cells = sorted({(str(r["label.trajectory"]), str(r["label.level"])) for r in ok})
    means: dict[tuple[str, str, str], list[float]] = {}
    for r in ok:
        means.setdefault((str(r["controller"]), str(r["label.trajectory"]), str(r["label.level"])), []).append(
            r["e_tr_mean"]
        )
    cell_table = Table(
        "cells-table",
        ("controller", *(f"{t} / {lv}" for t, lv in cells)),
        tuple(
            (name, *(fmt(float(np.mean(means[(name, *c)]))) if (name, *c) in means else "–" for c in cells))
            for name in controllers
        ),
        caption="Mean e_tr [m] per trajectory / uncertainty level (mean over seeds; failed runs left out).",
    )
    figures = []
    trajectories = sorted({str(r["label.trajectory"]) for r in ok})
    if trajectories:
        columns = len(trajectories) if len(controllers) * len(trajectories) <= 16 else min(3, len(trajectories))
        panel_rows = -(-len(trajectories) // columns)  # many controllers: panels wrap, three to a row, to stay readable
        fig, axes = plt.subplots(
            panel_rows,
            columns,
            squeeze=False,
            layout="constrained",
            figsize=(min(12.5, max(3.6, 0.4 * len(controllers) + 1.4) * columns), 3.4 * panel_rows + 1.0),
        )
        for i, (ax, trajectory) in enumerate(zip(axes.flat, trajectories, strict=False)):
            plot_distributions(
                {
                    name: [
                        r["e_tr_mean"]
                        for r in ok
                        if str(r["controller"]) == name and str(r["label.trajectory"]) == trajectory
                    ]
                    for name in controllers
                },
                ax=ax,
                ylabel="mean e_tr per run [m]" if i % columns == 0 else "",
                title=_mpl(trajectory),
            )
            if i + columns < len(trajectories):  # a panel below carries the controller names
                ax.tick_params(labelbottom=False)
        for ax in axes.flat[len(trajectories) :]:
            ax.set_visible(False)
        figures.append(
            Figure(
                "fig-distributions",
                "Mean e_tr of each run per controller, one panel per trajectory "
                "(every uncertainty level and seed; box: quartiles).",
                svg(fig, "distributions", "distributions of the mean tracking error"),
                wide=True,
            )
        )
    for i, reference in enumerate(r for r in references if r in controllers):
        ratios = _bench_ratios(ok, controllers, reference)
        if any(ratios.values()):
            figures.append(
                Figure(
                    f"fig-ratio-{i}",
                    f"Mean e_tr of each run over {reference}'s on the same trajectory, level and seed "
                    "(below 1: better). The leaderboard's improvement is that of the pooled mean.",
                    svg(
                        plot_distributions(
                            ratios,
                            ylabel=f"e_tr / e_tr of {_mpl(reference)}",
                            reference=1.0,
                            title=f"paired against {_mpl(reference)}",
                        ),
                        f"ratio{i}",
                        f"paired error ratios against {reference}",
                    ),
                    wide=len(controllers) > 4,
                )
            )
    if {"label.mass_factor", "label.friction_factor"} <= set(table.column_names):
        robustness = _robustness_figure(results, controllers)
        if robustness is not None:
            figures.append(
                Figure(
                    "fig-robustness",
                    "Robustness map: mean e_tr on the circle over the plant's mass and "
                    "wheel-friction factors (grey: no successful run).",
                    svg(robustness, "robustness", "robustness map"),
                    wide=True,
                )
            )
    suite_rows = (
        [(str(key), fmt(value)) for key, value in suite.items()]
        if isinstance(suite, Mapping)
        else [("suite", fmt(suite))]
    )
    suite_rows += [
        ("controllers", ", ".join(str(c) for c in summary["controllers"])),
        ("tuned gains (backstepping_tuned)", fmt(summary["tuned_gains"])),
        ("runs", fmt(summary["runs"])),
        ("reused from an earlier start", fmt(summary["reused"])),
        ("diverged or non-finite", fmt(summary["not_ok"])),
        ("errors", fmt(summary["errors"])),
    ]
    tuned = _read_toml(folder / "tuned.toml")[0] if (folder / "tuned.toml").is_file() else ""
    sections = [
        Section("leaderboard", "Leaderboard", tables=(leaderboard, cell_table)),
        Section("distributions", "Distributions", figures=tuple(figures)),
        Section(
            "suite",
            "Suite",
            tables=(Table("suite-table", ("setting", "value"), tuple(suite_rows), left=2),),
            code=tuned,
            code_title="tuned.toml",
        ),
    ]
    cards = (
        Card("best mean e_tr", controllers[0] if controllers else "–", "good"),
        Card("controllers", str(len(controllers))),
        Card("runs", fmt(summary["runs"])),
        Card("diverged or non-finite", fmt(summary["not_ok"]), "good" if not summary["not_ok"] else "bad"),
        Card("errors", fmt(summary["errors"]), "good" if not summary["errors"] else "bad"),
    )
    levels = sorted({str(r["label.level"]) for r in ok})
    return {
        "title": "Benchmark",
        "subtitle": f"{len(controllers)} controllers × {len(trajectories)} trajectories × "
        f"{len(levels)} uncertainty level(s), on common random numbers",
        "cards": cards,
        "sections": sections,
        "written": _written(folder, KINDS["bench"]),
    }


def _bench_ratios(rows: list[dict], controllers: Sequence[str], reference: str) -> dict[str, list[float]]:
    """Per controller, E / E_reference for every (trajectory, level, seed) both ran. A ratio, not a percent
    improvement: a near-exact baseline (an error of 1e-12 m) would send a percentage to minus millions."""

    def cell(r: dict) -> tuple:
        return r["label.trajectory"], r["label.level"], r["seed"]

    base = {cell(r): r["e_tr_mean"] for r in rows if str(r["controller"]) == reference and r["e_tr_mean"] > 0}
    return {
        name: [r["e_tr_mean"] / base[cell(r)] for r in rows if str(r["controller"]) == name and cell(r) in base]
        for name in controllers
        if name != reference
    }


def _robustness_figure(results: list[dict], controllers: Sequence[str]) -> plt.Figure | None:
    rows = [
        r
        for r in results
        if r["label.study"] == "robustness"
        and r["status"] == "ok"
        and r["e_tr_mean"] is not None
        and r["label.mass_factor"] is not None
    ]
    names = [n for n in controllers if any(str(r["controller"]) == n for r in rows)]
    if not names:
        return None
    masses = sorted({r["label.mass_factor"] for r in rows})
    frictions = sorted({r["label.friction_factor"] for r in rows})
    columns = min(4, len(names))
    lines = math.ceil(len(names) / columns)
    fig, axes = plt.subplots(
        lines, columns, squeeze=False, layout="constrained", figsize=(2.5 * columns + 1.2, 2.2 * lines + 0.3)
    )
    values = np.asarray([r["e_tr_mean"] for r in rows], dtype=float)
    low = max(float(values.min()), 1e-6)
    norm = LogNorm(vmin=low, vmax=max(float(values.max()), low * 1.01))
    cmap = plt.get_cmap("viridis").with_extremes(bad="#dddddd")
    image = None
    for ax, name in zip(axes.flat, names, strict=False):
        grid = np.full((len(masses), len(frictions)), np.nan)
        for i, mass in enumerate(masses):
            for j, friction in enumerate(frictions):
                cell = [
                    r["e_tr_mean"]
                    for r in rows
                    if str(r["controller"]) == name
                    and r["label.mass_factor"] == mass
                    and r["label.friction_factor"] == friction
                ]
                grid[i, j] = np.mean(cell) if cell else np.nan
        image = ax.imshow(grid, origin="lower", aspect="auto", cmap=cmap, norm=norm)
        ax.set_title(_mpl(name), fontsize=9)
        ax.set_xticks(range(len(frictions)), [f"{f:g}" for f in frictions])
        ax.set_yticks(range(len(masses)), [f"{m:g}" for m in masses])
        ax.set_xlabel("friction ×", fontsize=8)
        ax.set_ylabel("mass ×", fontsize=8)
    for ax in list(axes.flat)[len(names) :]:
        ax.axis("off")
    assert image is not None, "a robustness map has at least one controller"
    fig.colorbar(image, ax=axes, label="mean e_tr [m]")
    return fig


# --- the page ------------------------------------------------------------------------------------------------

BUILDERS: dict[str, Callable[[Path], dict]] = {
    "run": _run_page,
    "reproduce": _reproduce_page,
    "mc": _mc_page,
    "bench": _bench_page,
}


def environment() -> Environment:
    """The Jinja2 environment: autoescape always on (``True``, so no file name can turn it off), and a
    missing value is an error, not an empty string."""
    return Environment(
        loader=FileSystemLoader(TEMPLATES),
        autoescape=True,
        undefined=StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
    )


def version() -> str:
    """The installed ddtrack's version (as ``ddtrack --version`` prints it), or "unknown"."""
    try:
        return metadata.version("ddtrack")
    except metadata.PackageNotFoundError:
        return "unknown"


def render(folder: Path, *, now: dt.datetime | None = None) -> str:
    """The HTML page for result folder ``folder`` (see :func:`detect_kind`)."""
    folder = Path(folder)
    kind = detect_kind(folder)
    with plt.rc_context(
        {
            "font.size": 9,
            "axes.titlesize": 10,
            "font.family": "sans-serif",
            "font.sans-serif": ["DejaVu Sans", "Liberation Sans", "Arial"],
        }
    ):
        try:
            parts = BUILDERS[kind](folder)
        except (KeyError, TypeError, ValueError, AttributeError) as exc:  # a file edited or from another version
            raise RunError(f"cannot read {DESCRIPTIONS[kind]} in '{folder}': {type(exc).__name__}: {exc}") from None
    page = Page(
        kind=kind,
        title=parts["title"],
        subtitle=parts["subtitle"],
        folder=str(folder.resolve()),
        written=parts["written"],
        generated=(now or dt.datetime.now(dt.UTC)).strftime("%Y-%m-%d %H:%M UTC"),
        version=version(),
        cards=tuple(parts["cards"]),
        sections=tuple(parts["sections"]),
    )
    return environment().get_template("report.html.j2").render(page=page, kind_name=DESCRIPTIONS[kind])


def write_report(folder: Path, *, out: Path | None = None) -> Path:
    """Render the report of ``folder`` into ``out`` (default ``folder/report.html``), atomically; return its path."""
    folder = Path(folder)
    detect_kind(folder)  # a wrong folder fails before anything else
    out = Path(out) if out is not None else folder / "report.html"
    if out.is_dir():
        raise RunError(f"--out '{out}' is a folder; give a file name, e.g. {out / 'report.html'}")
    check_writable(out.parent)
    html = render(folder)
    atomic_write(out, lambda f: f.write(html.encode("utf-8")))
    return out


__all__ = [
    "KINDS",
    "Page",
    "decimate",
    "detect_kind",
    "environment",
    "plot_distributions",
    "render",
    "svg",
    "write_report",
]
