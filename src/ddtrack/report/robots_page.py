"""The page of a ``ddtrack bench --suite robots`` folder: a board per robot, whether the paper robot's ranking
survives on the others, whether the NN-adaptive law helps, and the cells left out and why."""

from __future__ import annotations

from collections.abc import Mapping, Sequence, Sized
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.colors import LogNorm

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
    _read_table,
    ci_cell,
    fmt,
    plot_distributions,
    svg,
)
from .run_page import _written

ROBOTS_COLUMNS = ("controller", "seed", "status", "e_tr_mean", "label.study", "label.robot", "label.condition")
KIND_NAME = "a robots bench folder (ddtrack bench --suite robots)"


def is_robots_summary(summary: Any) -> bool:
    """Whether a ``leaderboard.json`` is the robots suite's (a board per robot) rather than the standard suite's."""
    return isinstance(summary, Mapping) and "boards" in summary


def _robots_page(folder: Path, summary: Mapping[str, Any]) -> dict:
    path = folder / "leaderboard.json"
    boards: Mapping[str, list[dict]] = _field(summary, "boards", path=path)
    suite = _field(summary, "suite", path=path)
    conditions = [str(c) for c in _field(suite, "conditions", path=path)]
    results = _read_table(folder / "results.parquet", ROBOTS_COLUMNS).to_pylist()
    ok = [r for r in results if r["label.study"] == "robots" and r["status"] == "ok" and r["e_tr_mean"] is not None]
    sections = [
        Section(
            f"robot-{i}",
            str(robot),
            notes=() if board else ("No controller of this suite drives this robot: every cell was left out.",),
            tables=(_board_table(f"board-{i}", str(robot), board, conditions),) if board else (),
        )
        for i, (robot, board) in enumerate(boards.items())
    ]
    figures = _figures(boards, conditions, ok)
    if figures:
        sections.append(Section("figures", "Errors per robot", figures=tuple(figures)))
    sections += [
        _agreement_section(_field(summary, "ranking_agreement", path=path)),
        _nn_section(_field(summary, "nn_adaptive", path=path)),
        _left_out_section(_field(summary, "left_out", path=path)),
        _suite_section(summary, suite),
    ]
    entries = [e for board in boards.values() for e in board]
    failures = sum(int(e["failures"]) for e in entries)
    implausible = sum(int(e["implausible"]) for e in entries)
    controllers = [str(c) for c in summary["controllers"]]
    cards = (
        Card("robots", str(len(boards))),
        Card("controllers", str(len(controllers))),
        Card("runs", fmt(summary["runs"])),
        Card("failures", str(failures), "good" if not failures else "bad"),
        Card("implausible runs", str(implausible), "good" if not implausible else "bad"),
        Card("errors", fmt(summary["errors"]), "good" if not summary["errors"] else "bad"),
    )
    trajectories = _field(suite, "trajectories", path=path)
    return {
        "title": "Robot benchmark",
        "subtitle": f"{_count(controllers, 'controller')} × {_count(boards, 'robot')} × "
        f"{_count(trajectories, 'path')} × {_count(conditions, 'condition')}, {fmt(suite.get('seeds'))} seed(s) "
        "per cell, on common random numbers",
        "cards": cards,
        "sections": sections,
        "written": _written(folder, KINDS["bench"]),
        "kind_name": KIND_NAME,
    }


def _count(items: Sized, noun: str) -> str:
    return f"{len(items)} {noun}{'' if len(items) == 1 else 's'}"


def _shown(board: Sequence[Mapping[str, Any]], conditions: Sequence[str]) -> list[str]:
    """The conditions some controller of ``board`` ran (a robot's model may express none of a condition)."""
    return [c for c in conditions if any(c in e for e in board)]


def _board_table(table_id: str, robot: str, board: Sequence[Mapping[str, Any]], conditions: Sequence[str]) -> Table:
    shown = _shown(board, conditions)
    rows: tuple[tuple[str | Cell, ...], ...] = tuple(
        (
            str(rank),
            str(e["controller"]),
            *(ci_cell(e.get(c)) for c in shown),
            ci_cell(e["all"]),
            f"{e['failures']}/{e['runs']}",
            f"{e['implausible']}/{e['runs']}",
        )
        for rank, e in enumerate(board, start=1)
    )
    return Table(
        table_id,
        ("rank", "controller", *shown, "all", "failures", "implausible"),
        rows,
        left=2,
        nowrap=2,
        caption=f"{robot}: mean e_tr [m] over its paths [95 % CI over seeds] per condition and over all its runs, "
        "ranked by the nominal condition; implausible: runs that asked for more grip, wheel speed or torque than "
        "the robot has.",
    )


def _agreement_section(agreement: Mapping[str, Mapping[str, Any]]) -> Section:
    rows = tuple(
        (
            str(robot),
            ", ".join(str(c) for c in a["controllers"]),
            str(len(a["controllers"])),
            fmt(a["tau"], 3),
            fmt(a["p_value"], 3),
        )
        for robot, a in agreement.items()
    )
    notes = (
        ()
        if rows
        else (
            "No robot shares three or more controllers with a nominal mean with the paper's robot: no ranking "
            "to compare.",
        )
    )
    table = Table(
        "agreement-table",
        ("robot", "controllers both ran", "n", "Kendall's tau", "p"),
        rows,
        caption="Kendall's tau between the nominal ranking on the paper's robot and on each other robot, over the "
        "controllers both ran (1: same order, 0: unrelated, -1: reversed).",
        left=2,
    )
    return Section("agreement", "Does the paper robot's ranking survive?", notes=notes, tables=(table,) if rows else ())


def _nn_section(questions: Mapping[str, Mapping[str, Any]]) -> Section:
    rows = tuple(
        (str(robot), str(question), ci_cell(value, 3), fmt(value["n"]) if value else "–")
        for robot, asked in questions.items()
        for question, value in asked.items()
    )
    notes = (
        ()
        if rows
        else (
            "The suite ran no NN-adaptive law beside its baseline (backstepping, or kinematic_backstepping over "
            "cmd_vel): nothing to compare.",
        )
    )
    table = Table(
        "nn-table",
        ("robot", "comparison", "improvement [%]", "pairs"),
        rows,
        left=2,
        nowrap=2,
        caption="Pooled paired improvement of mean e_tr [%] [95 % CI], pairing runs by path, condition and seed "
        "(positive: the NN-adaptive law tracks better; –: one of the two takes no command this robot takes).",
    )
    return Section(
        "nn-adaptive", "Does the paper's NN-adaptive law help?", notes=notes, tables=(table,) if rows else ()
    )


def _left_out_section(left_out: Sequence[Mapping[str, Any]]) -> Section:
    grouped: dict[tuple[str, str, str], list[str]] = {}
    for cell in left_out:  # one row per robot, controller and reason: its conditions listed
        grouped.setdefault((str(cell["robot"]), str(cell["controller"]), str(cell["why"])), []).append(
            str(cell["condition"])
        )
    rows = tuple((robot, controller, ", ".join(which), why) for (robot, controller, why), which in grouped.items())
    table = Table(
        "left-out-table",
        ("robot", "controller", "conditions", "why"),
        rows,
        left=4,
        nowrap=2,
        caption="Cells not run: the robot takes no command of the controller's kind, or its model cannot express "
        "the condition.",
    )
    notes = () if rows else ("Every robot ran every controller under every condition.",)
    return Section("left-out", "Left out", notes=notes, tables=(table,) if rows else ())


def _suite_section(summary: Mapping[str, Any], suite: Any) -> Section:
    rows = (
        [(str(key), fmt(value)) for key, value in suite.items()]
        if isinstance(suite, Mapping)
        else [("suite", fmt(suite))]
    )
    rows += [
        ("controllers", ", ".join(str(c) for c in summary["controllers"])),
        ("runs", fmt(summary["runs"])),
        ("reused from an earlier start", fmt(summary["reused"])),
        ("diverged or non-finite", fmt(summary["not_ok"])),
        ("errors", fmt(summary["errors"])),
    ]
    return Section("suite", "Suite", tables=(Table("suite-table", ("setting", "value"), tuple(rows), left=2),))


def _panels(count: int, columns: int, width: float, height: float) -> tuple[plt.Figure, np.ndarray]:
    """A figure of ``count`` panels, ``columns`` to a row, the unused ones hidden."""
    lines = -(-count // columns)
    fig, axes = plt.subplots(
        lines, columns, squeeze=False, layout="constrained", figsize=(min(12.5, width * columns), height * lines)
    )
    for ax in axes.flat[count:]:
        ax.set_visible(False)
    return fig, axes


def _figures(boards: Mapping[str, list[dict]], conditions: Sequence[str], ok: list[dict]) -> list[Figure]:
    ran = {str(robot): board for robot, board in boards.items() if board}
    figures = []
    shown = [c for c in conditions if any(c in e for board in ran.values() for e in board)]
    values = [e[c]["mean"] for b in ran.values() for e in b for c in shown if (e.get(c) or {}).get("mean")]
    if values:
        figures.append(
            Figure(
                "fig-conditions",
                "Mean e_tr [m] per controller and condition, one panel per robot, on one log colour scale "
                "(grey: left out or every seed failed).",
                svg(_condition_map(ran, shown, values), "conditions", "mean tracking error per condition"),
                wide=True,
            )
        )
    groups = {
        robot: {
            str(e["controller"]): [
                r["e_tr_mean"] for r in ok if r["label.robot"] == robot and r["controller"] == e["controller"]
            ]
            for e in board
        }
        for robot, board in ran.items()
    }
    if any(v for g in groups.values() for v in g.values()):
        columns = min(len(groups), 4)
        widest = max(len(g) for g in groups.values())
        fig, axes = _panels(len(groups), columns, max(3.2, 0.45 * widest + 1.6), 3.6)
        for i, (ax, (robot, group)) in enumerate(zip(axes.flat, groups.items(), strict=False)):
            plot_distributions(group, ax=ax, ylabel="mean e_tr per run [m]" if i % columns == 0 else "")
            ax.set_title(_mpl(robot))
        figures.append(
            Figure(
                "fig-distributions",
                "Mean e_tr of each run per controller, one panel per robot (every path, condition and seed; "
                "box: quartiles; failed runs left out).",
                svg(fig, "distributions", "distributions of the mean tracking error per robot"),
                wide=True,
            )
        )
    return figures


def _condition_map(boards: Mapping[str, list[dict]], conditions: Sequence[str], values: list[float]) -> plt.Figure:
    low = max(min(values), 1e-6)
    norm = LogNorm(vmin=low, vmax=max(max(values), low * 1.01))
    cmap = plt.get_cmap("viridis").with_extremes(bad="#dddddd")
    columns = min(len(boards), 2 if len(conditions) > 3 else 4)
    tallest = max(len(b) for b in boards.values())
    fig, axes = _panels(len(boards), columns, 0.5 * len(conditions) + 2.6, 0.3 * tallest + 2.4)
    image = None
    for ax, (robot, board) in zip(axes.flat, boards.items(), strict=False):
        grid = np.array([[(e.get(c) or {}).get("mean") or np.nan for c in conditions] for e in board], dtype=float)
        image = ax.imshow(grid, aspect="auto", cmap=cmap, norm=norm)
        ax.set_title(_mpl(robot))
        ax.set_xticks(range(len(conditions)), [_mpl(c) for c in conditions], rotation=35, ha="right")
        ax.set_yticks(range(len(board)), [_mpl(e["controller"]) for e in board], fontsize=8)
    assert image is not None, "a condition map has at least one robot"
    fig.colorbar(image, ax=axes, label="mean e_tr [m]")
    return fig
