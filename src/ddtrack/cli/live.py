"""Live ROS 2 commands over DDS (docs/ros.md): ``robot``, a scenario's plant as a ROS 2 robot."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import click

from ..errors import ConfigError
from . import cli, enable_compilation_cache, folder_name, overwrite_option

Command = TypeVar("Command", bound=Callable[..., Any])


def live_options(out_help: str) -> Callable[[Command], Command]:
    """The options every live command shares (``--set``, ``--domain``, ``--out``, ``--overwrite``), one way."""

    def decorate(command: Command) -> Command:
        for option in reversed(
            [
                click.option(
                    "--set",
                    "overrides",
                    multiple=True,
                    metavar="SECTION.KEY=VALUE",
                    help="Override a scenario value, e.g. --set simulation.duration=20 (repeatable).",
                ),
                click.option(
                    "--domain", type=click.IntRange(0, 232), help="DDS domain [default: ROS_DOMAIN_ID, else 0]."
                ),
                click.option("--out", type=click.Path(path_type=Path), help=out_help),
                overwrite_option,
            ]
        ):
            command = option(command)
        return command

    return decorate


def _start_nanoseconds(text: str | None) -> int | None:
    """``--start`` [s since the epoch] in nanoseconds, read exactly (None: the mode's default)."""
    if text is None:
        return None
    from decimal import Decimal, InvalidOperation

    try:
        seconds = Decimal(text.strip())
    except InvalidOperation:
        seconds = Decimal("NaN")
    if not (seconds.is_finite() and seconds >= 0):
        raise ConfigError("--start", f"{text} is not a time since the epoch", "give seconds since 1970")
    return int(seconds * 1_000_000_000)


def driven_by(mode: str, ended: str, periods: int) -> dict[str, str | int]:
    """``metrics.json``'s ``driven_by`` of a robot run: what drove it and how the run ended (``done``, ``stopped``,
    ``silent``, ``failed``) after how many periods, which ``bench --scenario`` names and checks."""
    return {"command": "ddtrack robot", "mode": mode, "topic": "/cmd_vel", "ended": ended, "periods": periods}


@cli.command(short_help="Run SCENARIO's plant as a ROS 2 robot driven by /cmd_vel, and score it.")
@click.argument("scenario", type=click.Path(path_type=Path))
@click.option(
    "--mode",
    default="realtime",
    show_default=True,
    metavar="MODE",
    help="realtime (one period per wall-clock period), fast (as fast as it can, time on /clock) or lockstep "
    "(each period waits for the /cmd_vel answering its /clock: deterministic).",
)
@click.option(
    "--timeout",
    type=click.FloatRange(min=0.0, min_open=True),
    default=5.0,
    show_default=True,
    metavar="SECONDS",
    help="lockstep: how long to wait for a /cmd_vel before ending the run; with --path-topic, for the path too.",
)
@click.option(
    "--path-topic",
    metavar="TOPIC",
    help="Score against the first nav_msgs/msg/Path on TOPIC (awaited before the first period, re-timed as "
    "`ddtrack import` does) instead of the scenario's reference; the start pose stays the scenario's.",
)
@click.option(
    "--start", metavar="SECONDS", help="Stamp of t = 0 [s since the epoch; default: 0, realtime the wall clock]."
)
@click.option("--twist-stamped", is_flag=True, help="Take /cmd_vel as TwistStamped instead of Twist.")
@click.option("--seed", type=click.IntRange(min=0), help="Replace simulation.seed.")
@live_options("Run folder [default: runs/NAME].")
def robot(
    scenario: Path,
    mode: str,
    timeout: float,
    path_topic: str | None,
    start: str | None,
    twist_stamped: bool,
    domain: int | None,
    overrides: tuple[str, ...],
    seed: int | None,
    out: Path | None,
    overwrite: bool,
) -> int:
    """Run SCENARIO's plant (a velocity-input one: its motors, grip, latency and encoders) as a ROS 2 robot: it
    takes /cmd_vel and publishes /clock, /odom, /tf, /tf_static and /joint_states, until the scenario's duration,
    Ctrl-C or SIGTERM; then it scores the run against the reference (the scenario's, or --path-topic's) into a run
    folder, as `ddtrack run` does. Exit 1: the run failed, or (lockstep) the driver stopped answering."""
    from ..ros.robot import MODES, Options, run_robot

    if mode not in MODES:
        raise ConfigError("--mode", f"'{mode}' is not a mode", f"give one of {', '.join(MODES)}")
    origin = _start_nanoseconds(start)
    from ..scenario import load_scenario

    enable_compilation_cache()
    spec = load_scenario(scenario, overrides=overrides, seed=seed)
    folder = out if out is not None else Path("runs") / folder_name(spec.name)
    from ..outdir import check_output, staged_folder

    check_output(folder, command="run", overwrite=overwrite)  # before the robot goes live
    options = Options(
        mode=mode, timeout=timeout, start=origin, twist_stamped=twist_stamped, domain=domain, path_topic=path_topic
    )
    live = run_robot(spec, options, on_ready=lambda line: click.echo(line, err=True))
    spec = live.scenario or spec  # a path's reference: the run folder describes what was scored
    from ..rundir import write_run

    with staged_folder(folder, command="run") as stage:  # a run folder as `ddtrack run` writes it
        write_run(stage, spec, live.columns, live.metrics | {"driven_by": driven_by(mode, live.ended, live.periods)})
    metrics = live.metrics
    simulated = live.periods * spec.simulation.control_period
    mean, worst = (metrics.get(name) for name in ("e_tr_mean", "e_tr_max"))
    error = "no e_tr (the run ended before the metric window)" if mean is None else f"e_tr mean {mean:.4g} m"
    error += "" if worst is None else f", max {worst:.4g} m"
    click.echo(
        f"{spec.name}: {mode}, {live.periods} periods ({simulated:g} s), {live.ended}; {error}; "
        f"{live.late} periods late -> {folder}"
    )
    if live.ended == "silent":
        click.echo(f"the driver stopped answering: no /cmd_vel within {timeout:g} s; run ended there", err=True)
    if live.ended == "failed":
        click.echo(f"run {metrics['status']}: the robot left the divergence bounds", err=True)
    return 1 if live.ended in ("silent", "failed") else 0
