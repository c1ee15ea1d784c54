"""``ddtrack bench``: controllers x trajectories x uncertainty levels x seeds, and a robustness map, on common
random numbers, through the sweep runner; a leaderboard and its figures.

Every cell is a resolved scenario run by :func:`.sweep.run_sweep` (vmapped chunks on Dask, records keyed by
hash, resumable). Seed s gives every controller the same plant draw, disturbance and noise, so improvements are
paired by (trajectory, level, seed). ``backstepping_tuned`` is backstepping with the gains ``ddtrack tune`` finds on
the paper's two cases (the suite runs the tuning first and keeps its result in ``tuned.toml``).
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from .._format import interval_text as _ci
from .._format import significant
from ..errors import ConfigError
from ..metrics import pooled_improvement
from ..outdir import atomic_write
from ..scenario import controller_kinds, kanayama_gains, load_scenario, tracking_kinds
from ..shipped import scenario_path
from .board import STATISTICS, interval_columns, run_statistics, tracking_value, write_board
from .cells import SUITE_TASK
from .sweep import Configuration, Plan, canonical, read_records, run_key, run_sweep, toml_value
from .tune import problems, tune

TUNED = "backstepping_tuned"
BASELINE = "backstepping"

# the paper's wheel-torque disturbance (model.md §1.4)
_PAPER_DISTURBANCE = {"kind": "sinusoid", "bias": [0.03, 0.0], "amplitude": [0.05, -0.05], "frequency": 0.5}
#: uncertainty level -> replacements of the scenario's [plant], [disturbance] and [noise] (the nominal [robot] stays)
LEVELS: dict[str, dict[str, Any]] = {
    "exact": {"plant": {}, "disturbance": {"kind": "none"}, "noise": {}},
    "paper": {
        "plant": {
            "mass": 12.0,
            "inertia": 0.70,
            "com_offset": 0.08,
            "viscous_friction": 0.005,
            "coulomb_friction": 0.05,
        },
        "disturbance": _PAPER_DISTURBANCE,
        "noise": {},
    },
    "severe": {
        "plant": {
            "mass": 15.0,
            "inertia": 0.84,
            "com_offset": 0.08,
            "viscous_friction": 0.015,
            "coulomb_friction": 0.15,
        },
        "disturbance": _PAPER_DISTURBANCE,
        "noise": {"position_std": 0.002, "heading_std": 0.002},
    },
}


def _spline_points(seed: int = 7, count: int = 8) -> list[list[float]]:
    """A fixed random smooth path: waypoints marching along +x with random lateral offsets (filleted)."""
    rng = np.random.Generator(np.random.PCG64(seed))
    return [[4.0 * i, float(np.round(rng.uniform(-2.0, 2.0), 3)) if i else 0.0] for i in range(count)]


_OPEN_PATH = ["simulation.duration=50", "simulation.metric_window=[10, 50]", "initial.pose=[0, 0.3, 0]"]
#: trajectory -> (shipped scenario, overrides); the scenario supplies the nominal robot, timing and start
TRAJECTORIES: dict[str, tuple[str, list[str]]] = {
    "line": ("paper_line", []),
    "square": ("paper_square", []),
    "circle": ("circle", []),
    "figure_eight": ("figure_eight", []),
    "sinusoid": (
        "paper_line",
        [
            *_OPEN_PATH,
            'trajectory={kind="sinusoid", start=[0.0, 0.0], heading=0.0, speed=0.5, amplitude=1.0, wavelength=12.0}',
        ],
    ),
    "spline": (
        "paper_line",
        [
            *_OPEN_PATH,
            f'trajectory={{kind="waypoints", points={toml_value(_spline_points())}, speed=0.5, corner_radius=1.5}}',
        ],
    ),
}


@dataclass(frozen=True)
class Suite:
    """A benchmark suite (``ddtrack bench --suite``): the cells run for every controller, the seeds per cell,
    the robustness map's grid and the tuning budget of ``backstepping_tuned``."""

    trajectories: tuple[str, ...]
    levels: tuple[str, ...]
    seeds: int
    robustness_mass: tuple[float, ...]  #: plant mass factors of the robustness map (x nominal)
    robustness_friction: tuple[float, ...]  #: wheel friction factors (x the paper's)
    tune_steps: int
    overrides: tuple[str, ...] = ()  #: applied to every cell last (e.g. a shorter duration, for tests)


SUITES = {
    "quick": Suite(("line", "circle", "sinusoid"), ("paper",), 2, (1.0, 1.5), (1.0, 3.0), 6),
    "standard": Suite(tuple(TRAJECTORIES), tuple(LEVELS), 5, (0.8, 1.0, 1.2, 1.5, 1.8), (0.0, 1.0, 3.0, 5.0), 40),
}


def controller_names(requested: Sequence[str] | None) -> list[str]:
    """Every registered controller that tracks a reference in closed loop, and tuned backstepping; or the requested
    ones (checked: a kind that plays a plan back, such as ``replay``, has nothing to rank here)."""
    kinds = controller_kinds()
    known = [*tracking_kinds(), TUNED]
    names = list(requested) if requested else known
    for name in names:
        if name in kinds and name not in known:
            raise ConfigError(
                "--controllers",
                f"'{name}' does not track a reference in closed loop (it plays a plan back), so a suite cannot rank it",
                f"choose from: {', '.join(known)}",
            )
        if name not in known:
            raise ConfigError("--controllers", f"unknown controller '{name}'", f"choose from: {', '.join(known)}")
    if len(set(names)) != len(names):
        raise ConfigError("--controllers", "lists a controller twice")
    return names


def _section_overrides(level: str) -> list[str]:
    return [f"{section}={toml_value(value)}" for section, value in LEVELS[level].items()]


def _configuration(
    controller: str,
    base: str,
    overrides: list[str],
    tuned_gains: Sequence[float] | None,
    labels: dict,
    common: Sequence[str] = (),
) -> Configuration:
    kind = BASELINE if controller == TUNED else controller
    extra = []
    if controller == TUNED:
        assert tuned_gains is not None, "the tuned controller's cells are planned once its gains are known"
        extra = [f"controller.gains={toml_value(list(tuned_gains))}"]
    scenario = load_scenario(scenario_path(base), overrides=[*overrides, *extra, *common], controller=kind)
    return Configuration(controller, {"overrides": [*overrides, *extra, *common]}, scenario, labels)


def plan_suite(suite: Suite, controllers: Sequence[str], tuned_gains: Sequence[float] | None) -> Plan:
    """Every cell resolved (bad input fails here); keys hash the cell's labels with the scenario and seed."""
    configurations: list[Configuration] = []
    for controller in controllers:
        for trajectory in suite.trajectories:
            base, overrides = TRAJECTORIES[trajectory]
            for level in suite.levels:
                labels: dict[str, str | float] = {"study": "leaderboard", "trajectory": trajectory, "level": level}
                configurations.append(
                    _configuration(
                        controller, base, [*overrides, *_section_overrides(level)], tuned_gains, labels, suite.overrides
                    )
                )
        for mass in suite.robustness_mass:
            for friction in suite.robustness_friction:
                plant = {
                    **LEVELS["paper"]["plant"],
                    "mass": 10.0 * mass,
                    "viscous_friction": 0.005 * friction,
                    "coulomb_friction": 0.05 * friction,
                }
                sections = {**LEVELS["paper"], "plant": plant}
                overrides = [f"{section}={toml_value(value)}" for section, value in sections.items()]
                labels = {
                    "study": "robustness",
                    "trajectory": "circle",
                    "mass_factor": mass,
                    "friction_factor": friction,
                }
                configurations.append(
                    _configuration(controller, "circle", overrides, tuned_gains, labels, suite.overrides)
                )
    runs = {}
    for index, configuration in enumerate(configurations):
        for seed in range(suite.seeds):
            cell = canonical({"labels": configuration.labels, "controller": configuration.controller})
            key = hashlib.sha256((run_key(configuration.scenario, seed) + cell).encode()).hexdigest()
            runs[key] = (index, seed)
    return Plan(configurations, runs, chunk=max(SUITE_TASK, suite.seeds))


# --- the leaderboard -----------------------------------------------------------------------------------------


def _rows(records: dict[str, dict], study: str) -> list[dict]:
    rows = []
    for record in records.values():
        labels = record["configuration"].get("labels", {})
        if labels.get("study") == study:
            rows.append(
                {
                    "controller": record["configuration"]["controller"],
                    "seed": record["seed"],
                    "status": record["status"],
                    **labels,
                    **(record["metrics"] or {}),
                }
            )
    return rows


def leaderboard(records: dict[str, dict], controllers: Sequence[str]) -> list[dict]:
    """Per controller over every leaderboard cell: mean and 95 % CI of each statistic (over the runs that tracked),
    failures, runs that lost the path, and the paired improvement of the mean tracking error over backstepping and
    over tuned backstepping (over the pairs where both tracked)."""
    rows = _rows(records, "leaderboard")
    by_cell = {(r["controller"], r["trajectory"], r["level"], r["seed"]): r for r in rows}
    board = []
    for name in controllers:
        mine = [r for r in rows if r["controller"] == name]
        entry: dict[str, Any] = {"controller": name, **run_statistics(mine)}
        for reference in (BASELINE, TUNED):
            others = [by_cell.get((reference, r["trajectory"], r["level"], r["seed"]), {}) for r in mine]
            entry[f"improvement_over_{reference}"] = (
                None
                if reference == name
                else pooled_improvement(
                    [tracking_value(o) if o else None for o in others], [tracking_value(r) for r in mine]
                )
            )
        board.append(entry)
    return sorted(board, key=lambda e: math.inf if e["e_tr_mean"]["mean"] is None else e["e_tr_mean"]["mean"])


def board_markdown(board: list[dict], cells: dict) -> str:
    """The leaderboard as Markdown (``leaderboard.md``): mean [95 % CI] of each statistic per controller, paired
    improvements over backstepping and tuned backstepping, then mean e_tr [m] per trajectory and level
    (``cells``, from :func:`cell_means`)."""
    lines = [
        "| controller | mean e_tr [m] | RMS e_tr [m] | max e_tr [m] | effort [N² m² s] | saturated [%] | failures "
        "| lost [%] | vs backstepping [%] | vs tuned backstepping [%] |",
        "|" + "---|" * 10,
    ]
    for e in board:
        lines.append(
            f"| {e['controller']} | {_ci(e['e_tr_mean'])} | {_ci(e['e_tr_rms'])} | {_ci(e['e_tr_max'])} | "
            f"{_ci(e['effort'])} | {_ci(e['saturation_fraction'], 100.0)} | {e['failures']}/{e['runs']} | "
            f"{e['lost']}: {_ci(e['lost_rate'], 100.0)} | "
            f"{_ci(e['improvement_over_' + BASELINE])} | {_ci(e['improvement_over_' + TUNED])} |"
        )
    lines += [
        "",
        "Statistics over the runs that tracked to the end; lost: runs that ended off the path (e_tr beyond a quarter "
        "of the reference's width for the last fifth of the window), with the rate's 95 % interval; improvements "
        "over the pairs where both tracked.",
        "",
        "Mean e_tr [m] per trajectory and uncertainty level (mean over seeds; failed and lost runs left out):",
        "",
    ]
    columns = sorted({(t, lv) for (_, t, lv) in cells})
    lines.append("| controller | " + " | ".join(f"{t} / {lv}" for t, lv in columns) + " |")
    lines.append("|" + "---|" * (len(columns) + 1))
    for e in board:
        values = [cells.get((e["controller"], t, lv)) for t, lv in columns]
        lines.append(f"| {e['controller']} | " + " | ".join("" if v is None else significant(v) for v in values) + " |")
    return "\n".join(lines) + "\n"


def cell_means(records: dict[str, dict]) -> dict[tuple[str, str, str], float]:
    """Mean e_tr_mean [m] over the successful seeds of each (controller, trajectory, level) of the leaderboard."""
    groups: dict[tuple, list[float]] = {}
    for r in _rows(records, "leaderboard"):
        if tracking_value(r) is not None:
            groups.setdefault((r["controller"], r["trajectory"], r["level"]), []).append(r["e_tr_mean"])
    return {k: float(np.mean(v)) for k, v in groups.items()}


def board_table(board: list[dict]) -> pa.Table:
    """The leaderboard as a flat table (``leaderboard.csv``, ``.parquet``): one row per controller, a mean, a
    ci_low and a ci_high column per statistic and improvement."""
    flat = []
    for e in board:
        row = {"controller": e["controller"], "runs": e["runs"], "failures": e["failures"], "lost": e["lost"]}
        for key in (*STATISTICS, "lost_rate", f"improvement_over_{BASELINE}", f"improvement_over_{TUNED}"):
            row |= interval_columns(key, e[key])
        flat.append(row)
    return pa.Table.from_pylist(flat)


def figures(records: dict[str, dict], controllers: Sequence[str], suite: Suite) -> dict[str, Any]:
    """``robustness.png`` (mean e_tr over mass x friction factors, one panel per controller) and
    ``boxplots.png`` (e_tr_mean per controller, one panel per trajectory)."""
    import matplotlib.pyplot as plt

    out = {}
    rows = [r for r in _rows(records, "robustness") if r["status"] == "ok" and r.get("e_tr_mean") is not None]
    columns = min(4, len(controllers))
    fig, axes = plt.subplots(
        math.ceil(len(controllers) / columns),
        columns,
        squeeze=False,
        layout="constrained",
        figsize=(3.2 * columns, 2.8 * math.ceil(len(controllers) / columns)),
    )
    values = [r["e_tr_mean"] for r in rows] or [1e-3]
    low, high = max(min(values), 1e-5), max(values)
    for ax, name in zip(axes.flat, controllers, strict=False):
        grid = np.full((len(suite.robustness_mass), len(suite.robustness_friction)), np.nan)
        for i, mass in enumerate(suite.robustness_mass):
            for j, friction in enumerate(suite.robustness_friction):
                cell = [
                    r["e_tr_mean"]
                    for r in rows
                    if r["controller"] == name and r["mass_factor"] == mass and r["friction_factor"] == friction
                ]
                grid[i, j] = np.mean(cell) if cell else np.nan
        image = ax.imshow(
            grid,
            origin="lower",
            aspect="auto",
            cmap="viridis",
            norm=plt.matplotlib.colors.LogNorm(vmin=low, vmax=max(high, low * 1.01)),
        )
        ax.set(
            title=name,
            xticks=range(len(suite.robustness_friction)),
            yticks=range(len(suite.robustness_mass)),
            xticklabels=[f"{f:g}" for f in suite.robustness_friction],
            yticklabels=[f"{m:g}" for m in suite.robustness_mass],
            xlabel="friction x paper",
            ylabel="mass x nominal",
        )
    for ax in list(axes.flat)[len(controllers) :]:
        ax.axis("off")
    fig.colorbar(image, ax=axes, label="mean e_tr [m] (circle, NaN: failed)")
    out["robustness.png"] = fig
    board_rows = [r for r in _rows(records, "leaderboard") if r["status"] == "ok" and r.get("e_tr_mean") is not None]
    fig, axes = plt.subplots(
        1,
        len(suite.trajectories),
        squeeze=False,
        layout="constrained",
        figsize=(max(4.0, 0.45 * len(controllers)) * len(suite.trajectories) / 1.5, 4.0),
    )
    for ax, trajectory in zip(axes.flat, suite.trajectories, strict=True):
        data = [
            [r["e_tr_mean"] for r in board_rows if r["controller"] == name and r["trajectory"] == trajectory]
            or [np.nan]
            for name in controllers
        ]
        ax.boxplot(data, tick_labels=controllers)
        ax.set_yscale("log")
        ax.set_title(trajectory)
        ax.tick_params(axis="x", labelrotation=90)
    axes.flat[0].set_ylabel("mean e_tr per run [m]")
    out["boxplots.png"] = fig
    return out


def tune_on_paper_cases(steps: int, seeds: int = 2) -> list[float]:
    """Backstepping's gains tuned by ``ddtrack tune`` (its defaults: e_tr^2 over the metric window) on both paper
    cases."""
    specs = [load_scenario(scenario_path(name)) for name in ("paper_line", "paper_square")]
    return list(tune(problems(specs, range(seeds)), kanayama_gains(specs[0].controller), steps=steps).gains)


def run_suite(
    suite: Suite,
    controllers: Sequence[str],
    out: Path,
    client: Any,
    *,
    on_record: Callable[[int, int], None] = lambda done, total: None,
    on_programs: Callable[[int, int], None] = lambda needed, held: None,
) -> dict:
    """Tune (or reuse ``out/tuned.toml``), run every cell through the sweep runner, write the leaderboard
    (``leaderboard.md``, ``.csv``, ``.parquet``), the per-run ``results.parquet``/``.csv`` and the figures."""
    import tomllib

    tuned = None
    if TUNED in controllers:
        stored = out / "tuned.toml"
        if stored.is_file():
            tuned = tomllib.loads(stored.read_text())["controller"]["gains"]
        else:
            tuned = tune_on_paper_cases(suite.tune_steps)
            text = (
                f"# ddtrack bench: gains tuned by ddtrack tune on paper_line and paper_square\n[controller]\n"
                f'kind = "backstepping"\ngains = {toml_value(tuned)}\n'
            )
            atomic_write(stored, lambda f: f.write(text.encode()))
    plan = plan_suite(suite, controllers, tuned)
    outcome = run_sweep(plan, out, client, on_record=on_record, on_programs=on_programs)
    records = {k: r for k, r in read_records(out).items() if k in plan.runs}
    board = leaderboard(records, controllers)
    summary = {
        "suite": dataclasses.asdict(suite),
        "controllers": list(controllers),
        "tuned_gains": tuned,
        "runs": outcome.total,
        "reused": outcome.reused,
        "errors": outcome.errors,
        "not_ok": outcome.not_ok,
        "leaderboard": board,
    }
    markdown = board_markdown(board, cell_means(records))
    write_board(out, markdown, board_table(board), figures(records, controllers, suite), summary)
    return summary
