"""The study commands: ``reproduce``, ``mc``, ``tune`` and ``sweep``, registered on the ``ddtrack`` group
(``bench`` is :mod:`.bench`'s)."""

from __future__ import annotations

from pathlib import Path

import click

from ..cluster import check_cluster_options, cluster_options, dask_client
from ..errors import ConfigError
from . import cli, enable_compilation_cache, overwrite_option, progress_bar, say_programs, study_progress


@cli.command(short_help="The paper's Table 1 and Figs. 10-17, over seeds, with intervals.")
@click.option(
    "--out",
    type=click.Path(path_type=Path),
    default=Path("runs/reproduce"),
    show_default=True,
    help="Folder for table1.{md,csv,json} and figures/.",
)
@click.option(
    "--seeds",
    type=click.IntRange(min=1, max=1000),
    default=5,
    show_default=True,
    help="Seeds per case (common random numbers across controllers).",
)
@click.option(
    "--ablations",
    is_flag=True,
    help="Add the NN variants: Jacobian source, error Jacobian, no identification, no online learning.",
)
@overwrite_option
def reproduce(out: Path, seeds: int, ablations: bool, overwrite: bool) -> int:
    """The paper's Table 1 and Figs. 10-17: backstepping vs NN-adaptive backstepping, both cases.

    Exit code 1 if NN-adaptive backstepping does not beat backstepping in a case.
    """
    from ..outdir import check_output, staged_folder

    check_output(out, command="reproduce", overwrite=overwrite)
    enable_compilation_cache()
    from ..studies.reproduce import nn_beats_backstepping, table_markdown
    from ..studies.reproduce import reproduce as run_reproduce

    with staged_folder(out, command="reproduce") as stage:
        table = run_reproduce(stage, seeds=seeds, ablations=ablations, on_programs=say_programs)
    click.echo(table_markdown(table))
    click.echo(f"wrote {out}/table1.md, table1.csv, table1.json and figures/ in {table['elapsed_s']:.0f} s")
    losing = [name for name, wins in nn_beats_backstepping(table).items() if not wins]
    if losing:
        click.echo(f"NN-adaptive backstepping does not beat backstepping on: {', '.join(losing)}", err=True)
        return 1
    return 0


@cli.command(short_help="Monte Carlo: N seeds per controller, on common random numbers.")
@click.argument("scenario", type=click.Path(path_type=Path))
@click.option("-n", "n", type=click.IntRange(min=1, max=1_000_000), required=True, help="Runs per controller.")
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True, help="First seed.")
@click.option(
    "--controllers",
    default="backstepping",
    show_default=True,
    metavar="A,B,...",
    help="Controllers to compare on common random numbers; the first is the baseline.",
)
@click.option(
    "--vary",
    multiple=True,
    metavar="FIELD=DIST:SPREAD",
    help="Draw a plant parameter per run, e.g. --vary mass=uniform:0.2 (repeatable).",
)
@click.option("--set", "overrides", multiple=True, metavar="SECTION.KEY=VALUE", help="Override a scenario value.")
@click.option(
    "--chunk",
    type=click.IntRange(min=1, max=100_000),
    default=64,
    show_default=True,
    help="Runs per vmapped batch (bounds memory).",
)
@click.option("--out", type=click.Path(path_type=Path), default=Path("runs/mc"), show_default=True)
@overwrite_option
def mc(
    scenario: Path,
    n: int,
    seed: int,
    controllers: str,
    vary: tuple[str, ...],
    overrides: tuple[str, ...],
    chunk: int,
    out: Path,
    overwrite: bool,
) -> int:
    """Monte Carlo: N seeds of SCENARIO for each controller, on common random numbers."""
    from ..outdir import check_output, staged_folder

    names = [c.strip() for c in controllers.split(",") if c.strip()]
    if not names or len(set(names)) != len(names):
        raise ConfigError(
            "--controllers",
            f"'{controllers}' must name distinct controllers, comma-separated",
            "e.g. --controllers backstepping,nn_adaptive_backstepping",
        )
    from ..scenario import MAX_SEED
    from ..studies.mc import format_summary, load_specs, run_specs, summarise, write

    if seed + n - 1 > MAX_SEED:
        raise ConfigError(
            "--seed", f"seeds {seed} .. {seed + n - 1} pass the largest seed, {MAX_SEED}", "choose a smaller --seed"
        )

    specs = load_specs(scenario, controllers=names, vary=vary, overrides=overrides)  # bad input: nothing written
    check_output(out, command="mc", overwrite=overwrite)
    enable_compilation_cache()
    with progress_bar(n * len(names), "runs") as advance:
        rows = run_specs(
            specs,
            n=n,
            seed=seed,
            chunk_size=chunk,
            on_chunk=lambda name, done: advance(names.index(name) * n + done, name),
            on_programs=say_programs,
        )
    summary = summarise(rows)
    with staged_folder(out, command="mc") as stage:
        write(stage, rows, summary)
    click.echo(format_summary(summary, n))
    click.echo(f"wrote {out}/runs.parquet, runs.csv, summary.json")
    failed = sum(row["status"] != "ok" for runs in rows.values() for row in runs)
    if failed:  # exit 1, as for `run` and `sweep`: the results are written, with the failures among them
        click.echo(
            f"{failed} of {n * len(names)} runs diverged or went non-finite (status column of runs.csv)", err=True
        )
        return 1
    return 0


@cli.command(short_help="Tune a controller's gains by gradient descent through rollouts.")
@click.argument("scenarios", nargs=-1, required=True, metavar="SCENARIO...", type=click.Path(path_type=Path))
@click.option(
    "--controller",
    default="backstepping",
    show_default=True,
    metavar="NAME",
    help="The controller whose constant gains are tuned.",
)
@click.option(
    "--seeds",
    type=click.IntRange(min=1, max=1000),
    default=4,
    show_default=True,
    help="Training seeds per scenario (0 .. N-1), on common random numbers.",
)
@click.option(
    "--steps",
    type=click.IntRange(min=1, max=10_000),
    default=40,
    show_default=True,
    help="Gradient iterations (Adam on log-gains).",
)
@click.option(
    "--learning-rate",
    type=click.FloatRange(min=0.0, min_open=True, max=10.0),
    default=0.1,
    show_default=True,
    help="Adam step size in log-gain units.",
)
@click.option(
    "--effort-weight",
    type=click.FloatRange(min=0.0),
    default=0.0,
    show_default=True,
    help="Weight of the effort term: loss += W * integral of tau_R^2 + tau_L^2 [m^2 / (N^2 m^2)].",
)
@click.option(
    "--gamma",
    type=(float, float, float),
    default=(1.0, 1.0, 0.0),
    show_default=True,
    metavar="GX GY GTHETA",
    help="Weights of (e_x, e_y, e_theta) in the cost eq. 22; the default is e_tr^2.",
)
@click.option("--whole-run", is_flag=True, help="Sum the cost over the whole run, not the scenario's metric window.")
@click.option("--set", "overrides", multiple=True, metavar="SECTION.KEY=VALUE", help="Override every scenario.")
@click.option(
    "--out",
    type=click.Path(path_type=Path),
    default=Path("runs/tune"),
    show_default=True,
    help="Folder for tuned.toml, loss.csv, loss.png, tune.json.",
)
@overwrite_option
def tune(
    scenarios: tuple[Path, ...],
    controller: str,
    seeds: int,
    steps: int,
    learning_rate: float,
    effort_weight: float,
    gamma: tuple[float, float, float],
    whole_run: bool,
    overrides: tuple[str, ...],
    out: Path,
    overwrite: bool,
) -> int:
    """Tune a controller's constant gains by gradient descent through whole simulated rollouts of SCENARIO...
    (the paper's cost, eq. 22, summed over each run's metric window, averaged over scenarios and seeds)."""
    from ..outdir import check_output, staged_folder
    from ..scenario import kanayama_gains, load_scenario, tunable_kinds
    from ..studies.tune import problems, write
    from ..studies.tune import tune as run_tuning

    if controller not in tunable_kinds():
        raise ConfigError(
            "--controller", f"'{controller}' has no tunable gains", f"choose one of: {', '.join(tunable_kinds())}"
        )
    if min(gamma) < 0 or max(gamma) == 0:
        raise ConfigError("--gamma", f"{gamma} must be >= 0 and not all 0", "e.g. --gamma 1 1 0 (the squared e_tr)")
    specs = [load_scenario(path, overrides=overrides, controller=controller) for path in scenarios]
    check_output(out, command="tune", overwrite=overwrite)
    enable_compilation_cache()
    initial = kanayama_gains(specs[0].controller)
    with progress_bar(steps + 1, "tuning") as advance:
        training = problems(specs, range(seeds))
        result = run_tuning(
            training,
            initial,
            steps=steps,
            learning_rate=learning_rate,
            effort_weight=effort_weight,
            gamma=gamma,
            whole_run=whole_run,
            on_step=lambda record: advance(record["step"] + 1),
        )
    settings = {
        "scenarios": [str(p) for p in scenarios],
        "controller": controller,
        "seeds": seeds,
        "steps": steps,
        "learning_rate": learning_rate,
        "effort_weight": effort_weight,
        "whole_run": whole_run,
        "gamma": list(gamma),
        "overrides": list(overrides),
        "initial_gains": list(initial),
    }
    with staged_folder(out, command="tune") as stage:
        write(stage, result, controller, settings)
    click.echo(
        f"gains {', '.join(f'{g:.4g}' for g in initial)} -> {', '.join(f'{g:.4g}' for g in result.gains)}; "
        f"loss {result.initial_loss:.4g} -> {result.final_loss:.4g} "
        f"({100 * (1 - result.final_loss / result.initial_loss):.1f} % lower)"
    )
    click.echo(f"wrote {out}/tuned.toml, loss.csv, loss.png, tune.json")
    return 0


@cli.command(short_help="Run a parameter sweep (SWEEP.toml) on Dask, resumably.")
@click.argument("sweep_file", metavar="SWEEP.toml", type=click.Path(path_type=Path))
@click.option(
    "--out",
    type=click.Path(path_type=Path),
    required=True,
    help="Result folder: records/<key>.json, results.parquet, results.csv. Rerun to resume.",
)
@overwrite_option
@cluster_options
def sweep(
    sweep_file: Path,
    out: Path,
    overwrite: bool,
    scheduler: str | None,
    scheduler_file: Path | None,
    workers: int | None,
) -> int:
    """Run a parameter sweep (SWEEP.toml, see docs/sweeps.md) on Dask, resumably.

    Without --scheduler or --scheduler-file, an embedded cluster on 127.0.0.1 runs it.
    """
    check_cluster_options(scheduler, scheduler_file, workers)
    from ..studies.sweep import plan_sweep, read_sweep, run_sweep

    spec = read_sweep(sweep_file)
    plan = plan_sweep(spec, sweep_file.parent)  # every configuration resolved: bad input writes nothing
    from ..outdir import check_output, start_resumable

    study = plan.identity()
    resume = check_output(out, command="sweep", overwrite=overwrite, study=study)  # the same sweep resumes
    with dask_client(scheduler, scheduler_file, workers) as client, progress_bar(len(plan.runs), "runs") as advance:
        start_resumable(out, command="sweep", study=study, resume=resume)
        outcome = run_sweep(plan, out, client, **study_progress(advance))
    click.echo(
        f"{outcome.total} runs ({len(plan.configurations)} configurations x {len(spec.seed_list)} seeds): "
        f"{outcome.reused} found in {out}/records, {outcome.ran} run; "
        f"{outcome.not_ok} diverged or non-finite, {outcome.errors} errors"
    )
    if outcome.warnings:
        click.echo("warnings: " + ", ".join(f"{code} x {count}" for code, count in outcome.warnings.items()))
    click.echo(f"wrote {out}/results.parquet, results.csv")
    return 1 if outcome.errors or outcome.not_ok else 0
