"""``ddtrack drive``: a scenario's velocity-output controller driving a ROS 2 robot live (docs/ros.md).

It reads odometry (``nav_msgs/msg/Odometry``, or the pose of one ``/tf`` transform: ``ddtrack.ros.poses``), follows
the scenario's reference or a planner's path, and publishes ``/cmd_vel`` once per control period, on the wall clock
(a period timer using the latest odometry) or in lockstep with a simulated robot (one command per new odometry
stamp). Safety first: a zero twist when the odometry is stale, at the reference's end, on SIGINT and on SIGTERM;
every command clamped to the scenario's limits. A torque-output law publishes wheel torques to a ros2_control
effort controller instead (``--effort-topic``), and a velocity law may publish wheel speeds to a velocity controller
(``--wheel-velocity-topic``; ``ddtrack.ros.joint_groups``); their zero command is zero torques or speeds. What it
saw and sent is written as an MCAP bag when it stops, however it stops.
"""

from __future__ import annotations

import math
import signal
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from ..errors import ConfigError
from .dds import DEFAULT_QOS, SENSOR_DATA_QOS, Participant
from .export import write_bag
from .joint_groups import (
    ARRAY_TYPE,
    DEFAULT_JOINTS,
    torque_limit,
    wheel_array,
    wheel_sides,
    wheel_speed_limit,
    wheel_speeds,
    within_wheel_limit,
)
from .messages import NANOSECONDS, header, message, planar_pose, quaternion_yaw, stamp_nanoseconds, twist
from .poses import TF_QOS, TF_TOPIC, TF_TYPE, TfOdometry

ODOMETRY_TYPE = "nav_msgs/msg/Odometry"
PATH_TYPE = "nav_msgs/msg/Path"
TWIST_TYPE = "geometry_msgs/msg/Twist"
TWIST_STAMPED_TYPE = "geometry_msgs/msg/TwistStamped"
POSE_STAMPED_TYPE = "geometry_msgs/msg/PoseStamped"
#: [s] of the reference between two lines of the live tracking error on stderr
REPORT_EVERY = 2.0
#: where the wall clock's ticks fall in the period after the odometry's arrivals: half way, so that a robot
#: publishing at the control rate has x_k delivered before tick k, and tick k's command back before its period k + 1
#: starts, with half a period of margin on each side (ticks in phase with the odometry race it tick by tick)
TICK_PHASE = 0.5


@dataclass(frozen=True)
class DriveOptions:
    """How ``ddtrack drive`` talks to the robot; the CLI's options, one field each (docs/ros.md).

    Attributes
    ----------
    odom_topic, cmd_vel_topic : str
        The odometry in and the commands out.
    path_topic : str or None
        A ``nav_msgs/msg/Path`` topic whose first message replaces the scenario's reference (re-timed as
        ``ddtrack import`` does).
    twist_stamped : bool
        Publish ``geometry_msgs/msg/TwistStamped`` instead of ``Twist``.
    pose_from : {"odom", "tf"}
        Read the pose from the odometry topic, or from the transform ``odom_frame`` -> ``base_frame`` on ``/tf``
        (for a robot that broadcasts no odometry; the twist is then differenced from consecutive poses).
    odom_frame, base_frame : str
        The parent and child frames of that transform (``pose_from="tf"`` only).
    odom_timeout : float
        [s] odometry older than this stops the robot (a zero twist each period).
    clock : {"wall", "odom"}
        A period timer on the wall clock, or one command per new odometry stamp (lockstep).
    dry_run : bool
        Compute and record the commands without publishing them.
    wait : float
        [s] to wait for the first odometry (and path) before giving up.
    domain : int or None
        The DDS domain (``ROS_DOMAIN_ID`` when None).
    effort_topic : str or None
        Publish a torque-output law's wheel torques here as ``std_msgs/msg/Float64MultiArray`` (a ros2_control
        ``JointGroupEffortController``'s ``/<controller>/commands``) instead of /cmd_vel (``ddtrack.ros.joint_groups``).
    wheel_velocity_topic : str or None
        Publish a velocity law's (v, omega) as wheel speeds [rad/s] on the believed wheels here, a ros2_control
        ``JointGroupVelocityController``'s ``/<controller>/commands``, instead of /cmd_vel.
    joints : tuple of str
        The joint-group controller's ``joints`` parameter, in its order: which entry is the right wheel, which the left.
    """

    odom_topic: str = "/odom"
    cmd_vel_topic: str = "/cmd_vel"
    path_topic: str | None = None
    twist_stamped: bool = False
    pose_from: Literal["odom", "tf"] = "odom"
    odom_frame: str = "odom"
    base_frame: str = "base_footprint"
    odom_timeout: float = 0.5
    clock: Literal["wall", "odom"] = "wall"
    dry_run: bool = False
    wait: float = 30.0
    domain: int | None = None
    effort_topic: str | None = None
    wheel_velocity_topic: str | None = None
    joints: tuple[str, ...] = DEFAULT_JOINTS


@dataclass
class DriveSummary:
    """What a drive did: commands sent, tracking error, timing, and how it ended (for the summary line)."""

    commands: int = 0
    stale: int = 0  #: periods that sent a zero twist for stale odometry
    missed: int = 0  #: wall clock: periods skipped because the loop woke a period or more late
    errors: list[float] = field(default_factory=list)  #: e_tr [m] of each computed command
    jitter: list[float] = field(default_factory=list)  #: wall clock: |actual - nominal| period [s]
    ended: str = "the reference's end"
    counts: dict[str, int] = field(default_factory=dict)  #: messages in the bag, by topic
    rows: list[tuple] = field(default_factory=list)  #: (t, y, reference, command) of each command: the run folder's

    def lines(self) -> list[str]:
        """The end-of-drive summary, in plain lines."""
        mean = f"{np.mean(self.errors):.4g} m" if self.errors else "none"
        lines = [f"stopped at {self.ended}: {self.commands} commands, mean e_tr {mean}, {self.stale} stale periods"]
        if self.jitter:
            ms = 1e3 * np.asarray(self.jitter)
            median, p99 = np.percentile(ms, 50), np.percentile(ms, 99)
            lines.append(f"  missed periods {self.missed}; jitter median {median:.3f} ms, 99th percentile {p99:.3f} ms")
        return lines


def speed_limits(scenario: Any) -> tuple[float | None, float | None]:
    """The clamp of the commands, (|v| [m/s], |omega| [rad/s]) or None where nothing bounds one.

    Parameters
    ----------
    scenario : Scenario
        The scenario driven.

    Returns
    -------
    tuple of (float or None, float or None)
        The controller's ``max_velocity`` and ``max_yaw_rate`` where its config has them, else the robot's top
        speeds (its preset's rated limits, ``robot.top_speed``, its motors').
    """
    config = scenario.controller
    top_v, top_w, _ = scenario.top_speeds()
    v = getattr(config, "max_velocity", None)
    w = getattr(config, "max_yaw_rate", None)
    return (top_v if v is None else float(v)), (top_w if w is None else float(w))


def refuse_unfit_law(scenario: Any, effort_topic: str | None = None, wheel_velocity_topic: str | None = None) -> None:
    """Refuse a law whose output does not fit the command topic: wheel torques reach a robot only through a ros2_control
    effort controller (``--effort-topic``), a velocity law's (v, omega) are no efforts, and wheel speeds
    (``--wheel-velocity-topic``) come from a velocity law only."""
    from ..scenario import controller_output

    torque = controller_output(scenario.controller) == "torque"
    inner = getattr(scenario.controller, "inner", None)
    how = f" (inner = '{inner}')" if inner else ""
    if effort_topic is not None and wheel_velocity_topic is not None:
        raise ConfigError(
            "--wheel-velocity-topic", "cannot be combined with --effort-topic: a law's command goes to one controller"
        )
    if torque and wheel_velocity_topic is not None:
        raise ConfigError(
            "--wheel-velocity-topic",
            f"'{scenario.controller.kind}'{how} outputs wheel torques, not speeds: give --effort-topic for them, or "
            "drive a velocity-output law (inner = 'none', or a cmd_vel controller)",
        )
    if torque and effort_topic is None:
        raise ConfigError(
            "controller",
            f"'{scenario.controller.kind}'{how} outputs wheel torques, and no standard ROS 2 topic carries wheel "
            "torques to a robot: name a ros2_control effort controller's command topic with --effort-topic, or "
            "drive a velocity-output law (inner = 'none', or a cmd_vel controller)",
        )
    if not torque and effort_topic is not None:
        raise ConfigError(
            "--effort-topic",
            f"'{scenario.controller.kind}'{how} outputs (v, omega), not wheel torques: drop --effort-topic to "
            "publish them on /cmd_vel, or give a torque-output law (e.g. inner = 'computed_torque')",
        )


def path_scenario(data: dict[str, Any], path_message: Any, topic: str, base_dir: Path) -> Any:
    """The scenario with its trajectory replaced by a received Path, re-timed exactly as ``ddtrack import`` does
    (:func:`~ddtrack.ros.references.reference_from_path_message`); the robot starts where it is."""
    from ..scenario.files import validate_scenario
    from .references import path_scenario_data, reference_from_path_message

    data = path_scenario_data(data, reference_from_path_message(path_message, topic))
    data.pop("initial", None)  # the robot starts where it is
    return validate_scenario(data, base_dir=base_dir)


class Stop:
    """SIGINT and SIGTERM set a flag, read once per period, instead of raising inside DDS or the bag writer."""

    def __init__(self) -> None:
        self.signal: str | None = None
        self._previous: dict[int, Any] = {}

    def __enter__(self) -> Stop:
        for number in (signal.SIGINT, signal.SIGTERM):
            try:
                self._previous[number] = signal.signal(number, self._handle)
            except ValueError:  # not the main thread: the caller's own handling applies
                break
        return self

    def _handle(self, number: int, frame: Any) -> None:
        self.signal = signal.Signals(number).name

    def __exit__(self, *exc: object) -> None:
        for number, handler in self._previous.items():
            signal.signal(number, handler)


class Driver:
    """One live drive: the jitted controller, the topics, the recording; :func:`drive` runs it."""

    def __init__(self, scenario: Any, options: DriveOptions, node: Participant, log: Callable[[str], None]) -> None:
        import jax

        from ..runner import closed_loop, prepare

        setup, draws = prepare(scenario)
        loop = closed_loop(scenario, setup)
        self.nominal = setup.nominal
        self.scenario, self.options, self.log = scenario, options, log
        self.period = float(loop.control_period)
        self.duration = float(scenario.simulation.duration)
        self.limits = speed_limits(scenario)
        self._controller, self._key = loop.controller, draws.controller_key
        # closures, not the objects: jit hashes its function, and a trajectory or controller holding arrays has no hash
        self._step = jax.jit(lambda t, y, ref, memory: loop.controller.step(t, y, ref, memory))
        self._reference = jax.jit(lambda t: loop.trajectory(t))
        self.memory: Any = None
        self.summary = DriveSummary()
        self.recorded: list[tuple[str, str, int, Any]] = []
        self.latest_stamp = 0  #: the newest odometry stamp [ns]: the bag's clock in lockstep
        self.frames = ("odom", "base_footprint")
        ref = self._reference(0.0)
        y = np.array([float(ref.x), float(ref.y), float(ref.theta), 0.0, 0.0])
        self._step(0.0, y, ref, self._controller.init(y, ref, self._key))  # compiled now, not in the first period
        if options.pose_from == "tf":
            self.poses: TfOdometry | None = TfOdometry(options.odom_frame, options.base_frame)
            self.odometry = node.subscriber(TF_TOPIC, TF_TYPE, qos=TF_QOS)
        else:
            self.poses = None
            self.odometry = node.subscriber(options.odom_topic, ODOMETRY_TYPE, qos=SENSOR_DATA_QOS)
        msgtype = TWIST_STAMPED_TYPE if options.twist_stamped else TWIST_TYPE
        #: what goes out: a twist on /cmd_vel, or a joint-group controller's array of wheel torques or speeds
        self.output: Literal["twist", "effort", "wheel_velocity"] = "twist"
        self.wheel_limit: float | None = None  #: [rad/s] on either wheel, wheel-velocity mode
        topic = options.cmd_vel_topic
        if options.effort_topic is not None:  # wheel torques, and no /cmd_vel at all
            self.output, self.limits = "effort", (torque_limit(scenario),) * 2
            topic, msgtype = options.effort_topic, ARRAY_TYPE
        elif options.wheel_velocity_topic is not None:  # (v, omega) as wheel speeds, and no /cmd_vel
            self.output, self.wheel_limit = "wheel_velocity", wheel_speed_limit(scenario, self.nominal)
            topic, msgtype = options.wheel_velocity_topic, ARRAY_TYPE
        self.sides = wheel_sides(options.joints)  #: (right, left) indices in the joint-group controller's order
        self.command_topic = topic
        self.commands = None if options.dry_run else node.publisher(topic, msgtype, qos=DEFAULT_QOS)
        self._next_report = 0.0

    def body(self, odom: Any) -> np.ndarray:
        """The BODY vector [x, y, theta, v, omega] of an odometry message (its twist is in the body frame)."""
        pose, velocity = odom.pose.pose, odom.twist.twist
        self.frames = (odom.header.frame_id or "odom", odom.child_frame_id or "base_footprint")
        return np.array(
            [pose.position.x, pose.position.y, quaternion_yaw(pose.orientation), velocity.linear.x, velocity.angular.z]
        )

    def command(self, t: float, y: np.ndarray, nanoseconds: int) -> tuple[float, float]:
        """The clamped command at reference time ``t`` for the measured ``y``, (v, omega) (in wheel-velocity mode
        also scaled to the wheels' limit) or in effort mode (tau_r, tau_l) clamped to the torque limit; records the
        reference and e_tr."""
        ref = self._reference(t)
        if self.memory is None:
            self.memory = self._controller.init(y, ref, self._key)
        u, self.memory, _ = self._step(t, y, ref, self.memory)
        v, omega = (float(value) for value in np.asarray(u)[:2])
        if not (math.isfinite(v) and math.isfinite(omega)):
            v, omega = 0.0, 0.0
        v_max, w_max = self.limits
        v = v if v_max is None else min(max(v, -v_max), v_max)
        omega = omega if w_max is None else min(max(omega, -w_max), w_max)
        if self.output == "wheel_velocity":
            v, omega = within_wheel_limit(v, omega, self.nominal, self.wheel_limit)
        x_ref, y_ref, theta_ref = float(ref.x), float(ref.y), float(ref.theta)
        error = math.hypot(y[0] - x_ref, y[1] - y_ref)
        self.summary.errors.append(error)
        self.summary.rows.append((t, np.array(y), (x_ref, y_ref, theta_ref, float(ref.v), float(ref.omega)), v, omega))
        pose = message(
            POSE_STAMPED_TYPE, header=header(nanoseconds, self.frames[0]), pose=planar_pose(x_ref, y_ref, theta_ref)
        )
        self.recorded.append(("/reference", POSE_STAMPED_TYPE, nanoseconds, pose))
        if t >= self._next_report:
            torques = self.output == "effort"
            a, b = (("tau_r", "N m"), ("tau_l", "N m")) if torques else (("v", "m/s"), ("omega", "rad/s"))
            self.log(f"t = {t:6.2f} s  e_tr = {error:.4f} m  {a[0]} = {v:+.3f} {a[1]}  {b[0]} = {omega:+.3f} {b[1]}")
            self._next_report = t + REPORT_EVERY
        return v, omega

    def send(self, v: float, omega: float, nanoseconds: int, *, final: bool = False) -> None:
        """Publish (unless a dry run) and record one command (the final zero twist is not counted); in effort mode
        ``v, omega`` are (tau_r, tau_l) and go out as the effort controller's Float64MultiArray, in wheel-velocity
        mode as the wheel speeds of (v, omega)."""
        body = twist(v, omega)
        if self.output == "effort":
            outgoing = wheel_array(v, omega, self.sides)
        elif self.output == "wheel_velocity":
            outgoing = wheel_array(*wheel_speeds(v, omega, self.nominal), self.sides)
        elif self.options.twist_stamped:
            outgoing = message(TWIST_STAMPED_TYPE, header=header(nanoseconds, self.frames[1]), twist=body)
        else:
            outgoing = body
        if self.commands is not None:
            self.commands.publish(outgoing)
        self.recorded.append((self.command_topic, outgoing.__msgtype__, nanoseconds, outgoing))
        self.summary.commands += not final

    def halt(self) -> None:
        """The last word to the robot: a zero twist, acknowledged where the subscription is reliable."""
        try:
            self.send(0.0, 0.0, self.now(), final=True)
            if self.commands is not None:
                self.commands.flush(timeout=1.0)
        except Exception as exc:  # the bag must still be written
            self.log(f"warning: the final zero twist failed ({exc})")

    def now(self) -> int:
        """The bag's clock [ns]: the odometry's stamps in lockstep (simulated time), else the wall clock; so that a
        log's commands and measurements share one time line (``ddtrack identify`` reads it)."""
        return self.latest_stamp if self.options.clock == "odom" else time.time_ns()

    def receive(self, messages: list[Any]) -> list[Any]:
        """Record received odometry (at its stamp in lockstep, else at its receive time) and hand it on; from /tf,
        the messages carrying the transform are recorded as received and their odometry handed on."""
        if self.poses is not None:
            odometry = []
            for tf_message in messages:
                if found := self.poses.odometry(tf_message):
                    self.latest_stamp = max(self.latest_stamp, *(stamp_nanoseconds(odom.header) for odom in found))
                    self.recorded.append((TF_TOPIC, TF_TYPE, self.now(), tf_message))
                    odometry += found
            return odometry
        for odom in messages:
            self.latest_stamp = max(self.latest_stamp, stamp_nanoseconds(odom.header))
            self.recorded.append((self.options.odom_topic, ODOMETRY_TYPE, self.now(), odom))
        return messages

    def source(self) -> str:
        """What the pose is read from, for the waiting line and the error when none comes."""
        if self.poses is not None:
            return f"the transform {self.poses.parent} -> {self.poses.child} on {TF_TOPIC}"
        return f"{ODOMETRY_TYPE} on {self.options.odom_topic}"

    def first_odometry(self, stop: Stop) -> Any:
        """Wait for the first odometry message, up to ``options.wait`` seconds (a stop signal ends the wait)."""
        deadline = time.monotonic() + self.options.wait
        while stop.signal is None and time.monotonic() < deadline:
            if received := self.receive(self.odometry.wait(timeout=0.1)):
                return received[-1]
        self.summary.ended = stop.signal or ""
        if stop.signal is None:
            raise ConfigError(
                "--pose-from" if self.poses is not None else "--odom-topic",
                f"no {self.source()} within {self.options.wait:g} s",
                "check the topic, frames, ROS_DOMAIN_ID and the network (docs/ros.md)",
            )
        return None

    def run_wall(self, stop: Stop) -> None:
        """A period timer on the wall clock: each tick commands from the latest odometry, or stops the robot. Tick k
        comes :data:`TICK_PHASE` of a period after t_k = k T (t = 0 the first odometry's arrival), and its reference
        is taken at t_k, the time of the odometry it expects; its command is recorded when it is sent."""
        latest = self.first_odometry(stop)
        if latest is None:
            return
        arrived, wall0 = time.monotonic(), time.time_ns()
        start = arrived + TICK_PHASE * self.period  # tick 0
        if (pause := start - time.monotonic()) > 0:
            time.sleep(pause)
        received_at, k, woke = arrived, 0, time.monotonic()
        while stop.signal is None:
            t = k * self.period
            if t >= self.duration - 1e-9:
                return
            if fresh := self.receive(self.odometry.take()):
                latest, received_at = fresh[-1], time.monotonic()
            nanoseconds = wall0 + round((t + TICK_PHASE * self.period) * NANOSECONDS)
            if time.monotonic() - received_at > self.options.odom_timeout:
                self.summary.stale += 1
                self.send(0.0, 0.0, nanoseconds)
            else:
                self.send(*self.command(t, self.body(latest), nanoseconds), nanoseconds)
            k += 1
            late = time.monotonic() - (start + k * self.period)
            if late >= self.period:  # woke a whole period late or more: those ticks are skipped, not bunched
                skipped = int(late // self.period)
                self.summary.missed += skipped
                k += skipped
            pause = start + k * self.period - time.monotonic()
            if pause > 0:
                time.sleep(pause)
            now = time.monotonic()
            self.summary.jitter.append(abs((now - woke) - self.period))
            woke = now
        self.summary.ended = stop.signal

    def run_odom(self, stop: Stop) -> None:
        """Lockstep: one command per odometry message stamped later than the last, at t = stamp - first stamp."""
        first = self.first_odometry(stop)
        if first is None:
            return
        origin = stamp_nanoseconds(first.header)
        last, pending, received_at = origin - 1, [first], time.monotonic()
        while stop.signal is None:
            for odom in pending:
                nanoseconds = stamp_nanoseconds(odom.header)
                if nanoseconds <= last:
                    continue
                last = nanoseconds
                t = (nanoseconds - origin) / NANOSECONDS
                if t >= self.duration - 1e-9:
                    return
                self.send(*self.command(t, self.body(odom), nanoseconds), nanoseconds)
            if pending := self.receive(self.odometry.wait(timeout=min(self.period, self.options.odom_timeout))):
                received_at = time.monotonic()
            elif time.monotonic() - received_at > self.options.odom_timeout:
                self.summary.stale += 1
                self.send(0.0, 0.0, self.now())
        self.summary.ended = stop.signal


def drive(scenario: Any, options: DriveOptions, bag: Path, *, log: Callable[[str], None] | None = None) -> DriveSummary:
    """Drive a robot live with the scenario's controller until the reference ends or a signal stops it.

    Parameters
    ----------
    scenario : Scenario
        The scenario: its velocity-output controller, reference, control period and limits.
    options : DriveOptions
        Topics, clock, timeouts (the CLI's options).
    bag : Path
        The MCAP file written at the end with /odom in, /cmd_vel out and /reference, whatever ended the drive.
    log : callable, optional
        Where the live tracking error goes (a line at a time); stderr by default.

    Returns
    -------
    DriveSummary
        Commands sent, tracking errors, missed periods, jitter and how it ended.
    """
    say = log if log is not None else (lambda line: print(line, file=sys.stderr, flush=True))
    refuse_unfit_law(scenario, options.effort_topic, options.wheel_velocity_topic)
    with Stop() as stop, Participant(options.domain) as node:
        if options.path_topic is not None:
            scenario = _await_path(scenario, options, node, stop)
        if stop.signal is not None:
            return DriveSummary(ended=stop.signal)
        driver = Driver(scenario, options, node, say)
        try:
            say(f"waiting for {driver.source()} (domain {node.domain})")
            (driver.run_odom if options.clock == "odom" else driver.run_wall)(stop)
        finally:
            driver.halt()
            driver.summary.counts = write_bag(bag, driver.recorded) if driver.recorded else {}
    return driver.summary


def _await_path(scenario: Any, options: DriveOptions, node: Participant, stop: Stop) -> Any:
    """The scenario with the reference of the first Path received on ``options.path_topic``."""
    assert options.path_topic is not None, "called with a path topic"
    paths = node.subscriber(options.path_topic, PATH_TYPE, qos=DEFAULT_QOS)
    deadline = time.monotonic() + options.wait
    while stop.signal is None and time.monotonic() < deadline:
        if received := paths.wait(timeout=0.1):
            return path_scenario(scenario.model_dump(mode="json"), received[-1], options.path_topic, Path("."))
    if stop.signal is not None:
        return scenario
    raise ConfigError("--path-topic", f"no {PATH_TYPE} on '{options.path_topic}' within {options.wait:g} s", "")
