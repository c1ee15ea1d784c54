"""``ddtrack report DIR``: one self-contained HTML page for a run, ``reproduce``, ``mc`` or ``bench`` folder (the
standard suites' leaderboard, or ``--suite robots``' board per robot).

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

from ._page import DESCRIPTIONS as DESCRIPTIONS
from ._page import GAIN_NAMES as GAIN_NAMES
from ._page import KINDS as KINDS
from ._page import MAX_PNG_BYTES as MAX_PNG_BYTES
from ._page import MAX_POINTS as MAX_POINTS
from ._page import MAX_RUN_ROWS as MAX_RUN_ROWS
from ._page import METRICS as METRICS
from ._page import PALETTE as PALETTE
from ._page import TEMPLATES as TEMPLATES
from ._page import Card as Card
from ._page import Cell as Cell
from ._page import Figure as Figure
from ._page import Page as Page
from ._page import Section as Section
from ._page import Table as Table
from ._page import ci_cell as ci_cell
from ._page import decimate as decimate
from ._page import detect_kind as detect_kind
from ._page import fmt as fmt
from ._page import fmt_ci as fmt_ci
from ._page import plot_distributions as plot_distributions
from ._page import png as png
from ._page import svg as svg
from .bench_page import BENCH_COLUMNS as BENCH_COLUMNS
from .mc_page import MC_COLUMNS as MC_COLUMNS
from .mc_page import MC_STATISTICS as MC_STATISTICS
from .render import BUILDERS as BUILDERS
from .render import environment as environment
from .render import render as render
from .render import version as version
from .render import write_report as write_report
from .reproduce_page import fmt_window as fmt_window
from .run_page import SERIES as SERIES
