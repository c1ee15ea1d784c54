"""The page of a ``ddtrack reproduce`` folder: Table 1 and the paper's figures."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..plotting import ADAPTIVE, ROBOT, plt
from ._page import (
    GAIN_NAMES,
    Card,
    Figure,
    Section,
    Table,
    _field,
    _mpl,
    _read_json,
    ci_cell,
    fmt,
    fmt_ci,
    png,
    svg,
)
from .run_page import (
    _written,
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
