"""The ``ddtrack`` command (docs/guide.md). Exit codes: 0 success, 1 a run diverged, 2 usage or configuration error.

User mistakes print one or two plain lines on stderr, never a traceback.
"""

from __future__ import annotations

import gc
import os
import re
import sys
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

import click

from .._after_import import after_import
from ..errors import ConfigError, RunError
from ..precision import enable_float64

if TYPE_CHECKING:
    from ..robots import RobotPreset
    from ..scenario import Scenario
    from ..sim import SimResult

LISTS = ("controllers", "plants", "trajectories", "disturbances", "robots")

overwrite_option = click.option(
    "--overwrite",
    is_flag=True,
    help="Replace another ddtrack command's output (or, for sweep and bench, another study) in --out, whole.",
)


@click.group(context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(package_name="ddtrack")
def cli() -> None:
    """Simulate, compare and tune trajectory-tracking controllers for differential-drive robots."""


@cli.command(short_help="Simulate SCENARIO once and write a run folder.")
@click.argument("scenario", type=click.Path(path_type=Path))
@click.option("--controller", "controller", metavar="NAME", help="Replace controller.kind (see `ddtrack list`).")
@click.option(
    "--set",
    "overrides",
    multiple=True,
    metavar="SECTION.KEY=VALUE",
    help="Override a scenario value, e.g. --set robot.mass=12 (repeatable).",
)
@click.option("--seed", type=click.IntRange(min=0), help="Replace simulation.seed.")
@click.option("--out", type=click.Path(path_type=Path), help="Run folder [default: runs/NAME].")
@overwrite_option
def run(
    scenario: Path,
    controller: str | None,
    overrides: tuple[str, ...],
    seed: int | None,
    out: Path | None,
    overwrite: bool,
) -> int:
    """Simulate SCENARIO once and write a run folder."""
    from ..scenario import load_scenario

    enable_compilation_cache()  # loading already compiles: the reference is sampled for the feasibility checks
    spec = load_scenario(scenario, overrides=overrides, seed=seed, controller=controller)
    folder = out if out is not None else Path("runs") / folder_name(spec.name)
    from ..outdir import check_output, staged_folder

    check_output(folder, command="run", overwrite=overwrite)  # before spending time on the simulation
    from ..rundir import write_run
    from ..runner import needs_identification, prepare, run_record, run_setup

    show = terminal_status()
    show("identifying the robot: the NN emulator's pre-training run" if needs_identification(spec) else "preparing")
    setup, draws = prepare(spec)
    show(f"simulating {spec.simulation.duration:g} s")
    result = run_setup(spec, setup, draws)
    columns, metrics = run_record(spec, setup, result)  # with the grip the run needed, and its wheel speeds
    identification = None
    if setup.identification is not None:
        found = setup.identification
        identification = {
            "samples": int(found.samples),
            "epochs": int(found.epoch_loss.shape[0]),
            "epoch_loss": [float(v) for v in found.epoch_loss],
            "nmse": dict(zip(("forward", "lateral", "yaw"), map(float, found.nmse), strict=True)),
        }
    show("")
    summary, notes, code = run_summary(spec, folder, result, columns, metrics)
    click.echo("\n".join(summary))  # before the figures: the numbers are ready now
    show("writing the run folder and its figures")
    with staged_folder(folder, command="run") as stage:  # the folder holds this run and nothing older
        write_run(stage, spec, columns, metrics, identification)
    show("")
    for note in notes:  # what the saved numbers may not mean (a write that failed said only why)
        click.echo(note, err=True)
    return code


def run_summary(
    spec: Scenario, folder: Path, result: SimResult, columns: dict, metrics: dict
) -> tuple[list[str], list[str], int]:
    """A finished run's summary: (lines for stdout: the tracking error, settling, effort; lines for stderr: its
    warnings, and for a failed run its likely cause; the command's exit code, 0 or 1 for a failed run)."""
    sim = spec.simulation
    header = f"{spec.name}: {spec.controller.kind} on {spec.trajectory.kind}, seed {sim.seed}, {sim.duration:g} s"
    header += f" -> {folder}"
    warnings = [f"warning: {w['message']} [{w['code']}]" for w in metrics["warnings"]]
    if result.status_name != "ok":
        from ..sim import remedy

        cause = remedy(result.status_name, columns, metrics["warnings"])
        others = [line for w, line in zip(metrics["warnings"], warnings, strict=True) if w["message"] != cause]
        return [header], [*others, f"run {result.status_name} at t = {result.failure_time:.2f} s: {cause}"], 1
    window = f"[{sim.window[0]:g}, {sim.window[1]:g}] s"
    settle, effort = metrics["settling_time"], metrics["effort"]  # no effort on a velocity-input (kinematic) plant
    from .._format import percent, significant

    errors = (
        f"  e_tr over {window}: mean {significant(metrics['e_tr_mean'])} m, "
        f"rms {significant(metrics['e_tr_rms'])} m, max {significant(metrics['e_tr_max'])} m, "
        f"final {significant(metrics['e_tr_final'])} m"
    )
    effort_line = (
        f"  settling (e_tr < {sim.settling_threshold:g} m): "
        f"{'never' if settle is None else f'{significant(settle)} s'}; "
        f"effort {'none (no torques)' if effort is None else f'{significant(effort)} N^2 m^2 s'}; "
        f"saturated {percent(metrics['saturation_fraction'])} of the time"
    )
    return [header, errors, effort_line], warnings, 0  # the warnings: what the numbers may not mean, on stderr


def terminal_status() -> Callable[[str], None]:
    """A one-line status on stderr, rewritten in place, for the slow phases of a lone run (an NN identification
    takes seconds); silent when stderr is not a terminal, so pipes, logs and tests see the plain output."""
    if not sys.stderr.isatty():
        return lambda text: None

    def show(text: str) -> None:
        click.echo(f"\r\033[K{text + ' ...' if text else ''}", err=True, nl=False)

    return show


def folder_name(name: str) -> str:
    """``name`` as one safe folder name for the default ``runs/NAME``: every character other than a letter, a digit,
    ``.``, ``_`` or ``-`` becomes ``_`` and leading dots go, so a scenario named ``../../etc`` or ``a/b`` cannot
    make ``ddtrack run`` write outside ``runs/``."""
    safe = re.sub(r"[^A-Za-z0-9._-]", "_", name).lstrip(".")
    return safe or "run"


@cli.command(short_help="Check SCENARIO without running it.")
@click.argument("scenario", type=click.Path(path_type=Path))
@click.option("--set", "overrides", multiple=True, metavar="SECTION.KEY=VALUE", help="Override a value first.")
def validate(scenario: Path, overrides: tuple[str, ...]) -> int:
    """Check SCENARIO without running it."""
    from ..feasibility import check
    from ..scenario import load_scenario

    spec = load_scenario(scenario, overrides=overrides)
    click.echo(
        f"ok: {spec.name} ({spec.trajectory.kind}, {spec.controller.kind}, {spec.simulation.n_steps} control periods)"
    )
    for warning in check(spec):
        click.echo(f"warning: {warning['message']} [{warning['code']}]", err=True)
    return 0


@cli.command(name="list", short_help="List the controllers, plants, trajectories, disturbances and robot presets.")
@click.argument("what", required=False, type=click.Choice(LISTS))
def list_(what: str | None) -> int:
    """List the controllers, plants, trajectories, disturbances and robot presets (robot.preset) a scenario can
    name."""
    from ..robots import PRESETS
    from ..scenario import CONTROLLERS, DISTURBANCES, PLANTS, TRAJECTORIES, summary

    lines = {
        "controllers": {kind: summary(model) for kind, model in CONTROLLERS.items()},
        "plants": dict(PLANTS),
        "trajectories": {kind: summary(model) for kind, model in TRAJECTORIES.items()},
        "disturbances": {kind: summary(model) for kind, model in DISTURBANCES.items()},
        "robots": {name: robot_line(robot) for name, robot in PRESETS.items()},
    }
    width = max(len(kind) for registry in lines.values() for kind in registry)
    for name in [what] if what else LISTS:
        click.echo(f"{name}:")
        for kind, line in lines[name].items():
            click.echo(f"  {kind:<{width}}  {line}")
    return 0


def robot_line(robot: RobotPreset) -> str:
    """A preset's line in ``ddtrack list robots``: its description and, where published, its top speeds."""
    if robot.max_speed is None or robot.max_yaw_rate is None:
        return f"{robot.description}; no top speed"
    return f"{robot.description}; top speed {robot.max_speed:.3g} m/s, {robot.max_yaw_rate:.3g} rad/s"


@cli.command(short_help="Animate a run folder: the robot following its reference.")
@click.argument("folder", metavar="DIR", type=click.Path(path_type=Path))
@click.option(
    "--out",
    type=click.Path(path_type=Path),
    metavar="FILE",
    help="FILE.gif (Pillow) or FILE.mp4 (needs ffmpeg on PATH) [default: DIR/animation.gif].",
)
@click.option(
    "--fps", type=click.IntRange(min=1, max=50), default=20, show_default=True, help="Frames per second of playback."
)
@click.option(
    "--speed",
    type=click.FloatRange(min=0.01, max=1000.0),
    default=2.0,
    show_default=True,
    help="Simulated seconds per second of playback (1 = real time).",
)
def animate(folder: Path, out: Path | None, fps: int, speed: float) -> int:
    """Animate the run folder DIR (from `ddtrack run`): the robot's footprint following the reference with its
    trail, and the adapted gains beside it when they moved. At most 600 frames: a longer run plays faster."""
    from ..animation import animate as write_animation
    from ..animation import read_run
    from ..outdir import check_writable

    columns, spec = read_run(folder)
    out = out if out is not None else folder / "animation.gif"
    check_writable(out.parent)
    plant = spec.plant_params()  # the true robot's geometry
    info = write_animation(
        columns,
        out,
        half_axle=plant.half_axle,
        wheel_radius=plant.wheel_radius,
        fps=fps,
        speed=speed,
        title=f"{spec.name}: {spec.controller.kind} on {spec.trajectory.kind}",
    )
    click.echo(f"wrote {out}: {info.frames} frames at {fps} fps, {info.speed:.3g} x real time")
    return 0


@cli.command(short_help="Print the JSON Schema (or Markdown reference) of scenario files.")
@click.option("--markdown", is_flag=True, help="Print the Markdown reference (docs/reference.md) instead.")
def schema(markdown: bool) -> int:
    """Print the JSON Schema of scenario files (every key, its type, default, bounds and unit)."""
    import json

    from ..schema import scenario_schema, schema_markdown

    click.echo(schema_markdown() if markdown else json.dumps(scenario_schema(), indent=2), nl=not markdown)
    return 0


@cli.command(short_help="Write a self-contained HTML report of a result folder.")
@click.argument("folder", metavar="DIR", type=click.Path(path_type=Path))
@click.option(
    "--out", type=click.Path(path_type=Path), metavar="FILE", help="The HTML file [default: DIR/report.html]."
)
def report(folder: Path, out: Path | None) -> int:
    """Write one self-contained HTML page (inline CSS and SVG; no script, no external resource: it opens
    offline) for a run, reproduce, mc or bench folder DIR: the scenario, the metrics, the figures, the gains, and
    for mc and bench the distributions."""
    from ..report import write_report

    click.echo(f"wrote {write_report(folder, out=out)}")
    return 0


@contextmanager
def progress_bar(total: int, label: str) -> Iterator[Callable[..., None]]:
    """A rich progress bar on stderr, yielding ``advance(completed, label=None)``; silent when stderr is not a
    terminal, so logs, pipes and CI stay clean."""
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    console = Console(stderr=True)
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TextColumn("eta"),
        TimeRemainingColumn(),
        console=console,
        disable=not console.is_terminal,
    ) as bar:
        task = bar.add_task(label, total=total)

        def advance(completed: int, description: str | None = None, total: int | None = None) -> None:
            if total is not None:
                bar.update(task, total=total)
            bar.update(task, completed=completed, description=description or label)

        yield advance


def say_programs(needed: int, held: int) -> None:
    """A study's first line, on stderr: the simulation programs its runs need and how many the cache holds."""
    plural = "program" if needed == 1 else "programs"
    click.echo(
        f"{needed} simulation {plural} to run (one per structure); {held} already compiled in the cache", err=True
    )


def study_progress(advance: Callable[..., None]) -> dict[str, Callable[[int, int], None]]:
    """What a study (``run_sweep``, the bench suites) reports as it goes: first :func:`say_programs`; then the runs
    done, on ``advance``'s progress bar."""
    return {"on_record": lambda done, total: advance(done, total=total), "on_programs": say_programs}


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line with ``argv`` (default ``sys.argv[1:]``) and return the exit code."""
    os.environ.setdefault("MPLBACKEND", "Agg")  # commands write figures to files and never show them
    after_import("jax", lambda jax: enable_float64())  # the commands compute in float64, once JAX is loaded
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


def enable_compilation_cache() -> None:
    """JAX's persistent compilation cache, imported only by the commands that simulate."""
    from ..compilations import enable_compilation_cache as enable

    enable()


def one_device_per_core(jax: ModuleType) -> None:
    """One JAX CPU device per usable core (called once JAX is imported)."""
    jax.config.update(
        "jax_num_cpu_devices", len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    )


#: Python's cyclic garbage collector runs once GC_THRESHOLDS[0] more objects were allocated than freed (Python's
#: default: 700), and looks at the older generations after every 10 such runs. A ``ddtrack run`` allocates millions of
#: short-lived, mostly acyclic objects (imports, tracing, figures): at the default, some 630 collections took 0.3 s
#: of a 2 s warm run, and 5 of 112 s in a pytest worker (measured, docs/benchmarks.md). Cycles are still collected,
#: only in larger rounds.
GC_THRESHOLDS = (100_000, 10, 10)


def collect_garbage_rarely() -> None:
    """Set the process's garbage-collection thresholds to GC_THRESHOLDS. The ``ddtrack`` process does it at
    start (:func:`entry_point`), and the test session as well; a script calling :func:`main` keeps its own."""
    gc.set_threshold(*GC_THRESHOLDS)


def entry_point() -> None:
    """Console-script entry point. The ``ddtrack`` process gives JAX one CPU device per core, so that ``mc``
    batches split over the cores (``sim.batch.in_shares``), and collects garbage in large rounds
    (:func:`collect_garbage_rarely`); in-process callers of :func:`main` keep their own settings. JAX is imported
    only when a command needs it, so ``--help`` starts fast."""
    collect_garbage_rarely()
    after_import("jax", one_device_per_core)
    code = main()
    if "distributed" not in sys.modules:  # Dask's exit hooks stop worker processes: let those run
        exit_now(code)
    sys.exit(code)


def exit_now(code: int) -> None:
    """Exit without the interpreter's teardown (0.3 s of JAX and Matplotlib clean-up that keeps nothing): every
    file is written, fsynced and closed by then; the standard streams and the log are flushed here."""
    import logging

    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe: nothing more can reach it
            pass
    os._exit(code)


from . import bench as _bench  # noqa: E402, F401  (registers bench)
from . import drive as _drive  # noqa: E402, F401  (registers drive)
from . import identify as _identify  # noqa: E402, F401  (registers excite and identify)
from . import live as _live  # noqa: E402, F401  (registers robot)
from . import ros as _ros  # noqa: E402, F401  (registers export and import)
from . import studies as _studies  # noqa: E402, F401  (registers reproduce, mc, tune and sweep)
