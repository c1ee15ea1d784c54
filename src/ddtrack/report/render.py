"""One page from a folder: its kind detected, its builder run, the template rendered and written atomically."""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable
from importlib import metadata
from pathlib import Path

from jinja2 import Environment, FileSystemLoader, StrictUndefined

from ..errors import RunError
from ..outdir import atomic_write, check_writable
from ..plotting import plt
from ._page import (
    DESCRIPTIONS,
    KINDS,
    TEMPLATES,
    Page,
    decimate,
    detect_kind,
    plot_distributions,
    svg,
)
from .bench_page import _bench_page
from .mc_page import _mc_page
from .reproduce_page import _reproduce_page
from .run_page import (
    _run_page,
)

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
    kind_name = parts.get("kind_name", DESCRIPTIONS[kind])  # a builder may name its folder more closely
    return environment().get_template("report.html.j2").render(page=page, kind_name=kind_name)


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
