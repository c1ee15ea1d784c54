"""The identification commands: ``excite`` (a plan to drive on the robot) and ``identify`` (its lag model from the
log), docs/identification.md."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

from ..errors import ConfigError
from . import cli, enable_compilation_cache, overwrite_option

if TYPE_CHECKING:
    from ..robots import RobotPreset
    from ..sysid import SpeedFit, SpeedModel


@cli.command(short_help="Write a plan of timed cmd_vel commands (or voltages) that makes a robot's log identify it.")
@click.option("--preset", metavar="NAME", help="Take the top speed and yaw rate of this robot (`ddtrack list robots`).")
@click.option("--max-speed", type=click.FloatRange(min=0.0, min_open=True), metavar="V", help="Top speed [m/s].")
@click.option(
    "--max-yaw-rate", type=click.FloatRange(min=0.0, min_open=True), metavar="W", help="Top yaw rate [rad/s]."
)
@click.option("--fraction", type=click.FloatRange(0.05, 1.0), default=0.6, show_default=True, help="Of the top speeds.")
@click.option("--duration", type=click.FloatRange(8.0, 3600.0), default=60.0, show_default=True, help="[s]")
@click.option(
    "--rate", type=click.FloatRange(1.0, 1000.0), default=20.0, show_default=True, help="Commands per second."
)
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True, help="Draws the step levels.")
@click.option(
    "--out",
    type=click.Path(path_type=Path),
    required=True,
    metavar="FILE",
    help="FILE.csv (t, v, omega) or FILE.mcap / a folder name (a bag of /cmd_vel for `ros2 bag play`).",
)
@click.option("--start", type=float, metavar="SECONDS", help="Stamp of t = 0 in a bag [default: now].")
@click.option(
    "--volts",
    type=click.FloatRange(min=0.0, min_open=True),
    metavar="U",
    help="Instead, a plan of armature voltages (t, u_r, u_l) within +-U [V], for `identify --model motor`: held "
    "steps of common and differential voltage, each followed by its opposite (CSV only).",
)
@overwrite_option
def excite(
    preset: str | None,
    max_speed: float | None,
    max_yaw_rate: float | None,
    fraction: float,
    duration: float,
    rate: float,
    seed: int,
    out: Path,
    start: float | None,
    volts: float | None,
    overwrite: bool,
) -> int:
    """Write an excitation plan: held steps of forward speed, then of yaw rate, then arcs of both, within --fraction
    of the robot's top speeds. Drive it on the robot while recording /cmd_vel and /odom, then `ddtrack identify`
    the bag. With --volts, a plan of voltages for the motors instead."""
    import time

    from ..outdir import atomic_write
    from ..ros import check_target, write_bag
    from ..sysid import excitation_plan

    if volts is not None:
        return _voltage_plan(volts, duration, rate, seed, out, overwrite)
    top_speed, top_yaw_rate = _top_speeds(preset, max_speed, max_yaw_rate)
    kind = out.suffix.lower()
    if kind not in (".csv", ".mcap", ""):
        raise ConfigError(
            "--out", f"'{out}' has the suffix '{out.suffix}'", "give FILE.csv, FILE.mcap or a folder name"
        )
    check_target(out, overwrite=overwrite, option="--out")
    plan = excitation_plan(
        max_speed=top_speed, max_yaw_rate=top_yaw_rate, duration=duration, rate=rate, seed=seed, fraction=fraction
    )
    if kind == ".csv":
        table = zip(plan.t.tolist(), plan.v.tolist(), plan.omega.tolist(), strict=True)
        rows = "".join(f"{t!r},{v!r},{w!r}\n" for t, v, w in table)
        atomic_write(out, lambda file: file.write(("t,v,omega\n" + rows).encode()))
    else:
        from ..ros.messages import twist

        origin = round((start if start is not None else time.time()) * 1e9)
        messages = (
            ("/cmd_vel", "geometry_msgs/msg/Twist", origin + round(t * 1e9), twist(v, w))
            for t, v, w in zip(plan.t, plan.v, plan.omega, strict=True)
        )
        write_bag(out, messages)
    click.echo(
        f"wrote {out}: {len(plan.t)} commands over {duration:g} s, |v| <= {fraction * top_speed:.3g} m/s, "
        f"|omega| <= {fraction * top_yaw_rate:.3g} rad/s; followed exactly it goes {plan.reach():.2g} m from the "
        "start: clear that much floor around the robot"
    )
    return 0


def _voltage_plan(volts: float, duration: float, rate: float, seed: int, out: Path, overwrite: bool) -> int:
    """``excite --volts``: reversing voltage steps as a CSV of t [s], u_r, u_l [V]."""
    from ..outdir import atomic_write
    from ..ros import check_target
    from ..sysid import reversing_steps

    if out.suffix.lower() != ".csv":
        raise ConfigError(
            "--out", f"'{out}' is not a .csv file", "a voltage plan is a CSV: no standard ROS 2 message carries volts"
        )
    check_target(out, overwrite=overwrite, option="--out")
    t, voltage = reversing_steps(amplitude=volts, duration=duration, rate=rate, seed=seed)
    rows = "".join(
        f"{time!r},{right!r},{left!r}\n" for time, (right, left) in zip(t.tolist(), voltage.tolist(), strict=True)
    )
    atomic_write(out, lambda file: file.write(("t [s],u_r [V],u_l [V]\n" + rows).encode()))
    click.echo(
        f"wrote {out}: {t.size} voltage pairs over {duration:g} s within +-{volts:g} V; drive them open loop, log "
        "t, u_r, u_l, v, omega and the currents i_r, i_l, then `ddtrack identify LOG.csv --model motor`"
    )
    return 0


def _preset_option(name: str) -> RobotPreset:
    """The robot preset ``--preset`` names (a misspelt one: exit 2 naming the option, with a did-you-mean)."""
    from ..robots import preset

    try:
        return preset(name)
    except ConfigError as exc:
        raise ConfigError("--preset", exc.message, exc.suggestion) from None


def _top_speeds(preset: str | None, max_speed: float | None, max_yaw_rate: float | None) -> tuple[float, float]:
    """The top speed and yaw rate from the options, or from the preset where they are left out."""
    if preset is not None:
        robot = _preset_option(preset)
        max_speed = max_speed if max_speed is not None else robot.max_speed
        max_yaw_rate = max_yaw_rate if max_yaw_rate is not None else robot.max_yaw_rate
    if max_speed is None or max_yaw_rate is None:
        missing = "--max-speed" if max_speed is None else "--max-yaw-rate"
        raise ConfigError(
            missing, "the robot's top speeds are needed", "give --preset NAME, or --max-speed and --max-yaw-rate"
        )
    return max_speed, max_yaw_rate


@cli.command(short_help="Identify a robot's velocity lags, its body model, or its motors, from a log.")
@click.argument("log", metavar="LOG", type=click.Path(path_type=Path))
@click.option(
    "--model",
    type=click.Choice(["lag", "body", "motor"]),
    default="lag",
    show_default=True,
    help="lag: a base taking cmd_vel (theta_1..theta_6); body: a robot driven by wheel torques (mass, inertia, "
    "centre of mass, friction); motor: one driven by voltages (its motors' R_a, k_t, k_e and the body, from a "
    "table of t, u_r, u_l, v, omega and the currents i_r, i_l).",
)
@click.option("--cmd-topic", default="/cmd_vel", show_default=True, help="lag: the commands (Twist or TwistStamped).")
@click.option("--joint-topic", default="/joint_states", show_default=True, help="body: the wheel efforts.")
@click.option("--odom-topic", default="/odom", show_default=True, help="The measured speeds (Odometry's twist).")
@click.option(
    "--speeds",
    type=click.Choice(["odom", "joints"]),
    default="odom",
    show_default=True,
    help="A bag's measured speeds: odom, the --odom-topic's twist; joints, the wheel speeds of --joint-topic, "
    "with the wheel radius and half axle (--preset, or --wheel-radius and --half-axle).",
)
@click.option(
    "--preset",
    metavar="NAME",
    help="body, motor: take the wheel radius and half axle of this robot (motor: also its mass, supply voltage, "
    "and its datasheet resistance when no currents were logged).",
)
@click.option("--wheel-radius", type=click.FloatRange(min=0.0, min_open=True), metavar="R", help="body, motor: [m].")
@click.option("--half-axle", type=click.FloatRange(min=0.0, min_open=True), metavar="L", help="body, motor: [m].")
@click.option(
    "--mass",
    type=click.FloatRange(min=0.0, min_open=True),
    metavar="KG",
    help="motor: the robot's weighed mass [kg], which sets the torques' scale [default: the preset's].",
)
@click.option(
    "--max-delay", type=click.FloatRange(0.0, 2.0), default=0.3, show_default=True, help="Input delays tried [s]."
)
@click.option("--out", type=click.Path(path_type=Path), metavar="FILE.toml", help="Write the [plant] fragment here.")
@overwrite_option
def identify(
    log: Path,
    model: str,
    cmd_topic: str,
    joint_topic: str,
    odom_topic: str,
    speeds: str,
    preset: str | None,
    wheel_radius: float | None,
    half_axle: float | None,
    mass: float | None,
    max_delay: float,
    out: Path | None,
    overwrite: bool,
) -> int:
    """Fit a model and the input delay to LOG: a bag (a folder, .mcap or .db3: /cmd_vel or /joint_states, and
    /odom), a CSV or Parquet table (t, v, omega and v_cmd, omega_cmd, tau_r, tau_l, or u_r, u_l with i_r, i_l), or a
    run folder. Prints each parameter with its 95 % interval, the fit on the held-out last quarter, and what the log
    could not separate, as a [plant] fragment."""
    from ..ros import check_target
    from ..sysid import LAG, body_model, identify_body, identify_lag, lag_time_constants, plant_keys, read_speed_log
    from ..sysid.body import plant_std

    if out is not None:
        if out.suffix.lower() != ".toml":
            raise ConfigError("--out", f"'{out}' is not a .toml file", "give FILE.toml")
        check_target(out, overwrite=overwrite, option="--out")
    enable_compilation_cache()  # the fit's programs take seconds to compile; a second log of the shape loads them
    if model != "lag" or speeds == "joints":
        radius, half = _geometry(preset, wheel_radius, half_axle)
    if model == "motor":
        return _identify_motor(log, preset, radius, half, mass, max_delay, out)
    speed_log = read_speed_log(
        log,
        model=model,
        cmd_topic=cmd_topic,
        odom_topic=odom_topic,
        joint_topic=joint_topic,
        wheels=(radius, half) if speeds == "joints" else None,
    )
    if model == "body":
        fit = identify_body(speed_log, wheel_radius=radius, half_axle=half, max_delay=max_delay)
        described = body_model(wheel_radius=radius, half_axle=half)
    else:
        fit, described = identify_lag(speed_log, max_delay=max_delay), LAG
    lines = [f"# ddtrack identify {log}: the {model} model (docs/identification.md), 95 % intervals"]
    lines += _fitted_lines(described, fit)
    if model == "lag":
        lag_v, lag_w = lag_time_constants(fit.params)
        lines.append(f"#   lags {lag_v:.3g} s (v) and {lag_w:.3g} s (omega); command delay {_delay(fit)}")
    else:
        lines.append(f"#   torque delay {_delay(fit)}; the wheels' spin inertia is folded into mass and inertia")
    lines += [*_held_out_lines(fit), "[plant]"]
    if model == "lag":
        lines += ['model = "lag"', "lag = [" + ", ".join(repr(float(value)) for value in fit.params) + "]"]
    else:
        lines += _keyed(plant_keys(fit), plant_std(fit))
        lines += [f"wheel_radius = {radius!r}", f"half_axle = {half!r}"]
    lines += _sensing_lines(fit)
    return _report(lines, fit, out)


def _delay(fit: SpeedFit) -> str:
    """The fitted input delay with its 95 % interval, to the 0.1 ms the fragment keeps."""
    return f"{fit.delay:.4f} +- {1.96 * fit.delay_std:.2g} s"


def _sensing_lines(fit: SpeedFit) -> list[str]:
    """The fragment's [sensing] section: the fitted delay to 0.1 ms (finer than any log resolves), none if 0."""
    delay = round(fit.delay, 4)
    if delay <= 0:
        return []
    return ["[sensing]", f"actuation_delay = {delay!r}  # +- {1.96 * fit.delay_std:.2g} s (95 %), fitted"]


def _report(lines: list[str], fit: SpeedFit, out: Path | None) -> int:
    """Print the fragment, write it to ``out`` (atomically), and warn when the held-out fit is poor."""
    from ..outdir import atomic_write

    text = "\n".join(lines) + "\n"
    click.echo(text, nl=False)
    if out is not None:
        atomic_write(out, lambda file: file.write(text.encode()))
        click.echo(f"wrote {out}")
    if min(fit.fit_percent.values()) < 50:
        click.echo("warning: the model predicts the held-out speeds poorly (fit below 50 %)", err=True)
    return 0


def _keyed(values: dict[str, float], std: dict[str, float]) -> list[str]:
    """TOML lines ``key = value``, with ``# +- 1.96 std (95 %)`` where the value is uncertain."""
    return [
        f"{key} = {value!r}" + (f"  # +- {1.96 * std[key]:.2g} (95 %)" if 0.0 < std.get(key, 0.0) else "")
        for key, value in values.items()
    ]


def _fitted_lines(model: SpeedModel, fit: SpeedFit) -> list[str]:
    """Each parameter with its 95 % interval."""
    return [
        f"#   {name} = {value:.6g} +- {1.96 * sigma:.2g} [{unit}]"
        for name, unit, value, sigma in zip(model.names, model.units, fit.params, fit.std, strict=True)
    ]


def _held_out_lines(fit: SpeedFit) -> list[str]:
    """How the speeds were read, the held-out fit, and what the log could not separate."""
    reading = "means over each sample interval (odometry)" if fit.interval_mean else "instantaneous"
    return [
        f"#   speeds read as {reading}",
        f"#   fit on the held-out last quarter ({fit.samples[1]} samples): v {fit.fit_percent['v']:.1f} %, "
        f"omega {fit.fit_percent['omega']:.1f} %; residual spread {fit.noise[0]:.2g} m/s, {fit.noise[1]:.2g} rad/s",
        *(f"#   note: {note}" for note in fit.notes),
    ]


def _identify_motor(
    log: Path, preset: str | None, radius: float, half: float, mass: float | None, max_delay: float, out: Path | None
) -> int:
    """``identify --model motor``: the drivetrain constants, the armature's R_a and k_e (with currents), and the
    equivalent robot and motor as a ``[plant]`` fragment with ``[plant.motor]``."""
    import numpy as np

    from ..model.motor_plants import motor_from_datasheet
    from ..sysid import identify_motor, motor_model, plant_fragment, read_motor_log
    from ..sysid.motor import SYSID_NAMES, SYSID_UNITS, fragment_std, sysid_constants, sysid_std, time_constants

    robot = _preset_option(preset) if preset is not None else None
    if mass is None and robot is None:
        raise ConfigError("--mass", "the motor model needs the robot's mass to scale its torques", "weigh it")
    motor_log = read_motor_log(log)
    fit = identify_motor(motor_log, wheel_radius=radius, half_axle=half, max_delay=max_delay)
    preset_motor = None if robot is None or robot.motor is None else motor_from_datasheet(robot.motor)
    supply = None if preset_motor is not None else float(np.max(np.abs(motor_log.speeds.command)))
    weighed = mass if mass is not None else float(robot.params["mass"])  # type: ignore[union-attr]
    plant, motor, notes = plant_fragment(fit, mass=weighed, supply_voltage=supply, preset_motor=preset_motor)
    if mass is None:
        notes.append(f"the mass {weighed:g} kg is preset '{preset}''s: weigh the robot and give --mass")
    if supply is not None:
        notes.append(f"supply_voltage is the largest voltage logged ({supply:.4g} V): set your battery's")
    lines = [f"# ddtrack identify {log}: the motor model (docs/identification.md), 95 % intervals"]
    lines += _fitted_lines(motor_model(wheel_radius=radius, half_axle=half), fit.drive)
    if fit.armature is not None:
        armature = fit.armature
        lines.append(f"#   R_a = {armature.resistance:.6g} +- {1.96 * armature.std[0]:.2g} [ohm]")
        lines.append(f"#   k_e = {armature.back_emf:.6g} +- {1.96 * armature.std[1]:.2g} [V s/rad]")
    sysid = sysid_constants(fit.drive.params, wheel_radius=radius, half_axle=half)
    sysid_sigma = sysid_std(fit.drive, wheel_radius=radius, half_axle=half)
    lines.append(f"#   as WPILib's SysId reports a drivetrain (track width {2 * half:.6g} m; no term for kA_md):")
    lines += [
        f"#   {name} = {value:.6g} +- {1.96 * sigma:.2g} [{unit}]"
        for name, unit, value, sigma in zip(SYSID_NAMES, SYSID_UNITS, sysid, sysid_sigma, strict=True)
    ]
    lag_v, lag_w = time_constants(fit.drive.params, wheel_radius=radius, half_axle=half)
    lines.append(f"#   time constants {lag_v:.3g} s (v) and {lag_w:.3g} s (omega); voltage delay {_delay(fit.drive)}")
    step = float(np.median(np.diff(motor_log.speeds.t)))
    if min(lag_v, lag_w) < step:
        notes.append(
            f"a time constant is shorter than a sample ({step:.3g} s): the log barely resolves it, so kA_v and kA_w "
            "are rough; log at a higher rate"
        )
    lines += _held_out_lines(fit.drive)
    lines += [f"#   note: {note}" for note in notes]
    std = fragment_std(fit, mass=weighed, preset_motor=preset_motor)
    lines += ["[plant]", *_keyed(plant, std)]
    lines += [f"wheel_radius = {radius!r}", f"half_axle = {half!r}", "[plant.motor]"]
    lines += _keyed(motor, {key.removeprefix("motor."): value for key, value in std.items() if "motor." in key})
    lines += _sensing_lines(fit.drive)
    return _report(lines, fit.drive, out)


def _geometry(preset: str | None, wheel_radius: float | None, half_axle: float | None) -> tuple[float, float]:
    """The wheel radius and half axle from the options, or from the preset where they are left out."""
    if preset is not None:
        robot = _preset_option(preset)
        wheel_radius = wheel_radius if wheel_radius is not None else robot.params["wheel_radius"]
        half_axle = half_axle if half_axle is not None else robot.params["half_axle"]
    if wheel_radius is None or half_axle is None:
        missing = "--wheel-radius" if wheel_radius is None else "--half-axle"
        raise ConfigError(
            missing,
            "the body and motor models, and wheel-joint speeds, need the robot's geometry",
            "give --preset, or --wheel-radius and --half-axle",
        )
    return float(wheel_radius), float(half_axle)
