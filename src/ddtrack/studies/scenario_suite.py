"""``ddtrack bench --scenario FILE ...``: controllers compared on the user's own robot.

Each ``--scenario`` file is one entry, labelled by its file stem; a run folder is a *recorded* entry, labelled by
its name (:mod:`.recorded`: its one run, at its scenario's seed, not simulated again); ``--controllers`` adds the
robots suite's entries (:func:`ddtrack.studies.robot_suite.suite_entry`), each with its defaults for the first
entry's robot (:func:`ddtrack.studies.robot_suite.entry_controller`). A fair comparison changes only the
controller, so every entry's resolved scenario must equal the first entry's outside ``[controller]`` (and
:data:`IGNORED`), and every simulated entry must drive the scenario's plant (a velocity law on a torque plant would
drive an ideal unicycle instead; a torque law cannot drive a velocity plant). Every simulated entry runs seeds
0 .. N-1 through :func:`.sweep.run_sweep` (resumable, keyed by hash) on common random numbers: seed s gives every
entry the same plant draw, disturbance and noise, so the entries pair by seed, and each entry's improvement over the
first entry's is paired that way (a recorded entry on its one seed).
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pyarrow as pa

from .._format import interval_text, significant
from ..errors import ConfigError
from ..metrics import pooled_improvement
from ..scenario import Scenario, controller_output, load_scenario, plant_kind, to_toml_dict, validate_scenario
from .board import (
    GRIP,
    MOTOR,
    STATISTICS,
    interval_columns,
    lost,
    run_statistics,
    tracking_value,
    warning_codes,
    write_board,
)
from .cells import SUITE_TASK
from .recorded import RecordedRun, read_recorded
from .robot_suite import default_entries, entry_controller, entry_labels, suite_entry
from .sweep import Configuration, Outcome, Plan, canonical, read_records, run_key, run_sweep, toml_value

STUDY = "scenario"  #: the ``label.study`` of every run of a scenario bench
#: keys that may differ between the files besides ``[controller]``: they do not change what a run does (the bench
#: runs its own seeds, 0 .. N-1)
IGNORED = ("name", "description", "simulation.seed")
FIGURE = "entries.png"


@dataclass(frozen=True)
class BenchEntry:
    """One entry of the leaderboard: its label, its resolved scenario, where it came from (the results'
    ``set.*`` columns: the file, and for a ``--controllers`` entry the ``[controller]`` it was given; a run
    folder's ``run``), and for a run folder its recorded run (None: the entry is simulated)."""

    label: str
    scenario: Scenario
    source: dict[str, Any]
    recorded: RecordedRun | None = None

    @property
    def scenario_file(self) -> Path:
        """The file its scenario was read from (a run folder's ``scenario.toml``)."""
        return Path(self.source["scenario"]) if "scenario" in self.source else Path(self.source["run"], "scenario.toml")

    @property
    def driver(self) -> str:
        """The leaderboard's controller column: the scenario's controller kind, or what drove a recorded run."""
        return self.scenario.controller.kind if self.recorded is None else self.recorded.driver


def plant_input(scenario: Scenario) -> str:
    """What the scenario's true plant takes: ``"torque"`` or ``"velocity"`` (or another input a plugin declares)."""
    plant = plant_kind(scenario.plant.model).model(scenario)(scenario.plant_params())
    return str(plant.input_kind)


def _flat(table: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested tables as one level of dotted keys, in order."""
    out: dict[str, Any] = {}
    for key, value in table.items():
        if isinstance(value, Mapping):
            out |= _flat(value, f"{prefix}{key}.")
        else:
            out[f"{prefix}{key}"] = value
    return out


def experiment(scenario: Scenario) -> dict[str, Any]:
    """What a fair comparison keeps fixed: every resolved key of ``scenario`` (dotted) outside ``[controller]``
    and :data:`IGNORED`."""
    table = {k: v for k, v in to_toml_dict(scenario).items() if k != "controller"}
    return {k: v for k, v in _flat(table).items() if k not in IGNORED}


def first_difference(reference: Scenario, other: Scenario) -> tuple[str, str, str] | None:
    """The first key of :func:`experiment` on which ``other`` differs from ``reference``: (key, other's value,
    reference's value) as TOML text ("unset" where a side lacks it); None when they describe the same experiment."""
    mine, theirs = experiment(other), experiment(reference)

    def shown(table: dict[str, Any], key: str) -> str:
        return toml_value(table[key]) if key in table else "unset"

    for key in dict.fromkeys([*theirs, *mine]):
        if (key in mine) != (key in theirs) or (key in mine and mine[key] != theirs[key]):
            return key, shown(mine, key), shown(theirs, key)
    return None


def _read(path: Path, overrides: Sequence[str]) -> tuple[Scenario, str]:
    """A ``--scenario`` file with ``overrides`` applied, validated, and what its plant takes; its problems named with
    ``--scenario`` and the file."""
    try:
        scenario = load_scenario(path, overrides=list(overrides))
        return scenario, plant_input(scenario)  # building the plant checks what it reads beyond the parameters
    except ConfigError as exc:
        where = f"{path}: {exc.field}: " if exc.field else ""  # a problem with the file itself names the file
        raise ConfigError("--scenario", where + exc.message, exc.suggestion) from None


def _given_entry(path: Path, overrides: Sequence[str]) -> BenchEntry:
    """A ``--scenario`` path as an entry: a run folder's recorded run (as it ran: no override applies), or a
    file's scenario checked to drive its plant."""
    if path.is_dir():
        scenario, recorded = read_recorded(path)
        return BenchEntry(path.name, scenario, {"run": str(path)}, recorded)
    scenario, drives = _read(path, overrides)
    _check_drives(path, scenario, drives)
    return BenchEntry(path.stem, scenario, {"scenario": str(path)})


def _given_entries(paths: Sequence[Path], overrides: Sequence[str]) -> list[BenchEntry]:
    """One entry per file or run folder: labels distinct, each the same experiment as the first entry's."""
    if not paths:
        raise ConfigError("--scenario", "needs at least one scenario file")
    entries: list[BenchEntry] = []
    for path in paths:
        entry = _given_entry(path, overrides)
        for earlier in entries:
            if earlier.label == entry.label:
                raise ConfigError(
                    "--scenario",
                    f"{_given(earlier)} and {path} have the same label '{entry.label}' (a file's stem, a folder's "
                    "name)",
                    "rename one of them",
                )
        if entries:
            difference = first_difference(entries[0].scenario, entry.scenario)
            if difference is not None:
                key, mine, theirs = difference
                raise ConfigError(
                    "--scenario",
                    f"{path.name} differs from {_given(entries[0]).name} in {key} ({mine} vs {theirs}): "
                    "a fair comparison changes only [controller]",
                )
        entries.append(entry)
    return entries


def _given(entry: BenchEntry) -> Path:
    """The ``--scenario`` argument an entry came from: its file, or its run folder."""
    return Path(entry.source["run"] if entry.recorded is not None else entry.source["scenario"])


def _check_drives(path: Path, scenario: Scenario, drives: str) -> None:
    """Refuse a file whose controller does not output what its plant takes (``drives``)."""
    output = controller_output(scenario.controller)
    if output == drives:
        return
    hint = (
        'give it a law over cmd_vel (controller.inner = "none", or kinematic_backstepping)'
        if output == "torque"
        else "a velocity law would drive an ideal unicycle, not this robot: use a torque law, or a plant that "
        "takes velocity commands (`ddtrack list plants`)"
    )
    raise ConfigError(
        "--scenario",
        f"{path.name}: its controller ({scenario.controller.kind}) outputs {output} commands, but its plant "
        f"'{scenario.plant.model}' takes {drives} commands",
        hint,
    )


def _controller_entries(first: BenchEntry, labels: Sequence[str], taken: Sequence[str]) -> list[BenchEntry]:
    """The robots suite's entries ``labels`` on ``first``'s experiment, each with its defaults for that robot."""
    scenario, path = first.scenario, first.scenario_file
    drives = plant_input(scenario)
    fitting = [label for label in default_entries() if suite_entry(label).output == drives]
    entries = []
    for label in entry_labels(labels, where="bench --scenario"):
        entry = suite_entry(label, where="bench --scenario")
        if label in taken:
            raise ConfigError(
                "--controllers",
                f"'{label}' is also the label of a --scenario file or run folder: each entry needs its own label",
                "rename the file or folder",
            )
        if entry.output != drives:
            raise ConfigError(
                "--controllers",
                f"{label} outputs {entry.output} commands, but the plant of {path.name} "
                f"('{scenario.plant.model}') takes {drives} commands",
                f"choose from: {', '.join(fitting)}" if fitting else "",
            )
        preset = scenario.robot.preset_robot()
        params = {"mass": scenario.robot.mass, "wheel_radius": scenario.robot.wheel_radius}  # what the law believes
        speeds = (preset.max_speed, preset.max_yaw_rate) if preset is not None else (None, None)
        controller = entry_controller(entry, params, *speeds)
        data = to_toml_dict(scenario) | {"controller": controller}
        try:
            resolved = validate_scenario(data, base_dir=path.parent)
        except ConfigError as exc:
            message = f"{label} on {path.name}: {exc.field}: {exc.message}"
            raise ConfigError("--controllers", message, exc.suggestion) from None
        entries.append(BenchEntry(label, resolved, {"scenario": str(path), "controller": controller}))
    return entries


def bench_entries(
    paths: Sequence[Path], controllers: Sequence[str] = (), overrides: Sequence[str] = ()
) -> list[BenchEntry]:
    """Every entry of ``bench --scenario``, checked before anything runs (a :class:`ConfigError` naming the option
    otherwise): the files' and run folders' entries (``overrides`` applied to each file), then the ``controllers``
    added on the first entry's experiment."""
    given = _given_entries(paths, overrides)
    if not controllers:
        return given
    return given + _controller_entries(given[0], controllers, [e.label for e in given])


def plan_entries(entries: Sequence[BenchEntry], seeds: int) -> Plan:
    """Seeds 0 .. ``seeds`` - 1 of every simulated entry (a recorded one has run); keys hash the entry's label with
    its scenario and seed."""
    simulated = [e for e in entries if e.recorded is None]
    configurations = [Configuration(e.label, e.source, e.scenario, {"study": STUDY}) for e in simulated]
    runs = {}
    for index, configuration in enumerate(configurations):
        cell = canonical({"labels": configuration.labels, "controller": configuration.controller})
        for seed in range(seeds):
            key = hashlib.sha256((run_key(configuration.scenario, seed) + cell).encode()).hexdigest()
            runs[key] = (index, seed)
    return Plan(configurations, runs, chunk=max(SUITE_TASK, min(seeds, 64)))


# --- the leaderboard -----------------------------------------------------------------------------------------


def _row(entry: str, seed: int, status: str, metrics: Mapping[str, Any] | None) -> dict:
    """A run as the board counts it: its metrics, entry, seed, status, and its grip and motor flags."""
    codes = warning_codes(metrics)
    flags = {"grip": bool(codes & set(GRIP)), "motor": bool(codes & set(MOTOR))}
    return {**(metrics or {}), "entry": entry, "seed": seed, "status": status, **flags}


def rows(records: Mapping[str, dict], entries: Sequence[BenchEntry] = ()) -> list[dict]:
    """One flat row per run of a scenario bench (:func:`_row`): the sweep's ``records``, and the one run of each
    recorded entry among ``entries``, as its ``metrics.json`` has it."""
    out = [
        _row(record["configuration"]["controller"], record["seed"], record["status"], record["metrics"])
        for record in records.values()
        if (record["configuration"].get("labels") or {}).get("study") == STUDY
    ]
    for entry in entries:
        if (run := entry.recorded) is not None:
            out.append(_row(entry.label, run.seed, run.metrics["status"], run.metrics))
    return sorted(out, key=lambda r: (r["entry"], r["seed"]))


def _recorded(entry: BenchEntry) -> dict | None:
    """Where a recorded entry's run came from, for the board (None: a simulated entry)."""
    run = entry.recorded
    return None if run is None else {"run": str(run.folder), "seed": run.seed, "reproducible": run.reproducible}


def leaderboard(records: Mapping[str, dict], entries: Sequence[BenchEntry]) -> list[dict]:
    """Per entry: the statistics of its runs (:func:`ddtrack.studies.board.run_statistics`), runs ok, diverged (or
    non-finite) and raised, runs that lost the path, runs flagged for grip and for the motors, each seed's mean
    e_tr, and the pooled paired improvement of the mean e_tr over the first entry's, by seed, over the seeds where
    both tracked (a recorded entry is one run, at its seed: no interval); ranked by mean e_tr."""
    runs = rows(records, entries)
    reference = {r["seed"]: tracking_value(r) for r in runs if r["entry"] == entries[0].label}
    board = []
    for entry in entries:
        mine = [r for r in runs if r["entry"] == entry.label]
        improvement = None
        if entry.label != entries[0].label:
            baselines = [reference[r["seed"]] if r["seed"] in reference else None for r in mine]
            improvement = pooled_improvement(baselines, [tracking_value(r) for r in mine])
        board.append(
            {
                "entry": entry.label,
                "controller": entry.driver,
                **run_statistics(mine),
                "ok": sum(r["status"] == "ok" for r in mine),
                "diverged": sum(r["status"] in ("diverged", "non_finite") for r in mine),
                "errors": sum(r["status"] not in ("ok", "diverged", "non_finite") for r in mine),
                "grip": sum(r["grip"] for r in mine),
                "motor": sum(r["motor"] for r in mine),
                "e_tr_mean_by_seed": {str(r["seed"]): tracking_value(r) for r in mine},
                "status_by_seed": {str(r["seed"]): _outcome(r) for r in mine},
                "improvement": improvement,
                "recorded": _recorded(entry),
            }
        )
    return sorted(board, key=lambda e: math.inf if e["e_tr_mean"]["mean"] is None else e["e_tr_mean"]["mean"])


def _outcome(row: dict) -> str:
    """``ok``, ``lost`` (ran to the end off the path) or the failure's status."""
    return "lost" if lost(row) else row["status"]


def board_markdown(board: Sequence[dict], reference: str) -> str:
    """``leaderboard.md``: per entry, mean [95 % CI over seeds] of each statistic, runs ok and diverged, runs
    flagged implausible, the paired improvement over ``reference``; what the recorded entries are; then each seed's
    mean e_tr."""
    lines = [
        "Mean [95 % CI] over seeds; e_tr over each run's metric window. vs "
        f"{reference}: the pooled paired improvement of mean e_tr over the first --scenario entry, by seed "
        f"(positive: better), over the seeds where both tracked{_paired_on(board, reference)}. lost: runs that "
        "ended off the path (e_tr beyond "
        "simulation.lost_path_error for the last fifth of the window), counted apart like the diverged ones. "
        "grip, motor: runs that asked for more grip than the floor has, or more wheel speed or torque than the "
        "motors give.",
        "",
        "| entry | controller | mean e_tr [m] | RMS e_tr [m] | max e_tr [m] | effort [N² m² s] | saturated [%] "
        f"| tracked | diverged | lost | grip | motor | vs {reference} [%] |",
        "|" + "---|" * 13,
    ]
    for e in board:
        lines.append(
            f"| {e['entry']} | {e['controller']} | {interval_text(e['e_tr_mean'])} | {interval_text(e['e_tr_rms'])} "
            f"| {interval_text(e['e_tr_max'])} | {interval_text(e['effort'])} "
            f"| {interval_text(e['saturation_fraction'], 100.0)} | {e['ok'] - e['lost']}/{e['runs']} | {e['diverged']} "
            f"| {e['lost']} "
            f"| {e['grip']}/{e['runs']} | {e['motor']}/{e['runs']} | {interval_text(e['improvement'])} |"
        )
    lines += _recorded_notes(board)
    seeds = sorted({int(s) for e in board for s in e["e_tr_mean_by_seed"]})
    if len(seeds) > 1 and all(seeds_agree(e) for e in board):
        lines += [
            "",
            "Every seed gave each entry the same run: the scenario draws nothing at random, so the intervals show "
            "no spread. Add [randomize] draws (mass, friction), [noise] or a random disturbance to see how the "
            "entries fare on robots that differ.",
        ]
    lines += ["", "Mean e_tr [m] per seed (every entry meets the same plant draw, disturbance and noise):", ""]
    lines.append("| entry | " + " | ".join(f"seed {s}" for s in seeds) + " |")
    lines.append("|" + "---|" * (len(seeds) + 1))
    for e in board:
        shown = (
            significant(e["e_tr_mean_by_seed"][str(s)])
            if e["e_tr_mean_by_seed"].get(str(s)) is not None
            else e["status_by_seed"].get(str(s), "")
            for s in seeds
        )
        lines.append(f"| {e['entry']} | " + " | ".join(shown) + " |")
    return "\n".join(lines) + "\n"


def _paired_on(board: Sequence[dict], reference: str) -> str:
    """The reference's one seed, where the reference is a recorded run ('': a simulated reference)."""
    recorded = next((e["recorded"] for e in board if e["entry"] == reference and e.get("recorded")), None)
    return (
        ""
        if recorded is None
        else f" ({reference} is a recorded run: the others pair on its one seed, {recorded['seed']})"
    )


def _recorded_notes(board: Sequence[dict]) -> list[str]:
    """A line per recorded entry: where its one run comes from, whether another entry ran its seed, and whether
    it reproduces."""
    notes = []
    for e in board:
        if not (recorded := e.get("recorded")):
            continue
        seed = recorded["seed"]
        note = (
            f"{e['entry']}: recorded in {recorded['run']} (driven by {e['controller']}), one run at seed {seed}, "
            "scored against the true pose and not simulated again: no interval."
        )
        if len(board) > 1 and not any(str(seed) in o["status_by_seed"] for o in board if o is not e):
            note += f" No other entry ran seed {seed}, so nothing pairs with it: give --seeds {seed + 1} or more."
        if not recorded["reproducible"]:  # realtime: the wall clock decided which command each period held
            note += " A realtime run: the wall clock timed its commands, so no rerun gives it to the bit."
        notes += ["", note]
    return notes


def seeds_agree(entry: dict) -> bool:
    """Every seed of the entry ran ok and gave the same mean e_tr to the last bit."""
    values = list(entry["e_tr_mean_by_seed"].values())
    return None not in values and len(set(values)) == 1


def board_table(board: Sequence[dict]) -> pa.Table:
    """The leaderboard as a flat table (``leaderboard.csv``, ``.parquet``): a row per entry, a mean, a ci_low and
    a ci_high column per statistic and for the improvement."""
    flat = []
    for e in board:
        row = {k: e[k] for k in ("entry", "controller", "runs", "ok", "diverged", "errors", "lost", "grip", "motor")}
        for key in (*STATISTICS, "improvement"):
            row |= interval_columns(key, e[key])
        flat.append(row)
    return pa.Table.from_pylist(flat)


def figure(board: Sequence[dict], reference: str) -> Any:
    """``entries.png``: each entry's mean e_tr with its 95 % interval over seeds, and every seed's value."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(layout="constrained", figsize=(6.4, 1.2 + 0.45 * len(board)))
    for i, e in enumerate(board):
        values = [v for v in e["e_tr_mean_by_seed"].values() if v is not None]
        ax.plot(values, [i] * len(values), "o", color="0.6", markersize=3, label="a seed" if i == 0 else None)
        summary = e["e_tr_mean"]
        if summary["mean"] is None:
            continue
        low, high = (summary["mean"] if summary[k] is None else summary[k] for k in ("ci_low", "ci_high"))
        color = "C1" if e["entry"] == reference else "C0"
        error = [[summary["mean"] - low], [high - summary["mean"]]]
        ax.errorbar(summary["mean"], i, xerr=error, fmt="D", color=color, capsize=4)
    ax.set(
        yticks=range(len(board)),
        yticklabels=[e["entry"] for e in board],
        xlabel="mean e_tr per run [m]",
        title=f"mean and 95 % interval over seeds (orange: {reference}, the reference)",
    )
    ax.set_xlim(left=0.0)
    ax.invert_yaxis()  # the best on top, as in leaderboard.md
    return fig


def run_scenario_bench(
    entries: Sequence[BenchEntry],
    seeds: int,
    out: Path,
    client: Any,
    *,
    on_record: Callable[[int, int], None] = lambda done, total: None,
    on_programs: Callable[[int, int], None] = lambda needed, held: None,
) -> dict:
    """Run every simulated entry's seeds through the sweep runner (resumable), then write ``leaderboard.md``,
    ``.csv``, ``.parquet``, ``.json``, the simulated runs' ``results.*`` and ``entries.png``; return
    ``leaderboard.json``'s content."""
    plan = plan_entries(entries, seeds)
    outcome = Outcome(total=0, reused=0, ran=0, errors=0, not_ok=0, warnings={})  # only recorded runs: none to run
    if plan.runs:
        outcome = run_sweep(plan, out, client, on_record=on_record, on_programs=on_programs)
    records = {k: r for k, r in read_records(out).items() if k in plan.runs}
    board = leaderboard(records, entries)
    reference = entries[0].label
    summary = {
        "scenarios": [e.source["scenario"] for e in entries if "controller" not in e.source and not e.recorded],
        "recorded": [e.source["run"] for e in entries if e.recorded],
        "entries": [e.label for e in entries],
        "reference": reference,
        "seeds": seeds,
        "runs": outcome.total,
        "reused": outcome.reused,
        "errors": outcome.errors,
        "not_ok": outcome.not_ok,
        "leaderboard": board,
    }
    figures = {FIGURE: figure(board, reference)}
    write_board(out, board_markdown(board, reference), board_table(board), figures, summary)
    return summary
