"""The ``ddtrack`` command (DESIGN 4). Exit codes: 0 success, 1 a run diverged, 2 usage or configuration error.

User mistakes print one or two plain lines on stderr, never a traceback.
"""
from __future__ import annotations

import os
import sys
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

import click
import jax

from .errors import ConfigError, RunError
from .runner import enable_compilation_cache

LISTS = ("controllers", "trajectories", "disturbances")


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="ddtrack")
def cli() -> None:
    """Simulate, compare and tune trajectory-tracking controllers for differential-drive robots."""


@cli.command()
@click.argument("scenario", type=click.Path(path_type=Path))
@click.option("--controller", "controller", metavar="NAME", help="Replace controller.kind (see `ddtrack list`).")
@click.option("--set", "overrides", multiple=True, metavar="SECTION.KEY=VALUE",
              help="Override a scenario value, e.g. --set robot.mass=12 (repeatable).")
@click.option("--seed", type=click.IntRange(min=0), help="Replace simulation.seed.")
@click.option("--out", type=click.Path(path_type=Path), help="Run folder [default: runs/NAME].")
def run(scenario: Path, controller: str | None, overrides: tuple[str, ...], seed: int | None, out: Path | None) -> int:
    """Simulate SCENARIO once and write a run folder."""
    from .scenario import load_scenario

    spec = load_scenario(scenario, overrides=overrides, seed=seed, controller=controller)
    folder = out if out is not None else Path("runs") / spec.name
    from .rundir import check_writable

    check_writable(folder)  # before spending time on the simulation
    enable_compilation_cache()
    from .metrics import summarize
    from .rundir import write_run
    from .runner import prepare, run_setup
    from .sim import REMEDIES, timeseries

    setup, draws = prepare(spec)
    result = run_setup(spec, setup, draws)
    columns = timeseries(result)
    sim = spec.simulation
    metrics = summarize(columns, status=result.status_name, window=sim.window, control_period=sim.control_period,
                        settling_threshold=sim.settling_threshold, failure_time=result.failure_time)
    identification = None
    if setup.identification is not None:
        found = setup.identification
        identification = {"samples": found.samples, "epochs": int(found.epoch_loss.shape[0]),
                          "epoch_loss": [float(v) for v in found.epoch_loss],
                          "nmse": dict(zip(("forward", "lateral", "yaw"), map(float, found.nmse), strict=True))}
    write_run(folder, spec, columns, metrics, identification)
    click.echo(f"{spec.name}: {spec.controller.kind} on {spec.trajectory.kind}, seed {sim.seed}, "
               f"{sim.duration:g} s -> {folder}")
    if result.status_name != "ok":
        click.echo(f"run {result.status_name} at t = {result.failure_time:.2f} s: {REMEDIES[result.status_name]}",
                   err=True)
        return 1
    window = f"[{sim.window[0]:g}, {sim.window[1]:g}] s"
    settle = metrics["settling_time"]
    click.echo(f"  e_tr over {window}: mean {metrics['e_tr_mean']:.4f} m, rms {metrics['e_tr_rms']:.4f} m, "
               f"max {metrics['e_tr_max']:.4f} m, final {metrics['e_tr_final']:.4f} m")
    click.echo(f"  settling (e_tr < {sim.settling_threshold:g} m): "
               f"{'never' if settle is None else f'{settle:.2f} s'}; effort {metrics['effort']:.1f} N^2 m^2 s; "
               f"saturated {100 * metrics['saturation_fraction']:.1f} % of the time")
    return 0


@cli.command()
@click.argument("scenario", type=click.Path(path_type=Path))
@click.option("--set", "overrides", multiple=True, metavar="SECTION.KEY=VALUE", help="Override a value first.")
def validate(scenario: Path, overrides: tuple[str, ...]) -> int:
    """Check SCENARIO without running it."""
    from .scenario import load_scenario

    spec = load_scenario(scenario, overrides=overrides)
    click.echo(f"ok: {spec.name} ({spec.trajectory.kind}, {spec.controller.kind}, "
               f"{spec.simulation.n_steps} control periods)")
    return 0


@cli.command(name="list")
@click.argument("what", required=False, type=click.Choice(LISTS))
def list_(what: str | None) -> int:
    """List the controllers, trajectories and disturbances a scenario can name."""
    from .scenario import CONTROLLERS, DISTURBANCES, TRAJECTORIES, summary

    registries = {"controllers": CONTROLLERS, "trajectories": TRAJECTORIES, "disturbances": DISTURBANCES}
    width = max(len(kind) for registry in registries.values() for kind in registry)
    for name in [what] if what else LISTS:
        click.echo(f"{name}:")
        for kind, model in registries[name].items():
            click.echo(f"  {kind:<{width}}  {summary(model)}")
    return 0


@cli.command()
@click.option("--out", type=click.Path(path_type=Path), default=Path("runs/reproduce"), show_default=True,
              help="Folder for table1.{md,csv,json} and figures/.")
@click.option("--seeds", type=click.IntRange(min=1, max=1000), default=5, show_default=True,
              help="Seeds per case (common random numbers across controllers).")
@click.option("--ablations", is_flag=True, help="Add the NN variants: Jacobian source, error Jacobian, "
              "no identification, no online learning.")
def reproduce(out: Path, seeds: int, ablations: bool) -> int:
    """The paper's Table 1 and Figs. 10-17: backstepping vs NN-adaptive backstepping, both cases.

    Exit code 1 if NN-adaptive backstepping does not beat backstepping in a case.
    """
    from .rundir import check_writable

    check_writable(out)
    enable_compilation_cache()
    from .reproduce import nn_beats_backstepping
    from .reproduce import reproduce as run_reproduce
    from .reproduce import table_markdown

    table = run_reproduce(out, seeds=seeds, ablations=ablations)
    click.echo(table_markdown(table))
    click.echo(f"wrote {out}/table1.md, table1.csv, table1.json and figures/ in {table['elapsed_s']:.0f} s")
    losing = [name for name, wins in nn_beats_backstepping(table).items() if not wins]
    if losing:
        click.echo(f"NN-adaptive backstepping does not beat backstepping on: {', '.join(losing)}", err=True)
        return 1
    return 0


@cli.command()
@click.argument("scenario", type=click.Path(path_type=Path))
@click.option("-n", "n", type=click.IntRange(min=1, max=1_000_000), required=True, help="Runs per controller.")
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True, help="First seed.")
@click.option("--controllers", default="backstepping", show_default=True, metavar="A,B,...",
              help="Controllers to compare on common random numbers; the first is the baseline.")
@click.option("--vary", multiple=True, metavar="FIELD=DIST:SPREAD", help="Draw a plant parameter per run, "
              "e.g. --vary mass=uniform:0.2 (repeatable).")
@click.option("--set", "overrides", multiple=True, metavar="SECTION.KEY=VALUE", help="Override a scenario value.")
@click.option("--chunk", type=click.IntRange(min=1, max=100_000), default=64, show_default=True,
              help="Runs per vmapped batch (bounds memory).")
@click.option("--out", type=click.Path(path_type=Path), default=Path("runs/mc"), show_default=True)
def mc(scenario: Path, n: int, seed: int, controllers: str, vary: tuple[str, ...], overrides: tuple[str, ...],
       chunk: int, out: Path) -> int:
    """Monte Carlo: N seeds of SCENARIO for each controller, on common random numbers."""
    from .rundir import check_writable

    names = [c.strip() for c in controllers.split(",") if c.strip()]
    if not names or len(set(names)) != len(names):
        raise ConfigError("--controllers", f"'{controllers}' must name distinct controllers, comma-separated",
                          "e.g. --controllers backstepping,nn_adaptive_backstepping")
    from .mc import format_summary, load_specs, run_specs, summarise, write

    specs = load_specs(scenario, controllers=names, vary=vary, overrides=overrides)  # bad input: nothing written
    check_writable(out)
    enable_compilation_cache()
    with progress_bar(n * len(names), "runs") as advance:
        rows = run_specs(specs, n=n, seed=seed, chunk_size=chunk,
                         on_chunk=lambda name, done: advance(names.index(name) * n + done, name))
    summary = summarise(rows)
    write(out, rows, summary)
    click.echo(format_summary(summary, n))
    click.echo(f"wrote {out}/runs.parquet, runs.csv, summary.json")
    return 0


@cli.command()
@click.argument("sweep_file", metavar="SWEEP.toml", type=click.Path(path_type=Path))
@click.option("--out", type=click.Path(path_type=Path), required=True,
              help="Result folder: records/<key>.json, results.parquet, results.csv. Rerun to resume.")
@click.option("--scheduler", metavar="ADDRESS", help="Use a running Dask scheduler, e.g. tls://10.0.0.5:8786.")
@click.option("--scheduler-file", type=click.Path(path_type=Path), metavar="FILE",
              help="Use the running Dask scheduler described by FILE (dask scheduler --scheduler-file).")
@click.option("--workers", type=click.IntRange(min=1, max=1024), metavar="N",
              help="Worker processes of the embedded local cluster [default: CPU count].")
def sweep(sweep_file: Path, out: Path, scheduler: str | None, scheduler_file: Path | None, workers: int | None) -> int:
    """Run a parameter sweep (SWEEP.toml, see docs/sweeps.md) on Dask, resumably.

    Without --scheduler or --scheduler-file, an embedded cluster on 127.0.0.1 runs it.
    """
    if scheduler is not None and scheduler_file is not None:
        raise ConfigError("--scheduler", "give --scheduler or --scheduler-file, not both")
    if workers is not None and (scheduler is not None or scheduler_file is not None):
        raise ConfigError("--workers", "only applies to the embedded cluster",
                          "start workers on the cluster with `dask worker` instead")
    if scheduler_file is not None and not scheduler_file.is_file():
        raise ConfigError("--scheduler-file", f"'{scheduler_file}' does not exist",
                          "start the scheduler with `dask scheduler --scheduler-file FILE` first")
    from .sweep import local_cluster, plan_sweep, read_sweep, run_sweep

    spec = read_sweep(sweep_file)
    plan = plan_sweep(spec, sweep_file.parent)  # every configuration resolved: bad input writes nothing
    from .rundir import check_writable

    check_writable(out)
    from distributed import Client

    cluster = None
    try:
        if scheduler is not None or scheduler_file is not None:
            try:
                client = Client(scheduler, scheduler_file=None if scheduler_file is None else str(scheduler_file),
                                timeout="20s")
            except (OSError, TimeoutError) as exc:
                raise RunError(f"cannot reach the Dask scheduler ({exc})") from None
        else:
            cluster = local_cluster(workers or os.cpu_count() or 1)
            client = Client(cluster)
        with client, progress_bar(len(plan.runs), "runs") as advance:
            outcome = run_sweep(plan, out, client, on_record=lambda done, total: advance(done))
    finally:
        if cluster is not None:
            cluster.close()
    click.echo(f"{outcome.total} runs ({len(plan.configurations)} configurations x {len(spec.seed_list)} seeds): "
               f"{outcome.reused} found in {out}/records, {outcome.ran} run; "
               f"{outcome.not_ok} diverged or non-finite, {outcome.errors} errors")
    click.echo(f"wrote {out}/results.parquet, results.csv")
    return 1 if outcome.errors or outcome.not_ok else 0


@contextmanager
def progress_bar(total: int, label: str) -> Iterator[Callable[..., None]]:
    """A rich progress bar on stderr, yielding ``advance(completed, label=None)``; silent when stderr is not a
    terminal, so logs, pipes and CI stay clean."""
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    console = Console(stderr=True)
    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  TextColumn("eta"), TimeRemainingColumn(), console=console, disable=not console.is_terminal) as bar:
        task = bar.add_task(label, total=total)

        def advance(completed: int, description: str | None = None) -> None:
            bar.update(task, completed=completed, description=description or label)

        yield advance


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line with ``argv`` (default ``sys.argv[1:]``) and return the exit code."""
    try:
        code = cli.main(args=list(argv) if argv is not None else None, prog_name="ddtrack", standalone_mode=False)
    except click.exceptions.Exit as exc:
        return exc.exit_code
    except click.ClickException as exc:
        exc.show()
        return exc.exit_code
    except click.exceptions.Abort:
        click.echo("aborted", err=True)
        return 130
    except ConfigError as exc:
        click.echo(f"error: {exc}", err=True)
        return 2
    except RunError as exc:
        click.echo(f"error: {exc}", err=True)
        return 2
    return code if isinstance(code, int) else 0


def entry_point() -> None:
    """Console-script entry point. The ``ddtrack`` process gives JAX one CPU device per core, so that ``mc``
    batches split over the cores (``runner.shard_runs``); in-process callers of :func:`main` keep their own."""
    jax.config.update("jax_num_cpu_devices", len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
                      else os.cpu_count() or 1)
    sys.exit(main())
