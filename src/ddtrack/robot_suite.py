"""``ddtrack bench --suite robots``: controllers x robot presets x trajectories x conditions, on common random numbers.

The question users ask: how will a controller do on *my* robot? Each preset drives the plant it really has (the
paper's torque-source robot; a TurtleBot3's Dynamixel servos on a floor of finite grip, in current mode for torque
laws and under their wheel-speed PI loop for velocity laws, as cmd_vel; a Pioneer 3-DX's identified velocity lags),
at the rate it is driven (100 Hz for the paper's robot, 20 Hz for the ROS robots), on a figure eight and a filleted
square scaled to its top speed. Conditions vary one factor at a time from the nominal robot (no latency, floor
friction 1.0, true pose, no payload); a condition the robot's model cannot express (a payload on the Pioneer's
identified lags, a floor under the paper's massless wheels) is left out and listed as such. Seed s draws the same
plant (mass and inertia within 10 %), disturbance and noise for every controller, so cells pair by seed.
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import io
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.csv
import pyarrow.parquet as pq

from ._format import significant, with_interval
from .errors import ConfigError
from .metrics import METRIC_DOMAINS, mean_ci, pooled_improvement
from .outdir import atomic_write
from .robots import PRESETS
from .scenario import controller_kind
from .scenario.files import apply_override, validate_scenario
from .sweep import Configuration, Plan, canonical, read_records, run_key, run_sweep


@dataclass(frozen=True)
class Entry:
    """A controller as the suite runs it: its label, its kind, what it outputs, and keys beyond the kind's
    defaults."""

    label: str
    kind: str
    output: str  #: "torque" or "velocity": which of a robot's plants it drives
    keys: tuple[tuple[str, Any], ...] = ()


#: torque laws run through a robot's torque input; velocity laws publish (v, omega) as cmd_vel
ENTRIES = (
    Entry("backstepping", "backstepping", "torque"),
    Entry("nn_adaptive_backstepping", "nn_adaptive_backstepping", "torque"),
    Entry("ltv_lqr", "ltv_lqr", "torque"),
    Entry("sliding_mode_backstepping", "sliding_mode_backstepping", "torque"),
    Entry("regulated_pure_pursuit", "regulated_pure_pursuit", "torque"),
    Entry("adaptive_backstepping", "adaptive_backstepping", "torque"),
    Entry("mppi", "mppi", "torque"),
    Entry("kinematic_backstepping", "kinematic_backstepping", "velocity"),
    Entry("nn_adaptive_backstepping/cmd_vel", "nn_adaptive_backstepping", "velocity", (("inner", "none"),)),
    Entry("ltv_lqr/cmd_vel", "ltv_lqr", "velocity", (("inner", "none"),)),
    Entry("regulated_pure_pursuit/cmd_vel", "regulated_pure_pursuit", "velocity", (("inner", "none"),)),
    Entry("adaptive_compensator", "adaptive_compensator", "velocity"),
)
ENTRY = {e.label: e for e in ENTRIES}


@dataclass(frozen=True)
class Robot:
    """A preset as the suite drives it: its plant per controller output (None: it takes no such command), the
    control period, and its two paths (a figure eight and a filleted square) run for ``duration``."""

    preset: str
    plants: dict[str, str | None]  #: controller output -> plant model
    control_period: float  #: [s]
    substeps: int
    speed: float  #: reference speed [m/s] of the square; the figure eight peaks near it
    side: float  #: the square's side [m]; the figure eight is as wide
    duration: float  #: [s] a lap of each path
    floor: bool  #: finite grip is modelled (the floor conditions apply)
    payload: bool  #: the plant's mass enters its model (the payload condition applies)


ROBOTS = {
    "paper": Robot("paper", {"torque": "dynamic", "velocity": None}, 0.01, 10, 0.5, 4.0, 32.0, False, True),
    "turtlebot3_burger": Robot(
        "turtlebot3_burger", {"torque": "slip", "velocity": "slip_velocity"}, 0.05, 50, 0.1, 1.0, 40.0, True, True
    ),
    "turtlebot3_waffle_pi": Robot(
        "turtlebot3_waffle_pi", {"torque": "slip", "velocity": "slip_velocity"}, 0.05, 50, 0.12, 1.2, 40.0, True, True
    ),
    "pioneer_3dx": Robot("pioneer_3dx", {"torque": None, "velocity": "lag"}, 0.05, 10, 0.5, 4.0, 32.0, False, False),
}
TRAJECTORIES = ("figure_eight", "square")
CONDITIONS = ("nominal", "latency_50ms", "latency_150ms", "floor_mu_0.4", "odometry", "payload_+50%")
NOMINAL_FLOOR = (
    1.0  #: the nominal robot's floor friction (a clean indoor floor; the grip checks flag runs needing more)
)
ODOMETRY_RADIUS_ERROR = 1.01  #: the wheel radius odometry (and the controller) believes, over the true: a 1 % error


def trajectory_table(robot: Robot, name: str) -> dict[str, Any]:
    """The ``[trajectory]`` of ``name`` for ``robot``: a square of side S at speed v from (0, 0), corners filleted
    at S / 10; a figure eight S wide whose lap is the square's (so its speed peaks near 1.1 v)."""
    if name == "square":
        return {
            "kind": "square",
            "corner": [0.0, 0.0],
            "side": robot.side,
            "speed": robot.speed,
            "corner_radius": 0.1 * robot.side,
        }
    return {"kind": "figure_eight", "center": [0.0, 0.0], "size": robot.side / 2.0, "period": robot.duration}


def condition_overrides(robot: Robot, condition: str) -> list[str] | None:
    """The overrides of ``condition`` on ``robot``'s base scenario; None where its model cannot express it."""
    preset = PRESETS[robot.preset]
    if condition == "nominal":
        return []
    if condition.startswith("latency_"):  # the loop's whole delay, put where the command reaches the wheels
        return [f"sensing.actuation_delay={int(condition.removeprefix('latency_').removesuffix('ms')) / 1000}"]
    if condition == "floor_mu_0.4":
        return ["plant.floor_friction=0.4"] if robot.floor else None
    if condition == "odometry":
        counts = [f"sensing.encoder_counts={preset.motor.encoder_counts}"] if preset.motor is not None else []
        radius = preset.params["wheel_radius"]
        return [
            "sensing.odometry=true",
            *counts,
            f"robot.wheel_radius={radius * ODOMETRY_RADIUS_ERROR!r}",
            f"plant.wheel_radius={radius!r}",
        ]
    if condition == "payload_+50%":  # a payload spread like the robot's own mass
        mass, inertia = preset.params["mass"], preset.params["inertia"]
        return [f"plant.mass={1.5 * mass!r}", f"plant.inertia={1.5 * inertia!r}"] if robot.payload else None
    raise ValueError(f"unknown condition {condition!r}")


def base_scenario(robot: Robot, entry: Entry, trajectory: str) -> dict[str, Any] | None:
    """The scenario of ``entry`` on ``robot``'s plant along ``trajectory``, as a dict; None where the robot
    takes no command of the entry's output."""
    plant = robot.plants[entry.output]
    if plant is None:
        return None
    preset = PRESETS[robot.preset]
    controller: dict[str, Any] = {"kind": entry.kind, **dict(entry.keys)}
    fields = controller_kind(entry.kind).config.model_fields
    if preset.max_speed is not None and "max_velocity" in fields:  # the clamps at what the robot can do
        controller |= {"max_velocity": preset.max_speed, "max_yaw_rate": preset.max_yaw_rate}
    return {
        "name": f"robots_{robot.preset}_{trajectory}",
        "simulation": {
            "duration": robot.duration,
            "control_period": robot.control_period,
            "substeps": robot.substeps,
            "metric_window": [4.0, robot.duration],
        },
        "robot": {"preset": robot.preset},
        "plant": {"model": plant, "floor_friction": NOMINAL_FLOOR},
        "randomize": {"mass": {"relative": 0.1}, "inertia": {"relative": 0.1}},
        "trajectory": trajectory_table(robot, trajectory),
        "controller": controller,
    }


@dataclass(frozen=True)
class RobotSuite:
    """What ``--suite robots`` runs: robots, trajectories, conditions, seeds per cell, and overrides applied to
    every cell last (e.g. shorter runs, for tests)."""

    robots: tuple[str, ...] = tuple(ROBOTS)
    trajectories: tuple[str, ...] = TRAJECTORIES
    conditions: tuple[str, ...] = CONDITIONS
    seeds: int = 3
    overrides: tuple[str, ...] = ()


def entry_labels(requested: Sequence[str] | None) -> list[str]:
    """Every entry, or the requested ones (checked)."""
    names = list(requested) if requested else list(ENTRY)
    for name in names:
        if name not in ENTRY:
            raise ConfigError(
                "--controllers", f"unknown controller '{name}' for --suite robots", f"choose from: {', '.join(ENTRY)}"
            )
    if len(set(names)) != len(names):
        raise ConfigError("--controllers", "lists a controller twice")
    return names


def cells(suite: RobotSuite, entries: Sequence[str]) -> tuple[list[dict], list[dict]]:
    """(cells run, cells left out, each saying why: the robot takes no such command, or cannot express it)."""
    run: list[dict] = []
    left: list[dict] = []
    for name in suite.robots:
        robot = ROBOTS[name]
        for label in entries:
            entry = ENTRY[label]
            for condition in suite.conditions:
                cell = {"robot": name, "controller": label, "condition": condition}
                if robot.plants[entry.output] is None:
                    left.append(cell | {"why": f"takes no {entry.output} commands"})
                elif condition_overrides(robot, condition) is None:
                    left.append(
                        cell | {"why": "its model has no " + ("floor" if condition.startswith("floor") else "mass")}
                    )
                else:
                    run.extend(cell | {"trajectory": t} for t in suite.trajectories)
    return run, left


def plan_robot_suite(suite: RobotSuite, entries: Sequence[str]) -> Plan:
    """Every cell resolved (bad input fails here, before anything runs); keys hash the cell with the scenario
    and seed."""
    configurations = []
    for cell in cells(suite, entries)[0]:
        robot, entry = ROBOTS[cell["robot"]], ENTRY[cell["controller"]]
        data = base_scenario(robot, entry, cell["trajectory"])
        assert data is not None, "cells() leaves out robots that take no such command"
        overrides = [*(condition_overrides(robot, cell["condition"]) or []), *suite.overrides]
        for override in overrides:
            apply_override(data, override)
        labels = {"study": "robots", **{k: cell[k] for k in ("robot", "trajectory", "condition")}}
        described = {"base": copy.deepcopy(base_scenario(robot, entry, cell["trajectory"])), "overrides": overrides}
        configurations.append(Configuration(entry.label, described, validate_scenario(data), labels))
    runs = {}
    for index, configuration in enumerate(configurations):
        for seed in range(suite.seeds):
            cell_text = canonical({"labels": configuration.labels, "controller": configuration.controller})
            key = hashlib.sha256((run_key(configuration.scenario, seed) + cell_text).encode()).hexdigest()
            runs[key] = (index, seed)
    return Plan(configurations, runs, chunk=suite.seeds)


#: warnings that say a run asked for something the real robot cannot give
IMPLAUSIBLE = ("friction_exceeds_floor", "wheel_speed_beyond_motor", "torque_beyond_motor")


def rows(records: dict[str, dict]) -> list[dict]:
    """One flat row per run of the suite: its cell, status, tracking error, and whether it was plausible."""
    out = []
    for record in records.values():
        labels = record["configuration"].get("labels") or {}
        if labels.get("study") != "robots":
            continue
        metrics = record["metrics"] or {}
        codes = {w["code"] for w in metrics.get("warnings") or []}
        out.append(
            {
                "controller": record["configuration"]["controller"],
                "seed": record["seed"],
                "status": record["status"],
                **{k: labels[k] for k in ("robot", "trajectory", "condition")},
                "e_tr_mean": metrics.get("e_tr_mean") if record["status"] == "ok" else None,
                "implausible": bool(codes & set(IMPLAUSIBLE)),
            }
        )
    return out


def over_seeds(runs: list[dict]) -> dict:
    """Mean e_tr [95 % CI over seeds]: each seed's mean over ``runs`` (paths, conditions), then the interval over
    the seeds, the only random part; a seed with a failed run counts as missing."""
    by_seed: dict[int, list] = {}
    for r in runs:
        by_seed.setdefault(r["seed"], []).append(r["e_tr_mean"])
    means = [None if None in errors else float(np.mean(errors)) for errors in by_seed.values()]
    return mean_ci(means, domain=METRIC_DOMAINS["e_tr_mean"])


def robot_board(runs: list[dict], robot: str, entries: Sequence[str], conditions: Sequence[str]) -> list[dict]:
    """Per controller on ``robot``: mean e_tr over its paths [95 % CI over seeds] per condition and over all its
    runs, failures, runs flagged implausible; ranked by the nominal condition's mean."""
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
                "implausible": sum(r["implausible"] for r in mine),
                "all": over_seeds(mine),
                **{c: summary for c, summary in by_condition.items() if summary["n"] + summary["missing"]},
            }
        )
    nominal = [e.get("nominal", {}).get("mean") for e in board]
    return [e for _, e in sorted(zip(nominal, board, strict=True), key=lambda p: math.inf if p[0] is None else p[0])]


def paired(runs: list[dict], robot: str, baseline: str, candidate: str) -> dict | None:
    """The pooled paired improvement [%] of ``candidate`` over ``baseline`` on ``robot``, pairing runs by
    (trajectory, condition, seed); None if either did not run there."""

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


#: (baseline, candidate): the paper's question, over torque and over cmd_vel
NN_QUESTIONS = (
    ("backstepping", "nn_adaptive_backstepping"),
    ("kinematic_backstepping", "nn_adaptive_backstepping/cmd_vel"),
)


def _ci(summary: dict | None) -> str:
    if not summary or summary.get("mean") is None:
        return ""
    return with_interval(summary["mean"], summary.get("ci_low"), summary.get("ci_high"))


def summarize(records: dict[str, dict], suite: RobotSuite, entries: Sequence[str]) -> dict:
    """The leaderboard of every robot, the ranking agreement, the NN questions' answers and the left-out cells."""
    runs = rows(records)
    boards = {robot: robot_board(runs, robot, entries, suite.conditions) for robot in suite.robots}
    questions = {
        robot: {f"{c} vs {b}": paired(runs, robot, b, c) for b, c in NN_QUESTIONS if b in entries and c in entries}
        for robot in suite.robots
    }
    return {
        "boards": boards,
        "ranking_agreement": ranking_agreement(boards),
        "nn_adaptive": questions,
        "left_out": cells(suite, entries)[1],
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
            "mean e_tr [m] [95 % CI], ranked by the nominal condition; "
            "implausible: runs that asked for more grip, wheel speed or torque than the robot has",
            "",
        ]
        lines.append("| controller | " + " | ".join(shown) + " | all | failures | implausible |")
        lines.append("|" + "---|" * (len(shown) + 4))
        for e in board:
            values = " | ".join(_ci(e.get(c)) for c in shown)
            lines.append(
                f"| {e['controller']} | {values} | {_ci(e['all'])} | {e['failures']}/{e['runs']} | "
                f"{e['implausible']}/{e['runs']} |"
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
    answers = [(robot, q, v) for robot, qs in summary["nn_adaptive"].items() for q, v in qs.items() if v]
    if answers:
        lines += [
            "### Does the paper's NN-adaptive law help?",
            "",
            "Pooled paired improvement of mean e_tr [%] [95 % CI] over every cell the two share "
            "(positive: the NN-adaptive law tracks better):",
            "",
            "| robot | comparison | improvement [%] | pairs |",
            "|---|---|---|---|",
        ]
        for robot, question, value in answers:
            lines.append(f"| {robot} | {question} | {_ci(value)} | {value['n']} |")
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


def board_table(summary: dict) -> pa.Table:
    """The leaderboards as one flat table (``leaderboard.csv``, ``.parquet``): a row per robot and controller."""
    flat = []
    for robot, board in summary["boards"].items():
        for e in board:
            row = {"robot": robot, **{k: e[k] for k in ("controller", "runs", "failures", "implausible")}}
            for key in ("all", *CONDITIONS):
                row |= {f"{key}_{stat}": (e.get(key) or {}).get(stat) for stat in ("mean", "ci_low", "ci_high")}
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
        fig.colorbar(image, ax=axes, label="mean e_tr [m] (blank: left out or failed)")
    return fig


def run_robot_suite(
    suite: RobotSuite,
    entries: Sequence[str],
    out: Path,
    client: Any,
    *,
    on_record: Callable[[int, int], None] = lambda done, total: None,
) -> dict:
    """Run every cell through the sweep runner (resumable), then write ``leaderboard.md``, ``.csv``, ``.parquet``,
    ``.json``, the per-run ``results.*`` and ``robots.png``."""
    import matplotlib.pyplot as plt

    plan = plan_robot_suite(suite, entries)
    outcome = run_sweep(plan, out, client, on_record=on_record)
    records = {k: r for k, r in read_records(out).items() if k in plan.runs}
    summary = summarize(records, suite, entries)
    atomic_write(out / "leaderboard.md", lambda f: f.write(board_markdown(summary, suite.conditions).encode()))
    table = board_table(summary)
    atomic_write(out / "leaderboard.parquet", lambda f: pq.write_table(table, f))
    buffer = io.BytesIO()
    pa.csv.write_csv(table, buffer)
    atomic_write(out / "leaderboard.csv", lambda f: f.write(buffer.getvalue()))
    fig = figure(summary, suite.conditions)
    atomic_write(out / "robots.png", partial(fig.savefig, format="png", dpi=110))
    plt.close(fig)
    result = {
        "suite": dataclasses.asdict(suite),
        "controllers": list(entries),
        "runs": outcome.total,
        "reused": outcome.reused,
        "errors": outcome.errors,
        "not_ok": outcome.not_ok,
        **summary,
    }
    atomic_write(out / "leaderboard.json", lambda f: f.write((json.dumps(result, indent=2) + "\n").encode()))
    return result
