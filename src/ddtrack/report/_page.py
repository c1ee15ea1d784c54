"""What every page shares: the folder kinds, the page model the template prints, reading a folder's files,
numbers as text, and figures as inline SVG.
"""

from __future__ import annotations

import base64
import io
import itertools
import json
import math
import re
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from markupsafe import Markup

from .._format import significant
from ..errors import RunError
from ..plotting import plt, root_figure

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
TEMPLATES = Path(__file__).resolve().parent.parent / "templates"
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
