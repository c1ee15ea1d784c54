"""``ddtrack robot``: a scenario's plant as a ROS 2 robot, driven over DDS by whatever publishes ``/cmd_vel``.

Each control period k (t_k = k T_c after the start stamp) the robot publishes ``/clock`` (t_k), then ``/odom``,
``/tf`` (odom -> base_link) and ``/joint_states`` stamped t_k, all from the plant's state x_k: the odometry model's
estimate where the scenario has ``[sensing] odometry`` (with its covariances, as ``ddtrack export`` writes them),
else the true pose. Then it holds a velocity command over the period and advances the plant one period, as
``ddtrack run``'s simulator does (:func:`ddtrack.sim.plant_period`): motors, grip, latency and encoders included.
Which command it holds is the mode's (docs/ros.md): the latest received (``realtime``, ``fast``) or the first
received after the publication (``lockstep``, deterministic). After the last period it publishes the final state
x_N too (a driver then sees the reference's end). The run is scored like ``ddtrack run``'s: the
reference against the true pose, into a run folder; the reference is the scenario's, or with a path topic the first
``nav_msgs/msg/Path`` received on it, re-timed as ``ddtrack import`` does.
"""

from __future__ import annotations

import dataclasses
import signal
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, cast

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from ..errors import ConfigError, RunError
from ..runner import closed_loop, prepare, run_record
from ..scenario import Scenario
from ..sim import ClosedLoop, HeldInput, SimResult, measured, period_record
from .covariance import CovariancePropagation, _ros_six
from .dds import DEFAULT_QOS, TF_STATIC_QOS, Participant, Subscriber
from .export import CLOCK, ODOMETRY, TF, Frames, _odometry, _transform, viewer_of, wheel_signals
from .messages import NANOSECONDS, WHEEL_JOINTS, header, message, planar_pose, stamp

MODES = ("realtime", "fast", "lockstep")
TWIST, TWIST_STAMPED = "geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped"
JOINTS = "sensor_msgs/msg/JointState"
#: [s] the longest a wait on DDS blocks before looking for a stop signal (Ctrl-C, SIGTERM)
POLL = 0.1
#: [s] lockstep waits this long once matched: a reader that has not yet discovered the robot's writer drops what
#: it sends (volatile), and period 0's /clock would go unanswered
SETTLE = 0.5
#: [s] how long the robot stays after publishing its final state, so that a best-effort reader receives it
LINGER = 0.2


@dataclass
class LiveRun:
    """What a live run simulated: its rows as ``ddtrack run`` records them, and how it ended.

    Attributes
    ----------
    columns : dict
        ``timeseries.parquet``'s columns (:func:`ddtrack.runner.run_record`).
    metrics : dict
        ``metrics.json`` (:func:`ddtrack.runner.run_metrics`).
    periods : int
        Control periods simulated.
    ended : str
        ``"done"`` (the scenario's duration), ``"stopped"`` (a signal), ``"silent"`` (lockstep: the driver stopped
        answering) or ``"failed"`` (the run diverged or went non-finite).
    late : int
        Realtime periods that started later than one period after their deadline.
    scenario : Scenario or None
        The scenario run, when it is not the one given (a path topic's reference replaced its trajectory): the run
        folder must describe what was scored.
    """

    columns: dict
    metrics: dict
    periods: int
    ended: str
    late: int = 0
    scenario: Scenario | None = None


@dataclass
class _Record:
    """The per-period records, as :func:`ddtrack.sim.simulate` stacks them."""

    rows: list[tuple[Any, ...]] = field(default_factory=list)
    status: int = 0
    failure_index: int = -1


def require_velocity_plant(scenario: Scenario, plant: Any) -> None:
    """Refuse a plant that does not take velocity commands: a ``/cmd_vel`` cannot drive wheel torques.

    Parameters
    ----------
    scenario : Scenario
        The scenario, whose ``plant.model`` the refusal names.
    plant : Plant
        Its built plant (``input_kind`` ``"velocity"`` or ``"torque"``).

    Raises
    ------
    ConfigError
        For a plant whose input is not velocity.
    """
    if plant.input_kind != "velocity":
        raise ConfigError(
            "plant.model",
            f"'{scenario.plant.model}' takes {plant.input_kind} inputs, and /cmd_vel carries velocities",
            'give a velocity-input plant, e.g. model = "motor_velocity", "slip_velocity" or "unicycle"',
        )


def _period(loop: ClosedLoop, x: Any, u: Any, k: Any, xi_disturbance: Any, xi_noise: Any) -> tuple[Any, ...]:
    """One period of ``loop`` holding ``u``: :meth:`ClosedLoop.period` with ``u`` in place of the controller's, and
    what :func:`ddtrack.sim.simulate` records of it."""
    held = dataclasses.replace(loop, controller=HeldInput(u))
    x_next, _, status, (body, ref, error, u, logs) = held.period(x, (), jnp.asarray(0), k, xi_disturbance, xi_noise)
    return x_next, status, (body, ref, error, u, *period_record(loop.plant, x, u, logs))


class Robot:
    """The scenario's plant stepped period by period under external commands, recorded as ``ddtrack run`` records.

    Parameters
    ----------
    scenario : Scenario
        A validated scenario whose plant takes velocity commands.

    Raises
    ------
    ConfigError
        For a plant that takes torques (naming ``plant.model``).
    """

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        self.setup, self.draws = prepare(scenario)
        self.loop = closed_loop(scenario, self.setup)
        require_velocity_plant(scenario, self.loop.plant)
        self.period = float(scenario.simulation.control_period)
        self.n_steps = scenario.simulation.n_steps
        self.x = self.loop.plant.init(jnp.asarray(self.setup.x0, dtype=float))
        self.k = 0
        self.record = _Record()
        self._step = jax.jit(_period)
        self._odometry = jax.jit(lambda loop, x, xi: loop.noise.measure(measured(loop.plant, x), xi))
        robot = scenario.plant_params()
        self.geometry = {"half_axle": robot.half_axle, "wheel_radius": robot.wheel_radius}
        self.covariance = CovariancePropagation.of(scenario)
        self._angles = np.zeros(2)
        self._last: dict[str, float] | None = None
        # compiled now, not in period 0: a realtime robot would start seconds late
        jax.block_until_ready(self._step(self.loop, self.x, jnp.zeros(2), 0, *self._draw(0)))
        self.sensed()
        self.wheels()  # its first call compiles JAX's eager operations (0.4 s): period 0 would publish that late
        self._angles, self._last = np.zeros(2), None

    def _draw(self, k: int) -> tuple[Any, Any]:
        """Period k's standard-normal disturbance and noise draws."""
        return self.draws.disturbance[k], self.draws.noise[k]

    def sensed(self) -> np.ndarray:
        """x_k's BODY vector as the odometry reports it (the true one without ``[sensing] odometry``)."""
        k = min(self.k, self.n_steps - 1)  # the final state x_N is read with the last period's draw
        return np.asarray(self._odometry(self.loop, self.x, self.draws.noise[k]))

    def wheels(self) -> dict[str, float]:
        """x_k's wheel angles [rad] and speeds [rad/s] (:func:`ddtrack.ros.export.wheel_signals`, period by period)."""
        body = np.asarray(self.loop.plant.observe(self.x))
        row = {"t": self.k * self.period, "v": body[3], "omega": body[4]}
        names = self.loop.plant.state_layout.names
        row |= {n: self.x[names.index(n)] for n in ("phi_r", "phi_l", "phidot_r", "phidot_l") if n in names}
        last = self._last or row
        columns = {name: np.array([float(last[name]), float(row[name])]) for name in row}
        signals = wheel_signals(columns, **self.geometry)
        for i, side in enumerate("rl"):  # recorded angles as they are, else the speeds integrated
            step = signals[f"angle_{side}"][1]
            self._angles[i] = step if f"phi_{side}" in row else self._angles[i] + step
        self._last = {name: float(value) for name, value in row.items()}
        return {
            "angle_r": self._angles[0],
            "angle_l": self._angles[1],
            "speed_r": float(signals["speed_r"][1]),
            "speed_l": float(signals["speed_l"][1]),
        }

    def advance(self, v: float, omega: float) -> bool:
        """Hold (v [m/s], omega [rad/s]) over period k and advance the plant; whether the run goes on."""
        x_next, status, row = self._step(self.loop, self.x, jnp.array([v, omega]), self.k, *self._draw(self.k))
        self.record.rows.append(row)
        if int(status) != 0:
            self.record.status, self.record.failure_index = int(status), self.k
        self.x, self.k = x_next, self.k + 1
        return not self.finished

    @property
    def finished(self) -> bool:
        """Whether the run is over: the scenario's duration simulated, or a failed period (the state then frozen)."""
        return self.record.status != 0 or self.k >= self.n_steps

    def result(self) -> tuple[dict, dict]:
        """(columns, metrics) of the periods simulated, as :func:`ddtrack.runner.run_record` makes them."""
        if not self.record.rows:
            raise RunError("no control period was simulated: the driver never sent a /cmd_vel")
        stacked = jax.tree_util.tree_map(lambda *leaves: np.stack([np.asarray(v) for v in leaves]), *self.record.rows)
        body, ref, error, u, logs, extra = stacked
        n = len(self.record.rows)
        status, failure = (cast(Array, np.asarray(v)) for v in (self.record.status, self.record.failure_index))
        t = cast(Array, np.arange(n) * self.period)
        result = SimResult(t, body, ref, error, u, logs, status, failure, extra)
        return run_record(self.scenario, self.setup, result)


@dataclass(frozen=True)
class Options:
    """How a live run talks and keeps time (``ddtrack robot``'s options).

    Attributes
    ----------
    mode : str
        ``realtime``, ``fast`` or ``lockstep`` (:data:`MODES`).
    timeout : float
        Lockstep: how long [s] to wait for each period's ``/cmd_vel``.
    start : int or None
        The stamp of t = 0 [ns since the epoch]; None: 0, or in realtime the wall clock as period 0 starts.
    twist_stamped : bool
        Take ``/cmd_vel`` as TwistStamped.
    domain : int or None
        The DDS domain (None: ``ROS_DOMAIN_ID``, else 0).
    frames : Frames
        The world and body frames (``odom``, ``base_link``).
    path_topic : str or None
        A ``nav_msgs/msg/Path`` topic whose first message, awaited up to ``timeout`` before the first period,
        replaces the scenario's reference (None: the scenario's).
    """

    mode: str = "lockstep"
    timeout: float = 5.0
    start: int | None = None
    twist_stamped: bool = False
    domain: int | None = None
    frames: Frames = field(default_factory=Frames)
    path_topic: str | None = None


@contextmanager
def _stop_on_signals(stop: list[bool]) -> Iterator[None]:
    """Ctrl-C and SIGTERM set ``stop[0]`` (the loop ends after its period) instead of killing the process."""
    handler = lambda signum, frame: stop.__setitem__(0, True)  # noqa: E731
    previous = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


def _first_command(commands: Subscriber, timeout: float, stop: list[bool]) -> Any | None:
    """The first command received within ``timeout`` seconds (None: none came, or a stop signal)."""
    deadline = time.monotonic() + timeout
    while not stop[0] and (left := deadline - time.monotonic()) > 0:
        if received := commands.wait(min(POLL, left)):
            return received[0]
    return None


def _velocity(command: Any, stamped: bool) -> tuple[float, float]:
    """(v, omega) of a Twist or TwistStamped."""
    twist = command.twist if stamped else command
    return float(twist.linear.x), float(twist.angular.z)


def run_robot(scenario: Scenario, options: Options, *, on_ready: Callable[[str], None] = lambda line: None) -> LiveRun:
    """Run ``scenario``'s plant as a ROS 2 robot until its duration, a stop signal or (lockstep) a silent driver.

    Parameters
    ----------
    scenario : Scenario
        A validated scenario whose plant takes velocity commands.
    options : Options
        The mode, the lockstep timeout, the start stamp, the command type, the DDS domain and the path topic.
    on_ready : callable
        Called with a line once the robot is on the network (before the first period).

    Returns
    -------
    LiveRun
        The run's columns and metrics and how it ended.
    """
    frames = options.frames
    stamped = options.twist_stamped
    given = scenario
    stop = [False]
    with Participant(options.domain) as node, _stop_on_signals(stop):
        if options.path_topic is not None:  # before the robot is built: the path sets its duration
            scenario = _await_path(scenario, node, options.path_topic, options.timeout, stop)
        robot = Robot(scenario)
        clock = node.publisher("/clock", CLOCK)
        odometry = node.publisher("/odom", ODOMETRY)
        transforms = node.publisher("/tf", TF)
        joints = node.publisher("/joint_states", JOINTS)
        static = node.publisher("/tf_static", TF, qos=TF_STATIC_QOS)
        commands = node.subscriber("/cmd_vel", TWIST_STAMPED if stamped else TWIST, qos=DEFAULT_QOS)
        viewer = viewer_of(scenario, {}, frames)
        origin = options.start
        if origin is None and options.mode != "realtime":
            origin = 0
        fixed_stamp = time.time_ns() if origin is None else origin
        fixed = [_transform(fixed_stamp, frames.base, f.child, (f.x, f.y, f.z)) for f in viewer.fixed]
        static.publish(message(TF, transforms=fixed))
        if options.mode == "lockstep":  # a driver that is not matched yet would miss period 0
            deadline = time.monotonic() + max(options.timeout, 10.0)
            while not stop[0] and time.monotonic() < deadline:
                if commands.publishers() and (clock.subscriptions() or odometry.subscriptions()):
                    break
                time.sleep(0.01)
            time.sleep(SETTLE)  # the driver's side discovers the robot's writers too
        on_ready(f"robot on DDS domain {node.domain}: /cmd_vel in; /clock, /odom, /tf, /joint_states out")
        ended, late = _loop(robot, options, origin, stop, clock, odometry, transforms, joints, commands)
    columns, metrics = robot.result()
    if robot.record.status != 0:
        ended = "failed"
    return LiveRun(columns, metrics, len(robot.record.rows), ended, late, None if scenario is given else scenario)


def _await_path(scenario: Scenario, node: Participant, topic: str, timeout: float, stop: list[bool]) -> Scenario:
    """``scenario`` scored against the first ``nav_msgs/msg/Path`` received on ``topic`` within ``timeout`` [s].

    Two subscriptions, both reliable: a transient-local one (:data:`TF_STATIC_QOS`, keep last 1) receives a
    planner's latched path, published before the robot started; a volatile one (:data:`DEFAULT_QOS`) matches a
    volatile publisher too, which a transient-local subscription does not (DDS refuses a writer offering less
    durability than the reader requests). The path is re-timed as ``ddtrack import`` re-times it; the start pose
    stays the scenario's (its ``[initial] pose``, else its own reference's pose at t = 0), as a robot's would.
    """
    from pathlib import Path

    from ..scenario.files import validate_scenario
    from .references import PATH_TYPE, path_scenario_data, reference_from_path_message

    readers = [node.subscriber(topic, PATH_TYPE, qos=qos) for qos in (TF_STATIC_QOS, DEFAULT_QOS)]
    deadline = time.monotonic() + timeout
    while not stop[0] and time.monotonic() < deadline:
        for reader in readers:
            if received := reader.wait(POLL / len(readers)):
                reference = reference_from_path_message(received[0], topic)
                data = path_scenario_data(scenario.model_dump(mode="json"), reference)
                pose = scenario.initial.pose
                if pose is None:
                    ref0 = scenario.trajectory.build()(0.0)
                    pose = (float(ref0.x), float(ref0.y), float(ref0.theta))
                data["initial"] = dict(data.get("initial") or {}, pose=[float(value) for value in pose])
                return validate_scenario(data, base_dir=Path("."))
    if stop[0]:
        raise RunError(f"stopped while waiting for a {PATH_TYPE} on '{topic}'")
    raise ConfigError("--path-topic", f"no {PATH_TYPE} on '{topic}' within {timeout:g} s", "")


def _loop(robot: Robot, options: Options, origin: int | None, stop: list[bool], *topics: Any) -> tuple[str, int]:
    """The periods of a live run: publish x_k, take the mode's command, advance; (how it ended, late periods).
    ``origin`` None (realtime without ``--start``): t_0 is the wall clock as period 0 starts."""
    clock, odometry, transforms, joints, commands = topics
    frames, stamped, mode = options.frames, options.twist_stamped, options.mode
    v = omega = 0.0  # realtime and fast: zero until the first command
    wall = time.monotonic()
    if origin is None:  # now, not before the setup: creating the publishers alone takes a few hundred ms
        origin = time.time_ns()
    late = 0
    step_ns = round(robot.period * NANOSECONDS)
    while True:
        if stop[0]:
            return "stopped", late
        s = origin + robot.k * step_ns
        sensed = robot.sensed()
        pose_k = planar_pose(*sensed[:3])
        covariances: dict[str, np.ndarray] = {}
        if robot.covariance is not None:
            planar = robot.covariance.step(*(float(value) for value in sensed[2:]))
            covariances = {
                "pose_covariance": _ros_six(planar[None])[0],
                "twist_covariance": _ros_six(robot.covariance.twist[None])[0],
            }
        wheels = robot.wheels()
        if mode == "lockstep":
            commands.take()  # what came before this publication is not the answer to it
        clock.publish(message(CLOCK, clock=stamp(s)))
        odometry.publish(_odometry(s, pose_k, sensed[3], sensed[4], frames.odom, frames.base, **covariances))
        moved = _transform(s, frames.odom, frames.base, (sensed[0], sensed[1], 0.0), sensed[2])
        transforms.publish(message(TF, transforms=[moved]))
        joints.publish(
            message(
                JOINTS,
                header=header(s, frames.base),
                name=list(WHEEL_JOINTS),
                position=np.array([wheels["angle_r"], wheels["angle_l"]]),
                velocity=np.array([wheels["speed_r"], wheels["speed_l"]]),
                effort=np.zeros(0),
            )
        )
        if robot.finished:  # x_N published too, so a driver sees the reference's end: delivered before we leave
            for publisher in (clock, odometry):
                publisher.flush(timeout=1.0)  # reliable subscriptions acknowledge it
            time.sleep(LINGER)  # a best-effort one (drive's) has no acknowledgement to wait for
            return "done", late
        if mode == "lockstep":
            command = _first_command(commands, options.timeout, stop)
            if command is None:
                return ("stopped" if stop[0] else "silent"), late
            v, omega = _velocity(command, stamped)
        elif received := commands.take():
            v, omega = _velocity(received[-1], stamped)
        robot.advance(v, omega)
        if mode == "realtime":
            wall += robot.period
            left = wall - time.monotonic()
            if left > 0:
                time.sleep(left)
            elif -left > robot.period:  # more than a period behind: count it, and keep time from now
                late += 1
                wall = time.monotonic()


__all__ = ["MODES", "LiveRun", "Options", "Robot", "require_velocity_plant", "run_robot"]
