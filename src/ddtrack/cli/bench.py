"""``ddtrack bench``: the suites (``--suite quick|standard|robots``) and the user's own scenarios (``--scenario``),
registered on the ``ddtrack`` group."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import click

from ..cluster import check_cluster_options, cluster_options, dask_client
from ..errors import ConfigError
from . import cli, enable_compilation_cache, overwrite_option, progress_bar, study_progress

SCENARIO_SEEDS = 10  #: seeds per entry of a --scenario bench, unless --seeds says otherwise


def _names(controllers: str | None) -> list[str] | None:
    """``--controllers A,B`` as a list; None when not given."""
    return [c.strip() for c in controllers.split(",") if c.strip()] if controllers else None


@cli.command(short_help="Rank controllers over a suite, or on your own robot (--scenario FILE ...).")
@click.option(
    "--suite",
    "suite_name",
    type=click.Choice(["quick", "standard", "robots"]),
    help="quick: 3 trajectories, the paper's uncertainty, 2 seeds; standard: 6 x 3 levels x 5 seeds; robots: "
    "4 robot presets x 2 paths (a figure eight, a filleted square) x 6 conditions x 3 seeds, each robot on the "
    "plant it really has. [default: quick, without --scenario]",
)
@click.option(
    "--scenario",
    "scenarios",
    multiple=True,
    metavar="FILE.toml|RUN",
    type=click.Path(path_type=Path),
    help="Your own robot (repeatable; not with --suite): each file is an entry labelled by its stem, and the files "
    "may differ only in [controller]. A run folder (ddtrack run's, or ddtrack robot's: a foreign controller's) is "
    "an entry labelled by its name: its one run, at its simulation.seed, ranked as recorded, not run again. "
    "Improvements are over the first entry's, paired by seed.",
)
@click.option(
    "--seeds",
    type=click.IntRange(min=1, max=1000),
    help=f"Seeds per entry of a --scenario bench, 0 .. N-1 on common random numbers [default: {SCENARIO_SEEDS}]; "
    "the suites fix their own.",
)
@click.option(
    "--controllers",
    metavar="A,B,...",
    help="Controllers to rank, any registered kind that tracks a reference in closed loop (plugins' too; not "
    "replay) [default: all of them, and backstepping_tuned on quick and standard; on robots, also "
    "KIND/cmd_vel, a torque law without its inner loop, sent as cmd_vel]. With --scenario: entries to add, as on "
    "robots, each with its defaults for the first file's robot (one the plant does not take is refused).",
)
@click.option(
    "--set",
    "overrides",
    multiple=True,
    metavar="SECTION.KEY=VALUE",
    help="Override a value in every cell (or every --scenario file), last: e.g. a shorter simulation.duration to "
    "try a suite quickly. Other overrides make another study: a folder of the first is replaced only with "
    "--overwrite.",
)
@click.option(
    "--out",
    type=click.Path(path_type=Path),
    default=Path("runs/bench"),
    show_default=True,
    help="Result folder (rerun to resume): leaderboard.md/.csv/.parquet/.json, results.*, figures.",
)
@overwrite_option
@cluster_options
def bench(
    suite_name: str | None,
    scenarios: tuple[Path, ...],
    seeds: int | None,
    controllers: str | None,
    overrides: tuple[str, ...],
    out: Path,
    overwrite: bool,
    scheduler: str | None,
    scheduler_file: Path | None,
    workers: int | None,
) -> int:
    """Rank controllers on common random numbers through the sweep runner (resumable), with 95 % intervals and
    paired improvements; see docs/benchmarks.md.

    \b
    --suite quick|standard: every controller over trajectories, uncertainty levels and seeds, with a
      robustness map over mass and friction;
    --suite robots: on four robot presets, each on the plant it really has, under six conditions;
    --scenario FILE.toml ...: on your own robot. Each file is an entry, and each run folder (ddtrack run's,
      ddtrack robot's) an entry of its one recorded run; every section but [controller] must resolve the same
      in every entry (the first differing key is named otherwise). --controllers adds
      registered controllers on the first file's robot. Writes leaderboard.md/.csv/.parquet/.json (mean e_tr,
      RMS, max, effort, saturation with intervals; runs ok and diverged; grip and motor flags; the improvement
      over the first entry, paired by seed), results.* and entries.png.

    \b
    Example: ddtrack bench --scenario default.toml --scenario tuned.toml --seeds 5 --out runs/mine
    """
    check_cluster_options(scheduler, scheduler_file, workers)
    if scenarios and suite_name is not None:
        raise ConfigError(
            "--scenario", "cannot be combined with --suite: a bench runs your files or a suite", "drop one of them"
        )
    if scenarios:
        return _bench_scenarios(
            scenarios,
            seeds or SCENARIO_SEEDS,
            controllers,
            overrides,
            out,
            overwrite,
            scheduler,
            scheduler_file,
            workers,
        )
    if seeds is not None:
        raise ConfigError(
            "--seeds", "applies to --scenario benches: the suites fix their own (quick 2, standard 5, robots 3)"
        )
    if suite_name == "robots":
        return _bench_robots(controllers, overrides, out, overwrite, scheduler, scheduler_file, workers)
    from ..outdir import check_output, start_resumable
    from ..studies.suite import SUITES, board_markdown, cell_means, controller_names, plan_suite, run_suite

    suite_name = suite_name or "quick"
    names = controller_names(_names(controllers))
    suite = dataclasses.replace(SUITES[suite_name], overrides=(*SUITES[suite_name].overrides, *overrides))
    plan_suite(suite, names, (1.0, 55.0, 15.0))  # every cell resolves: bad input writes nothing
    study = f"{suite_name}: {', '.join(names)}" + _changed(overrides)
    resume = check_output(out, command="bench", overwrite=overwrite, study=study)  # the same suite resumes
    enable_compilation_cache()
    with dask_client(scheduler, scheduler_file, workers) as client, progress_bar(0, "runs") as advance:
        start_resumable(out, command="bench", study=study, resume=resume)
        summary = run_suite(suite, names, out, client, **study_progress(advance))
    from ..studies.sweep import read_records

    click.echo(board_markdown(summary["leaderboard"], cell_means(read_records(out))), nl=False)
    click.echo(
        f"{summary['runs']} runs ({summary['reused']} reused), {summary['not_ok']} diverged or non-finite, "
        f"{summary['errors']} errors; wrote {out}/leaderboard.md, .csv, .parquet, .json, results.*, "
        "robustness.png, boxplots.png"
    )
    return 1 if summary["errors"] else 0


def _changed(overrides: tuple[str, ...]) -> str:
    """The study's ``--set`` overrides, as its description in the folder names them (none: nothing)."""
    return "; set " + ", ".join(overrides) if overrides else ""


def _bench_robots(
    controllers: str | None,
    overrides: tuple[str, ...],
    out: Path,
    overwrite: bool,
    scheduler: str | None,
    scheduler_file: Path | None,
    workers: int | None,
) -> int:
    """``bench --suite robots``: every cell planned first (bad input writes nothing), then run and summarised."""
    from ..outdir import check_output, start_resumable
    from ..studies.robot_suite import RobotSuite, board_markdown, entry_labels, plan_robot_suite, run_robot_suite

    names = entry_labels(_names(controllers))
    suite = RobotSuite(overrides=overrides)
    plan_robot_suite(suite, names)
    study = f"robots: {', '.join(names)}" + _changed(overrides)
    resume = check_output(out, command="bench", overwrite=overwrite, study=study)
    enable_compilation_cache()
    start = time.perf_counter()
    with dask_client(scheduler, scheduler_file, workers) as client, progress_bar(0, "runs") as advance:
        start_resumable(out, command="bench", study=study, resume=resume)
        summary = run_robot_suite(suite, names, out, client, **study_progress(advance))
    click.echo(board_markdown(summary, suite.conditions), nl=False)
    click.echo(
        f"{summary['runs']} runs ({summary['reused']} reused) in {time.perf_counter() - start:.0f} s, "
        f"{summary['not_ok']} diverged or non-finite, {summary['errors']} errors; "
        f"wrote {out}/leaderboard.md, .csv, .parquet, .json, results.*, robots.png"
    )
    return 1 if summary["errors"] else 0


def _bench_scenarios(
    paths: tuple[Path, ...],
    seeds: int,
    controllers: str | None,
    overrides: tuple[str, ...],
    out: Path,
    overwrite: bool,
    scheduler: str | None,
    scheduler_file: Path | None,
    workers: int | None,
) -> int:
    """``bench --scenario``: every entry read and checked first (bad input writes nothing), then run and ranked."""
    from ..outdir import check_output, start_resumable
    from ..studies.scenario_suite import FIGURE, bench_entries, board_markdown, run_scenario_bench

    entries = bench_entries(paths, _names(controllers) or (), overrides)
    study = f"scenario: {', '.join(e.label for e in entries)}" + _changed(
        overrides
    )  # the same entries resume, whatever the seeds
    resume = check_output(out, command="bench", overwrite=overwrite, study=study)
    enable_compilation_cache()
    start = time.perf_counter()
    with dask_client(scheduler, scheduler_file, workers) as client, progress_bar(0, "runs") as advance:
        start_resumable(out, command="bench", study=study, resume=resume)
        summary = run_scenario_bench(entries, seeds, out, client, **study_progress(advance))
    click.echo(board_markdown(summary["leaderboard"], summary["reference"]), nl=False)
    recorded = f" and {len(summary['recorded'])} recorded" if summary["recorded"] else ""
    click.echo(
        f"{summary['runs']} runs ({summary['reused']} reused){recorded} in {time.perf_counter() - start:.0f} s, "
        f"{summary['not_ok']} diverged or non-finite, {summary['errors']} errors; "
        f"wrote {out}/leaderboard.md, .csv, .parquet, .json, {'results.*, ' if summary['runs'] else ''}{FIGURE}"
    )
    return 1 if summary["errors"] else 0
