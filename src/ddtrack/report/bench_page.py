"""The page of a ``ddtrack bench`` folder: the leaderboard, the cells and the robustness map (a ``--suite robots``
folder's page is :mod:`.robots_page`'s)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from matplotlib.colors import LogNorm

from ..errors import RunError
from ..plotting import plt
from ._page import (
    KINDS,
    Card,
    Cell,
    Figure,
    Section,
    Table,
    _field,
    _mpl,
    _read_json,
    _read_table,
    _read_toml,
    ci_cell,
    fmt,
    plot_distributions,
    svg,
)
from .robots_page import _robots_page, is_robots_summary
from .run_page import (
    _written,
)

# --- bench folder --------------------------------------------------------------------------------------------

BENCH_COLUMNS = ("controller", "seed", "status", "e_tr_mean", "label.study", "label.trajectory", "label.level")


def _bench_page(folder: Path) -> dict:
    path = folder / "leaderboard.json"
    summary = _read_json(path)
    if is_robots_summary(summary):  # `bench --suite robots`: a board per robot, its own page
        return _robots_page(folder, summary)
    if isinstance(summary, Mapping) and "reference" in summary and "entries" in summary:  # `bench --scenario`
        raise RunError(
            f"'{folder}' is a `ddtrack bench --scenario` folder, which `ddtrack report` does not show yet\n"
            f"  hint: its leaderboard.md and entries.png hold the board"
        )
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
