"""The leaderboard of ``ddtrack bench --suite robots`` (:mod:`ddtrack.studies.robot_suite`), from its runs' records: per
robot, each controller's mean tracking error per condition with a 95 % interval over seeds, its failures, the runs
that lost the path (counted apart, never averaged in) and the runs that asked for more than the robot has; whether
the paper robot's ranking survives on the others (Kendall's tau); and the NN-adaptive law's paired improvement over
the pairs where both laws tracked."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pyarrow as pa

from .._format import interval_text, significant
from ..metrics import METRIC_DOMAINS, mean_ci, pooled_improvement, rate_ci
from .board import IMPLAUSIBLE, interval_columns, lost, tracking_value, warning_codes


def rows(records: dict[str, dict]) -> list[dict]:
    """One flat row per run of the suite: its cell, status, whether it lost the path, its tracking error (None
    unless it tracked to the end), and whether it was plausible."""
    out = []
    for record in records.values():
        labels = record["configuration"].get("labels") or {}
        if labels.get("study") != "robots":
            continue
        metrics = record["metrics"] or {}
        out.append(
            {
                "controller": record["configuration"]["controller"],
                "seed": record["seed"],
                "status": record["status"],
                **{k: labels[k] for k in ("robot", "trajectory", "condition")},
                "lost": lost({"status": record["status"], **metrics}),
                "e_tr_mean": tracking_value({"status": record["status"], **metrics}),
                "implausible": bool(warning_codes(metrics) & set(IMPLAUSIBLE)),
            }
        )
    return out


def over_seeds(runs: list[dict]) -> dict:
    """Mean e_tr [95 % CI over seeds]: each seed's mean over ``runs`` (paths, conditions), then the interval over
    the seeds, the only random part; a seed with a failed or lost run counts as missing."""
    by_seed: dict[int, list] = {}
    for r in runs:
        by_seed.setdefault(r["seed"], []).append(r["e_tr_mean"])
    means = [None if None in errors else float(np.mean(errors)) for errors in by_seed.values()]
    return mean_ci(means, domain=METRIC_DOMAINS["e_tr_mean"])


def robot_board(runs: list[dict], robot: str, entries: Sequence[str], conditions: Sequence[str]) -> list[dict]:
    """Per controller on ``robot``: mean e_tr over its paths [95 % CI over seeds] per condition and over all its
    runs, failures, runs that lost the path (``lost``, and ``lost_rate`` with its Wilson interval), runs flagged
    implausible; ranked by the nominal condition's mean."""
    board = []
    for label in entries:
        mine = [r for r in runs if r["robot"] == robot and r["controller"] == label]
        if not mine:
            continue
        by_condition = {c: over_seeds([r for r in mine if r["condition"] == c]) for c in conditions}
        board.append(
            {
                "controller": label,
                "runs": len(mine),
                "failures": sum(r["status"] != "ok" for r in mine),
                "lost": (off := sum(bool(r.get("lost")) for r in mine)),
                "lost_rate": rate_ci(off, len(mine)),
                "implausible": sum(r["implausible"] for r in mine),
                "all": over_seeds(mine),
                **{c: summary for c, summary in by_condition.items() if summary["n"] + summary["missing"]},
            }
        )
    nominal = [e.get("nominal", {}).get("mean") for e in board]
    return [e for _, e in sorted(zip(nominal, board, strict=True), key=lambda p: math.inf if p[0] is None else p[0])]


def paired(runs: list[dict], robot: str, baseline: str, candidate: str) -> dict | None:
    """The pooled paired improvement [%] of ``candidate`` over ``baseline`` on ``robot``, pairing runs by
    (trajectory, condition, seed), over the pairs where both tracked to the end (``n``; ``missing``: the pairs
    where either failed or lost the path); None if either did not run there."""

    def cell(r: dict) -> tuple:
        return r["trajectory"], r["condition"], r["seed"]

    base = {cell(r): r["e_tr_mean"] for r in runs if r["robot"] == robot and r["controller"] == baseline}
    mine = [r for r in runs if r["robot"] == robot and r["controller"] == candidate]
    if not base or not mine:
        return None
    return pooled_improvement([base.get(cell(r)) for r in mine], [r["e_tr_mean"] for r in mine])


def ranking_agreement(boards: dict[str, list[dict]], reference: str = "paper") -> dict[str, dict]:
    """Kendall's tau between the nominal ranking on ``reference`` and on each other robot, over the controllers
    both ran (the ranking's survival from the paper's robot to real ones)."""
    from scipy import stats

    def nominal(board: list[dict]) -> dict[str, float]:
        return {
            e["controller"]: e["nominal"]["mean"] for e in board if (e.get("nominal") or {}).get("mean") is not None
        }

    out: dict[str, dict] = {}
    if reference not in boards:
        return out
    ref = nominal(boards[reference])
    for robot, board in boards.items():
        mine = nominal(board)
        common = sorted(set(ref) & set(mine))
        if robot == reference or len(common) < 3:
            continue
        tau = stats.kendalltau([ref[c] for c in common], [mine[c] for c in common])
        out[robot] = {"controllers": common, "tau": float(tau.statistic), "p_value": float(tau.pvalue)}
    return out


def agreement_by_path(
    runs: list[dict], robots: Sequence[str], entries: Sequence[str], conditions: Sequence[str]
) -> dict[str, dict[str, dict]]:
    """:func:`ranking_agreement` on each path's runs alone (corners and loops may rank controllers differently);
    empty when the runs cover one path."""
    paths = sorted({r["trajectory"] for r in runs})
    if len(paths) < 2:
        return {}
    return {
        path: ranking_agreement(
            {
                robot: robot_board([r for r in runs if r["trajectory"] == path], robot, entries, conditions)
                for robot in robots
            }
        )
        for path in paths
    }


#: (baseline, candidate): the paper's question, over torque and over cmd_vel
NN_QUESTIONS = (
    ("backstepping", "nn_adaptive_backstepping"),
    ("kinematic_backstepping", "nn_adaptive_backstepping/cmd_vel"),
)


def summarize(
    records: dict[str, dict], robots: Sequence[str], conditions: Sequence[str], entries: Sequence[str], left_out: list
) -> dict:
    """The leaderboard of every robot, the ranking agreement (over all paths and per path), the NN questions'
    answers and the left-out cells."""
    runs = rows(records)
    boards = {robot: robot_board(runs, robot, entries, conditions) for robot in robots}
    questions = {
        robot: {f"{c} vs {b}": paired(runs, robot, b, c) for b, c in NN_QUESTIONS if b in entries and c in entries}
        for robot in robots
    }
    return {
        "boards": boards,
        "ranking_agreement": ranking_agreement(boards),
        "ranking_agreement_by_path": agreement_by_path(runs, robots, entries, conditions),
        "nn_adaptive": questions,
        "left_out": left_out,
    }


def board_markdown(summary: dict, conditions: Sequence[str]) -> str:
    """``leaderboard.md``: per robot, mean e_tr [m] [95 % CI] per condition and overall, failures and implausible
    runs; then the ranking agreement with the paper's robot, the NN-adaptive law's paired improvement, and what was
    left out and why."""
    lines: list[str] = []
    for robot, board in summary["boards"].items():
        if not board:
            continue
        shown = [c for c in conditions if any(c in e for e in board)]
        lines += [
            f"### {robot}",
            "",
            "mean e_tr in m, with its 95 % CI over seeds, over the runs that tracked, ranked by the nominal condition; "
            "lost: runs that ended off the path (e_tr beyond a quarter of the path's width for the last fifth of the "
            "window), with the rate's 95 % interval; implausible: runs that asked for more grip, wheel speed or "
            "torque than the robot has",
            "",
        ]
        lines.append("| controller | " + " | ".join(shown) + " | all | failures | lost [%] | implausible |")
        lines.append("|" + "---|" * (len(shown) + 5))
        for e in board:
            values = " | ".join(interval_text(e.get(c)) for c in shown)
            lines.append(
                f"| {e['controller']} | {values} | {interval_text(e['all'])} | {e['failures']}/{e['runs']} | "
                f"{e['lost']}: {interval_text(e['lost_rate'], 100.0)} | {e['implausible']}/{e['runs']} |"
            )
        lines.append("")
    if summary["ranking_agreement"]:
        lines += [
            "### Does the paper robot's ranking survive?",
            "",
            "Kendall's tau between the nominal rankings (1: same order, 0: unrelated, -1: reversed):",
            "",
            "| robot | tau | p | controllers |",
            "|---|---|---|---|",
        ]
        for robot, a in summary["ranking_agreement"].items():
            lines.append(f"| {robot} | {a['tau']:.2f} | {significant(a['p_value'])} | {len(a['controllers'])} |")
        lines.append("")
    by_path = summary.get("ranking_agreement_by_path") or {}
    if by_path:
        robots = sorted({robot for agreement in by_path.values() for robot in agreement})
        lines += [
            "Kendall's tau on each path alone (its own nominal rankings):",
            "",
            "| path | " + " | ".join(robots) + " |",
            "|---|" + "---|" * len(robots),
        ]
        for path, agreement in by_path.items():
            taus = (f"{agreement[r]['tau']:.2f}" if r in agreement else "" for r in robots)
            lines.append(f"| {path} | " + " | ".join(taus) + " |")
        lines.append("")
    answers = [(robot, q, v) for robot, qs in summary["nn_adaptive"].items() for q, v in qs.items() if v]
    if answers:
        lines += [
            "### Does the paper's NN-adaptive law help?",
            "",
            "Pooled paired improvement of mean e_tr in %, with its 95 % CI, over the cells the two share where both "
            "tracked to the end (positive: the NN-adaptive law tracks better); pairs: used of shared:",
            "",
            "| robot | comparison | improvement [%] | pairs |",
            "|---|---|---|---|",
        ]
        for robot, question, value in answers:
            lines.append(
                f"| {robot} | {question} | {interval_text(value)} | {value['n']} of {value['n'] + value['missing']} |"
            )
        lines.append("")
    if summary["left_out"]:
        why: dict[tuple[str, str], set[str]] = {}
        for c in summary["left_out"]:
            why.setdefault((c["robot"], c["why"]), set()).add(
                c["condition"] if "model" in c["why"] else c["controller"]
            )
        lines += [
            "Left out: "
            + "; ".join(f"{robot} {reason} ({', '.join(sorted(what))})" for (robot, reason), what in why.items()),
            "",
        ]
    return "\n".join(lines)


def board_table(summary: dict, conditions: Sequence[str]) -> pa.Table:
    """The leaderboards as one flat table (``leaderboard.csv``, ``.parquet``): a row per robot and controller."""
    flat = []
    for robot, board in summary["boards"].items():
        for e in board:
            row = {"robot": robot, **{k: e[k] for k in ("controller", "runs", "failures", "lost", "implausible")}}
            for key in ("all", "lost_rate", *conditions):
                row |= interval_columns(key, e.get(key))
            flat.append(row)
    return pa.Table.from_pylist(flat)


def figure(summary: dict, conditions: Sequence[str]) -> Any:
    """``robots.png``: mean e_tr per controller and condition, one panel per robot, on one log colour scale."""
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    boards = {r: b for r, b in summary["boards"].items() if b}
    values = [e[c]["mean"] for b in boards.values() for e in b for c in conditions if (e.get(c) or {}).get("mean")]
    low, high = (max(min(values), 1e-5), max(values)) if values else (1e-3, 1e-2)
    fig, axes = plt.subplots(
        1, max(1, len(boards)), squeeze=False, layout="constrained", figsize=(3.6 * max(1, len(boards)), 4.2)
    )
    image = None
    for ax, (robot, board) in zip(axes.flat, boards.items(), strict=False):
        grid = np.array([[(e.get(c) or {}).get("mean") or np.nan for c in conditions] for e in board], dtype=float)
        image = ax.imshow(grid, aspect="auto", cmap="viridis", norm=LogNorm(vmin=low, vmax=max(high, low * 1.01)))
        ax.set(title=robot, xticks=range(len(conditions)), yticks=range(len(board)))
        ax.set_xticklabels(conditions, rotation=90)
        ax.set_yticklabels([e["controller"] for e in board], fontsize=7)
    if image is not None:
        fig.colorbar(image, ax=axes, label="mean e_tr [m] (blank: left out, failed or lost)")
    return fig
