"""The ROS 2 commands: ``export`` (a run as a bag or CSV) and ``import`` (a reference from a bag), docs/ros.md."""

from __future__ import annotations

from decimal import Decimal, InvalidOperation
from pathlib import Path

import click

from ..errors import ConfigError
from . import cli, overwrite_option


def _seconds(text: str) -> Decimal:
    """``--start`` as an exact decimal number of seconds after the epoch (a float would round the nanoseconds)."""
    try:
        seconds = Decimal(text.strip())
    except InvalidOperation:
        seconds = Decimal("NaN")
    if not (seconds.is_finite() and seconds > 0):
        raise ConfigError("--start", f"{text} is not a time after the epoch", "give seconds since 1970, e.g. 1.7e9")
    return seconds


@cli.command(short_help="Write a run folder as a ROS 2 bag (.mcap) or as CSV.")
@click.argument("folder", metavar="RUN_DIR", type=click.Path(path_type=Path))
@click.option(
    "--to",
    "to",
    type=click.Path(path_type=Path),
    required=True,
    metavar="FILE",
    help="FILE.mcap (one MCAP file: Foxglove, ros2 bag), FILE.csv (units in the header), or a name without "
    "suffix (a rosbag2 folder with metadata.yaml).",
)
@click.option(
    "--start",
    metavar="SECONDS",
    help="Stamp of t = 0, in seconds since the epoch, read to the nanosecond (e.g. 1700000000.123456789) "
    "[default: when the run folder was written].",
)
@click.option("--twist-stamped", is_flag=True, help="Publish /cmd_vel as TwistStamped instead of Twist.")
@click.option("--odom-frame", default="odom", show_default=True, metavar="NAME", help="The world frame.")
@click.option(
    "--base-frame",
    default="base_link",
    show_default=True,
    metavar="NAME",
    help="The robot's body frame (a TurtleBot3's is base_footprint); the estimate's is NAME_estimate.",
)
@overwrite_option
def export(
    folder: Path, to: Path, start: str | None, twist_stamped: bool, odom_frame: str, base_frame: str, overwrite: bool
) -> int:
    """Write the run folder RUN_DIR (from `ddtrack run`) as a ROS 2 bag, with /clock, /tf, /tf_static,
    /robot_description, /odom, /reference, /cmd_vel, /joint_states, /reference_path and /path, or as a CSV of its
    time series."""
    from ..ros import export_run

    origin = None if start is None else _seconds(start)
    done = export_run(
        folder,
        to,
        start=origin,
        twist_stamped=twist_stamped,
        odom_frame=odom_frame,
        base_frame=base_frame,
        overwrite=overwrite,
    )
    if done.counts:
        topics = ", ".join(f"{topic} {count}" for topic, count in done.counts.items())
        click.echo(f"wrote {to}: {done.rows} control periods; messages: {topics}")
    else:
        click.echo(f"wrote {to}: {done.rows} rows")
    return 0


@cli.command(name="import", short_help="Read a reference for a scenario from a ROS 2 bag.")
@click.argument("bag", metavar="BAG", type=click.Path(path_type=Path))
@click.option("--path-topic", metavar="TOPIC", help="A nav_msgs/Path topic (its last message: the latest plan).")
@click.option("--odom-topic", metavar="TOPIC", help="A nav_msgs/Odometry topic: the trajectory a robot drove.")
@click.option(
    "--speed",
    type=click.FloatRange(min=0.0, min_open=True),
    metavar="V",
    help="Run the path at V m/s instead of timing it by its stamps (--path-topic only).",
)
@click.option("--out", type=click.Path(path_type=Path), required=True, metavar="FILE.csv", help="Waypoints CSV.")
@overwrite_option
def import_(
    bag: Path, path_topic: str | None, odom_topic: str | None, speed: float | None, out: Path, overwrite: bool
) -> int:
    """Write a waypoints CSV for `[trajectory] kind = "waypoints"` from BAG (a rosbag2 folder, or its .mcap or
    .db3 file): a planner's path, timed by its stamps or run at --speed, or a driven trajectory from odometry."""
    from ..outdir import atomic_write
    from ..ros import reference_from_odometry, reference_from_path, write_reference_csv

    if (path_topic is None) == (odom_topic is None):
        raise ConfigError("--path-topic", "give exactly one of --path-topic and --odom-topic", "")
    if speed is not None and odom_topic is not None:
        raise ConfigError("--speed", "a driven trajectory is timed by its stamps", "drop --speed, or use --path-topic")
    if out.suffix.lower() != ".csv":
        raise ConfigError("--out", f"'{out}' is not a .csv file", "give FILE.csv")
    if out.exists() and not overwrite:
        raise ConfigError("--out", f"'{out}' exists", "give a new file, or add --overwrite to replace it")
    if path_topic is not None:
        reference = reference_from_path(bag, path_topic, speed=speed)
    else:
        assert odom_topic is not None, "one of the two topics was checked above"
        reference = reference_from_odometry(bag, odom_topic)
    comment = f"ddtrack import of {bag}: {reference.source}"
    atomic_write(out, lambda file: write_reference_csv(reference, file, comment=comment))
    rows = len(reference.columns["x"])
    timing = f"over {reference.duration:.6g} s, timed by the bag's stamps" if reference.timed else "untimed"
    click.echo(f"wrote {out}: {rows} points {timing}")
    for note in reference.notes:
        click.echo(f"note: {note}", err=True)
    speed_line = f"\nspeed = {speed:g}" if speed is not None else ""
    click.echo(f'use it in a scenario beside it:\n[trajectory]\nkind = "waypoints"\nfile = "{out.name}"{speed_line}')
    return 0
