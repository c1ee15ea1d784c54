"""``ddtrack drive``: the scenario's controller on a ROS 2 robot, live over DDS (docs/ros.md)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import click

from ..errors import ConfigError
from . import cli, folder_name
from .live import live_options


def write_drive_folder(spec: Any, summary: Any, folder: Path, recording: Path | None, *, effort: bool) -> None:
    """The drive's run folder (:func:`ddtrack.ros.measured.measured_run`), with ``recording`` (the default bag)
    moved in as ``drive.mcap``; the bag alone in ``folder`` when no command was computed."""
    from ..outdir import staged_folder
    from ..ros.measured import measured_run
    from ..rundir import write_run

    if not summary.rows:
        if recording is not None and recording.exists():
            folder.mkdir(parents=True, exist_ok=True)
            os.replace(recording, folder / "drive.mcap")
        return
    commands = ("tau_r", "tau_l") if effort else ("v_cmd", "omega_cmd")
    columns, metrics = measured_run(spec, summary.rows, commands=commands)
    with staged_folder(folder, command="run") as stage:
        write_run(stage, spec, columns, metrics)
        if recording is not None and recording.exists():
            os.replace(recording, stage / "drive.mcap")
    mean = metrics.get("e_tr_mean")
    error = "no e_tr (the drive ended before the metric window)" if mean is None else f"e_tr mean {mean:.4g} m"
    click.echo(f"wrote {folder}: the run as the odometry measured it, {error}", err=True)


#: what --cmd-vel-type accepts: the two messages a ROS 2 base takes its velocity commands in
CMD_VEL_TYPES = ("geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped")


def command_type(given: str | None, twist_stamped: bool) -> str:
    """The commands' message type from --cmd-vel-type and its shorthand --twist-stamped; anything but a twist is
    refused here, in one line naming the option, before DDS or JAX start (a typo would otherwise surface as a
    type-store error about ``msgtype``, or as a topic no robot subscribes to)."""
    from ..ros.messages import typestore

    if given is None:
        return CMD_VEL_TYPES[1] if twist_stamped else CMD_VEL_TYPES[0]
    accepted = " or ".join(CMD_VEL_TYPES)
    if given not in CMD_VEL_TYPES:
        what = "not a twist" if given in typestore().types else "not a ROS 2 message type"
        raise ConfigError("--cmd-vel-type", f"'{given}' is {what}: give {accepted}")
    if twist_stamped and given != CMD_VEL_TYPES[1]:
        raise ConfigError("--cmd-vel-type", f"'{given}' contradicts --twist-stamped: give one of them")
    return given


@cli.command(short_help="Drive a ROS 2 robot live with SCENARIO's controller (/odom in, /cmd_vel out).")
@click.argument("scenario", type=click.Path(path_type=Path))
@click.option("--odom-topic", default="/odom", show_default=True, metavar="TOPIC", help="nav_msgs/Odometry in.")
@click.option("--cmd-vel-topic", default="/cmd_vel", show_default=True, metavar="TOPIC", help="Commands out.")
@click.option(
    "--path-topic",
    metavar="TOPIC",
    help="Follow the first nav_msgs/Path received here (e.g. /plan), timed by its stamps as `import` does, "
    "instead of the scenario's reference.",
)
@click.option(
    "--pose-from",
    type=click.Choice(["odom", "tf"]),
    default="odom",
    show_default=True,
    help="odom: the pose and twist of --odom-topic; tf: the pose of the transform --odom-frame -> --base-frame on "
    "/tf (a direct one: no chained lookup), its twist differenced from consecutive stamps.",
)
@click.option("--odom-frame", default="odom", show_default=True, metavar="FRAME", help="Parent frame (--pose-from tf).")
@click.option(
    "--base-frame", default="base_footprint", show_default=True, metavar="FRAME", help="Child frame (--pose-from tf)."
)
@click.option(
    "--cmd-vel-type",
    metavar="TYPE",
    help=f"The commands' message type: {' or '.join(CMD_VEL_TYPES)} [default: {CMD_VEL_TYPES[0]}].",
)
@click.option("--twist-stamped", is_flag=True, help=f"Shorthand for --cmd-vel-type {CMD_VEL_TYPES[1]}.")
@click.option(
    "--odom-timeout",
    type=click.FloatRange(min=0.0, min_open=True),
    default=0.5,
    show_default=True,
    metavar="SECONDS",
    help="Send a zero twist while the latest odometry is older than this.",
)
@click.option(
    "--clock",
    type=click.Choice(["wall", "odom"]),
    default="wall",
    show_default=True,
    help="wall: a period timer using the latest odometry; odom: one command per new odometry stamp (lockstep "
    "with a simulated robot), t = stamp - first stamp.",
)
@click.option(
    "--effort-topic",
    metavar="TOPIC",
    help="For a torque-output law: publish its wheel torques [N m] here as std_msgs/Float64MultiArray (a ros2_control "
    "JointGroupEffortController's /<controller>/commands), clamped to max_torque; no /cmd_vel.",
)
@click.option(
    "--wheel-velocity-topic",
    metavar="TOPIC",
    help="For a velocity-output law: publish its (v, omega) as wheel speeds [rad/s] on the scenario's wheels here, "
    "as std_msgs/Float64MultiArray (a ros2_control JointGroupVelocityController's /<controller>/commands), both "
    "scaled down together to the wheels' top speed; no /cmd_vel.",
)
@click.option(
    "--joints",
    default="wheel_left_joint,wheel_right_joint",
    show_default=True,
    metavar="LEFT,RIGHT",
    help="The effort or velocity controller's joints parameter, in its order (names saying left and right).",
)
@click.option("--dry-run", is_flag=True, help="Compute and record the commands without publishing them.")
@click.option(
    "--wait",
    type=click.FloatRange(min=0.0, min_open=True),
    default=30.0,
    show_default=True,
    metavar="SECONDS",
    help="How long to wait for the first odometry (and path).",
)
@click.option("--bag", type=click.Path(path_type=Path), metavar="FILE.mcap", help="[default: OUT/drive.mcap].")
@live_options(
    "The run folder: what the odometry measured against the reference, as `ddtrack run` writes one, and the bag "
    "[default: runs/NAME_drive]."
)
def drive(
    scenario: Path,
    overrides: tuple[str, ...],
    odom_topic: str,
    cmd_vel_topic: str,
    path_topic: str | None,
    pose_from: str,
    odom_frame: str,
    base_frame: str,
    cmd_vel_type: str | None,
    twist_stamped: bool,
    odom_timeout: float,
    clock: str,
    effort_topic: str | None,
    wheel_velocity_topic: str | None,
    joints: str,
    dry_run: bool,
    wait: float,
    domain: int | None,
    bag: Path | None,
    out: Path | None,
    overwrite: bool,
) -> int:
    """Drive a ROS 2 robot live with SCENARIO's velocity-output controller: odometry in, /cmd_vel out at the
    control period, clamped to the scenario's limits; a zero twist on stale odometry, at the reference's end and
    on Ctrl-C or SIGTERM. A torque-output law needs --effort-topic: its wheel torques go to a ros2_control effort
    controller (zero torques where a zero twist would go); --wheel-velocity-topic sends a velocity law's commands
    to a ros2_control velocity controller as wheel speeds. What it saw and sent is recorded as an MCAP bag, and
    scored as a run folder (the measured pose against the reference) that report and export read."""
    from ..ros.dds import dds_topic_name
    from ..ros.drive import DriveOptions, refuse_unfit_law
    from ..ros.drive import drive as drive_robot
    from ..ros.joint_groups import wheel_sides
    from ..scenario import load_scenario

    msgtype = command_type(cmd_vel_type, twist_stamped)
    for option, frame in (("--odom-frame", odom_frame), ("--base-frame", base_frame)):
        if not frame.strip("/") or any(c.isspace() for c in frame):
            raise ConfigError(option, f"'{frame}' is not a frame id (give a name like odom or base_footprint)")
    spec = load_scenario(scenario, overrides=overrides)
    refuse_unfit_law(spec, effort_topic, wheel_velocity_topic)
    joint_names = tuple(name.strip() for name in joints.split(","))
    wheel_sides(joint_names)
    for option, topic in (
        ("--odom-topic", odom_topic),
        ("--cmd-vel-topic", cmd_vel_topic),
        ("--path-topic", path_topic),
        ("--effort-topic", effort_topic),
        ("--wheel-velocity-topic", wheel_velocity_topic),
    ):
        if topic is not None:
            try:
                dds_topic_name(topic)
            except ConfigError as exc:
                raise ConfigError(option, f"{exc.message} (give a name like /odom)") from None
    from ..outdir import check_output

    folder = out if out is not None else Path("runs") / folder_name(f"{spec.name}_drive")
    target = bag if bag is not None else folder / "drive.mcap"
    if target.suffix.lower() != ".mcap":
        raise ConfigError("--bag", f"'{target}' is not an .mcap file", "give FILE.mcap")
    if bag is not None and target.exists() and not overwrite:
        raise ConfigError("--bag", f"'{target}' exists", "give a new file, or add --overwrite to replace it")
    check_output(folder, command="run", overwrite=overwrite)  # before the robot moves
    options = DriveOptions(
        odom_topic=odom_topic,
        cmd_vel_topic=cmd_vel_topic,
        path_topic=path_topic,
        twist_stamped=msgtype == CMD_VEL_TYPES[1],
        pose_from="tf" if pose_from == "tf" else "odom",
        odom_frame=odom_frame,
        base_frame=base_frame,
        odom_timeout=odom_timeout,
        clock="odom" if clock == "odom" else "wall",
        dry_run=dry_run,
        wait=wait,
        domain=domain,
        effort_topic=effort_topic,
        wheel_velocity_topic=wheel_velocity_topic,
        joints=joint_names,
    )
    # the default bag goes into the run folder, which is swapped in whole at the end: written beside it meanwhile
    recording = target if bag is not None else folder.parent / f".{folder.name}.drive.mcap"
    recording.parent.mkdir(parents=True, exist_ok=True)
    summary = drive_robot(spec, options, recording)
    for line in summary.lines():
        click.echo(line, err=True)
    write_drive_folder(spec, summary, folder, recording if bag is None else None, effort=effort_topic is not None)
    if summary.counts:
        topics = ", ".join(f"{topic} {count}" for topic, count in summary.counts.items())
        click.echo(f"wrote {target}: {topics}")
    return {"SIGINT": 130, "SIGTERM": 143}.get(summary.ended, 0)
