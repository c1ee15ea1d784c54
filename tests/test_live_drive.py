"""``ddtrack drive`` live (docs/ros.md): the scenario's controller against a fake robot over DDS, on the loopback.

Each end runs in its own process: ``ddtrack drive`` and ``FAKE_ROBOT``, a unicycle written with plain Cyclone DDS
(its own types, named as ROS 2's middlewares name them, on ``rt/odom`` or ``rt/tf``, and ``rt/cmd_vel``; nothing
of ddtrack). Every participant talks on the loopback only (``dds_helpers.LOOPBACK``) and in a domain of its test's own.
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from dds_helpers import LOOPBACK, ROS2_TYPES, worker_domain

ROOT = Path(__file__).resolve().parents[1]
FIGURE8 = ROOT / "scenarios" / "burger_cmd_vel_figure8.toml"
PAPER_LINE = ROOT / "scenarios" / "paper_line.toml"
TIMEOUT = 30  # [s] a hung process is killed; each test takes well under this

pytest.importorskip("cyclonedds")
pytestmark = pytest.mark.slow  # each test starts ddtrack (JAX, a compiled controller): 7 to 15 s

# A user's plain node's ROS 2 types (ros2_types.py), then a unicycle that integrates the last twist it
# received. lockstep: publish /odom stamped t_k, wait for the next /cmd_vel, advance one period; periodic: publish
# /odom every period on its own timer, until `silent_after` seconds, and listen to /cmd_vel until `listen_for`.
FAKE_ROBOT = ROS2_TYPES + textwrap.dedent(
    """
    import json, math, os, sys, time
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.qos import Policy, Qos
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic
    from cyclonedds.util import duration

    config = json.loads(sys.argv[1])
    EFFORT = config.get("effort")  # wheel torques on a Float64MultiArray, in the joint order of EFFORT["joints"]
    WHEELS = config.get("wheels")  # wheel speeds [rad/s] likewise, turned by wheels of WHEELS' radius and half axle
    COMMAND = Float64MultiArray if EFFORT or WHEELS else TwistStamped if config.get("stamped") else Twist
    period, (x, y, theta) = config["period"], config["pose"]
    QOS = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.Volatile, Policy.History.KeepLast(10))
    participant = DomainParticipant(int(os.environ["ROS_DOMAIN_ID"]))
    POSES = ("rt/tf", TFMessage) if config.get("tf") else ("rt/odom", Odometry)  # the pose as a transform, or odometry
    odom = DataWriter(participant, Topic(participant, *POSES), qos=QOS)
    COMMANDS = "rt" + (EFFORT or WHEELS)["topic"] if EFFORT or WHEELS else "rt/cmd_vel"
    commands = DataReader(participant, Topic(participant, COMMANDS, COMMAND), qos=QOS)
    deadline = time.monotonic() + 20
    while not (odom.get_matched_subscriptions() and commands.get_matched_publications()):
        if time.monotonic() > deadline:
            sys.exit("no ddtrack drive matched")
        time.sleep(0.01)
    v = omega = 0.0
    received, published = [], []

    def publish(t):
        zero3 = Vector3(0.0, 0.0, 0.0)
        q = Quaternion(0.0, 0.0, math.sin(theta / 2), math.cos(theta / 2))
        sec = 1_700_000_000 + int(t)
        stamp = Time(sec, round((t - int(t)) * 1e9))
        body = Twist(Vector3(v, 0.0, 0.0), Vector3(0.0, 0.0, omega))
        if config.get("tf"):  # odom -> base_footprint, and a fixed joint drive must skip
            lidar = Transform(Vector3(-0.032, 0.0, 0.172), Quaternion(0.0, 0.0, 0.0, 1.0))
            odom.write(TFMessage([TransformStamped(Header(stamp, "odom"), "base_footprint",
                                                   Transform(Vector3(x, y, 0.0), q)),
                                  TransformStamped(Header(stamp, "base_footprint"), "base_scan", lidar)]))
            published.append(time.monotonic())
            return
        odom.write(Odometry(Header(stamp, "odom"), "base_footprint",
                            PoseWithCovariance(Pose(Point(x, y, 0.0), q), [0.0] * 36),
                            TwistWithCovariance(body, [0.0] * 36)))
        published.append(time.monotonic())

    def advance(dt):
        global x, y, theta, v, omega
        if EFFORT:  # a rigid body on its wheels: v' = (tau_r + tau_l) / (m r), omega' = L (tau_r - tau_l) / (I r)
            m, inertia, r, half = EFFORT["mass"], EFFORT["inertia"], EFFORT["radius"], EFFORT["half_axle"]
            for _ in range(10):
                h = dt / 10
                x, y, theta = x + h * v * math.cos(theta), y + h * v * math.sin(theta), theta + h * omega
                v, omega = v + h * (tau[0] + tau[1]) / (m * r), omega + h * half * (tau[0] - tau[1]) / (inertia * r)
            return
        for _ in range(10):  # the exact arc would do as well; ten Euler steps are within 1e-5 m here
            h = dt / 10
            x, y, theta = x + h * v * math.cos(theta), y + h * v * math.sin(theta), theta + h * omega

    tau = [0.0, 0.0]  # (tau_r, tau_l) [N m], effort mode

    def take():
        global v, omega
        got = [s for s in commands.take(N=100) if isinstance(s, COMMAND)]
        if EFFORT:
            for s in got:
                received.append([time.monotonic(), *s.data])
            if got:
                data = got[-1].data
                tau[:] = [data[EFFORT["joints"].index("right")], data[EFFORT["joints"].index("left")]]
            return got
        if WHEELS:  # the unicycle of these wheels: v = r (right + left) / 2, omega = r (right - left) / (2 L)
            for s in got:
                received.append([time.monotonic(), *s.data])
            if got:
                data, r, half = got[-1].data, WHEELS["radius"], WHEELS["half_axle"]
                right, left = data[WHEELS["joints"].index("right")], data[WHEELS["joints"].index("left")]
                v, omega = r * (right + left) / 2, r * (right - left) / (2 * half)
            return got
        got = [s.twist if config.get("stamped") else s for s in got]
        for s in got:
            received.append([time.monotonic(), s.linear.x, s.angular.z])
        if got:
            v, omega = got[-1].linear.x, got[-1].angular.z
        return got

    if config["mode"] == "lockstep":
        for k in range(config["steps"]):
            publish(k * period)
            wait = time.monotonic() + (15 if k == 0 else 3)
            while not take() and time.monotonic() < wait:
                time.sleep(0.0002)
            if time.monotonic() >= wait:
                break
            advance(period)
    else:
        start = time.monotonic()
        marker = config.get("marker")
        while time.monotonic() - start < config["listen_for"]:
            if time.monotonic() - start < config["silent_after"]:
                publish(time.monotonic() - start)
            tick = time.monotonic()
            while time.monotonic() < tick + period:
                take()
                time.sleep(0.002)
            advance(time.monotonic() - tick)
            if marker and len(received) >= 10:
                open(marker, "w").close()
            if config.get("until_quiet") and received and time.monotonic() - received[-1][0] > 1.5:
                break
    print(json.dumps({"pose": [x, y, theta], "received": received, "published": published}))
    """
)


def _domain(offset: int) -> int:
    """A domain of this test's own: parallel pytest workers and the tests of this file do not hear each other."""
    return worker_domain(20 + offset)  # 20 to 29: this file's


def _environment(domain: int) -> dict[str, str]:
    return dict(os.environ, CYCLONEDDS_URI=LOOPBACK, ROS_DOMAIN_ID=str(domain), PYTHONPATH=str(ROOT / "src"))


def _start(argv: list[str], domain: int) -> subprocess.Popen:
    return subprocess.Popen(
        argv, env=_environment(domain), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT
    )


def _robot(config: dict, domain: int) -> subprocess.Popen:
    return _start([sys.executable, "-c", FAKE_ROBOT, json.dumps(config)], domain)


def _drive(args: list[str], domain: int) -> subprocess.Popen:
    return _start([sys.executable, "-m", "ddtrack", "drive", *args], domain)


def _finish(*processes: subprocess.Popen) -> list[tuple[int, str, str]]:
    """Wait for every process (killing any still running after TIMEOUT); (exit code, stdout, stderr) of each."""
    done = []
    try:
        for process in processes:
            out, err = process.communicate(timeout=TIMEOUT)
            done.append((process.returncode, out, err))
    finally:
        for process in processes:
            process.kill()
    return done


def _bag_topics(bag: Path) -> dict[str, list]:
    """The bag's messages by topic, read by rosbags; and the same counts by mcap's own reader."""
    from mcap.reader import make_reader
    from rosbags.highlevel import AnyReader

    from ddtrack.ros.messages import typestore

    with AnyReader([bag], default_typestore=typestore()) as reader:
        by_topic: dict[str, list] = {}
        for connection, _, raw in reader.messages():
            by_topic.setdefault(connection.topic, []).append(reader.deserialize(raw, connection.msgtype))
    with bag.open("rb") as file:
        counts: dict[str, int] = {}
        for _, channel, _ in make_reader(file).iter_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
    assert counts == {topic: len(messages) for topic, messages in by_topic.items()}
    return by_topic


@pytest.mark.parametrize("pose_from", ["odom", "tf"])
def test_drive_in_lockstep_tracks_the_figure_eight(tmp_path, pose_from):
    """One lap of the figure eight (40 s at 20 Hz, 800 periods) in lockstep with an ideal unicycle; its pose read
    from /odom, or from the transform odom -> base_footprint on /tf (its twist then differenced by drive)."""
    from ddtrack.scenario import load_scenario

    duration, period, domain = 40.0, 0.05, _domain(1 if pose_from == "odom" else 6)
    reference = load_scenario(FIGURE8).trajectory.build()
    start = reference(0.0)
    steps = round(duration / period) + 1  # odometry at t_0 .. t_N: N commands, and the zero twist at the end
    robot = _robot(
        {"mode": "lockstep", "period": period, "steps": steps, "pose": [0.0, 0.0, float(start.theta)]}
        | {"tf": pose_from == "tf"},
        domain,
    )
    bag = tmp_path / "figure8.mcap"
    began = time.monotonic()
    drive = _drive(
        [
            str(FIGURE8),
            "--clock",
            "odom",
            "--pose-from",
            pose_from,
            "--set",
            f"simulation.duration={duration}",
            "--set",
            "simulation.metric_window=[0, 40]",
            "--bag",
            str(bag),
        ],
        domain,
    )
    (code, _, err), (robot_code, out, robot_err) = _finish(drive, robot)
    assert code == 0, err[-3000:]
    assert robot_code == 0, robot_err[-3000:]
    assert "stopped at the reference's end: 800 commands" in err and time.monotonic() - began < TIMEOUT
    seen = json.loads(out)
    assert len(seen["received"]) == steps and seen["received"][-1][1:] == [0.0, 0.0]  # and then a zero twist
    # An ideal unicycle under backstepping with the reference's feed-forward: what is left is the zero-order hold
    # of 50 ms on a path curving at most ~1/0.3 m^-1 at 0.13 m/s: 0.3 mm measured; 5 mm would be a real fault
    end = reference(duration)
    x, y, _ = seen["pose"]
    assert math.hypot(x - float(end.x), y - float(end.y)) < 0.005
    topics = _bag_topics(bag)
    poses = "/odom" if pose_from == "odom" else "/tf"  # drive records what it received
    assert sorted(topics) == sorted(["/cmd_vel", "/reference", poses])
    assert len(topics["/cmd_vel"]) == 801 and len(topics[poses]) == steps and len(topics["/reference"]) == 800


def test_a_path_received_on_path_topic_is_followed(tmp_path, monkeypatch):
    """A planner's Path (5 poses over 4 s, stamped) replaces the figure eight; the robot ends at its last pose."""
    from ddtrack.ros import dds
    from ddtrack.ros.messages import header, message, planar_pose

    domain, heading = _domain(5), math.atan2(0.05, 0.1)
    poses = [
        message(
            "geometry_msgs/msg/PoseStamped",
            header=header(n * 10**9, "map"),
            pose=planar_pose(0.1 * n, 0.05 * n, heading),
        )
        for n in range(5)
    ]
    robot = _robot({"mode": "lockstep", "period": 0.05, "steps": 81, "pose": [0.0, 0.0, heading]}, domain)
    drive = _drive(
        [str(FIGURE8), "--clock", "odom", "--path-topic", "/plan", "--bag", str(tmp_path / "p.mcap")], domain
    )
    monkeypatch.setenv("CYCLONEDDS_URI", LOOPBACK)
    with dds.Participant(domain=domain) as node:
        plans = node.publisher("/plan", "nav_msgs/msg/Path")
        assert plans.wait_for_subscriptions(timeout=20)
        plans.publish(message("nav_msgs/msg/Path", header=header(0, "map"), poses=poses))
        (code, _, err), (robot_code, out, robot_err) = _finish(drive, robot)
    assert code == 0 and robot_code == 0, (err + robot_err)[-3000:]
    assert "stopped at the reference's end: 80 commands" in err
    x, y, _ = json.loads(out)["pose"]
    assert math.hypot(x - 0.4, y - 0.2) < 0.005  # a straight segment at constant speed: tracked exactly


def test_stale_odometry_stops_the_robot_within_the_timeout(tmp_path):
    domain, timeout = _domain(2), 0.3
    robot = _robot(
        {"mode": "periodic", "period": 0.05, "pose": [0.0, 0.0, 0.785], "silent_after": 3.0, "listen_for": 6.0},
        domain,
    )
    drive = _drive(
        [
            str(FIGURE8),
            "--set",
            "simulation.duration=60",
            "--odom-timeout",
            str(timeout),
            "--bag",
            str(tmp_path / "b.mcap"),
        ],
        domain,
    )
    ((robot_code, out, robot_err),) = _finish(robot)
    drive.send_signal(signal.SIGTERM)
    ((code, _, err),) = _finish(drive)
    assert robot_code == 0, robot_err[-3000:]
    assert code == 143, err[-3000:]
    seen = json.loads(out)
    last_odom = seen["published"][-1]
    moving = [r for r in seen["received"] if r[0] < last_odom and (r[1] or r[2])]
    assert moving, "drive never commanded the robot while odometry came"
    zeros = [r[0] for r in seen["received"] if r[0] > last_odom and r[1:] == [0.0, 0.0]]
    # the first period after the odometry aged past the timeout: timeout + one period, and slack for a loaded
    # machine (pytest -n auto); 0.38 s measured on an idle one
    assert zeros and zeros[0] - last_odom < timeout + 0.05 + 0.25, zeros[:3]
    assert all(r[1:] == [0.0, 0.0] for r in seen["received"] if r[0] > zeros[0])  # and it stays stopped


def test_sigint_sends_a_zero_twist_and_leaves_a_readable_bag(tmp_path):
    """With --twist-stamped, as Jazzy's diff_drive_controller takes commands."""
    domain, marker, bag = _domain(3), tmp_path / "ten_commands", tmp_path / "interrupted.mcap"
    robot = _robot(
        {
            "mode": "periodic",
            "period": 0.05,
            "pose": [0.0, 0.0, 0.785],
            "silent_after": 25.0,
            "listen_for": 25.0,
            "marker": str(marker),
            "until_quiet": True,
            "stamped": True,
        },
        domain,
    )
    drive = _drive([str(FIGURE8), "--twist-stamped", "--bag", str(bag)], domain)
    deadline = time.monotonic() + 20
    while not marker.exists() and time.monotonic() < deadline and drive.poll() is None:
        time.sleep(0.05)
    assert marker.exists(), "the robot got no commands"
    drive.send_signal(signal.SIGINT)
    (code, stdout, err), (robot_code, out, robot_err) = _finish(drive, robot)
    assert code == 130, err[-3000:]
    assert "stopped at SIGINT" in err and "Traceback" not in err
    assert robot_code == 0, robot_err[-3000:]
    received = json.loads(out)["received"]
    assert received[-1][1:] == [0.0, 0.0] and any(r[1] for r in received)
    topics = _bag_topics(bag)
    assert topics["/cmd_vel"][-1].twist.linear.x == 0.0 and len(topics["/cmd_vel"]) >= 10 and len(topics["/odom"]) >= 5
    assert f"wrote {bag}" in stdout


def _one_line_error(args: list[str], domain: int, *, path=None) -> str:
    """Run drive with bad input; its stderr, checked to be one line, exit code 2, no traceback."""
    drive = _drive(args, domain)
    if path is not None:
        from ddtrack.ros import dds

        with dds.Participant(domain=domain) as node:
            plans = node.publisher("/plan", "nav_msgs/msg/Path")
            assert plans.wait_for_subscriptions(timeout=20)
            plans.publish(path)
            plans.flush(timeout=2)
            ((code, _, err),) = _finish(drive)
    else:
        ((code, _, err),) = _finish(drive)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err[-3000:]
    return err


def test_bad_input_is_one_line_and_exit_2(tmp_path, monkeypatch):
    from ddtrack.ros.messages import header, message, planar_pose

    domain = _domain(4)
    err = _one_line_error([str(PAPER_LINE), "--bag", str(tmp_path / "x.mcap")], domain)
    assert err.startswith("error: controller:") and "wheel torques" in err and "--effort-topic" in err
    err = _one_line_error(
        [str(FIGURE8), "--effort-topic", "/wheels/commands", "--bag", str(tmp_path / "x.mcap")], domain
    )
    assert err.startswith("error: --effort-topic:") and "not wheel torques" in err
    err = _one_line_error([str(PAPER_LINE), "--wheel-velocity-topic", "/w", "--bag", str(tmp_path / "x.mcap")], domain)
    assert err.startswith("error: --wheel-velocity-topic:") and "not speeds" in err and "--effort-topic" in err
    both = ["--effort-topic", "/e", "--wheel-velocity-topic", "/w", "--bag", str(tmp_path / "x.mcap")]
    err = _one_line_error([str(PAPER_LINE), *both], domain)
    assert err.startswith("error: --wheel-velocity-topic: cannot be combined with --effort-topic")
    err = _one_line_error(
        [str(PAPER_LINE), "--effort-topic", "/e", "--joints", "a,b", "--bag", str(tmp_path / "x.mcap")], domain
    )
    assert err.startswith("error: --joints:")
    err = _one_line_error([str(FIGURE8), "--odom-topic", "odom two", "--bag", str(tmp_path / "x.mcap")], domain)
    assert err.startswith("error: --odom-topic:")
    ((code, _, err),) = _finish(_drive([str(FIGURE8), "--clock", "sim"], domain))
    assert code == 2 and "Error: Invalid value for '--clock'" in err and "Traceback" not in err  # click's usage
    for wrong, what in (("geometry_msgs/msg/Twst", "not a ROS 2 message type"), ("std_msgs/msg/String", "not a twist")):
        err = _one_line_error([str(FIGURE8), "--cmd-vel-type", wrong, "--bag", str(tmp_path / "x.mcap")], domain)
        assert err.startswith(f"error: --cmd-vel-type: '{wrong}' is {what}") and "geometry_msgs/msg/TwistStamped" in err
    monkeypatch.setenv("CYCLONEDDS_URI", LOOPBACK)
    poses = [
        message("geometry_msgs/msg/PoseStamped", header=header(n * 10**9, "map"), pose=planar_pose(x, 0.0, 0.0))
        for n, x in enumerate([0.0, float("nan"), 1.0])
    ]
    path = message("nav_msgs/msg/Path", header=header(0, "map"), poses=poses)
    args = [str(FIGURE8), "--path-topic", "/plan", "--bag", str(tmp_path / "x.mcap")]
    err = _one_line_error(args, domain, path=path)
    assert err.startswith("error: --path-topic:") and "NaN" in err


def _in_lockstep(path: Path, duration: float, domain: int, fake: dict, args: list[str]) -> tuple[str, dict, int]:
    """``ddtrack drive PATH --clock odom ARGS`` for ``duration`` seconds against the fake robot taking ``fake``'s
    commands (effort or wheels), set at the reference's start; (drive's stderr, what the robot saw, its periods)."""
    from ddtrack.scenario import load_scenario

    scenario = load_scenario(path)
    period, start = float(scenario.simulation.control_period), scenario.trajectory.build()(0.0)
    steps = round(duration / period) + 1
    pose = [float(start.x), float(start.y), float(start.theta)]
    robot = _robot({"mode": "lockstep", "period": period, "steps": steps, "pose": pose} | fake, domain)
    sets = ["--set", f"simulation.duration={duration}", "--set", f"simulation.metric_window=[0, {duration}]"]
    drive = _drive([str(path), "--clock", "odom", *args, *sets], domain)
    (code, _, err), (robot_code, out, robot_err) = _finish(drive, robot)
    assert code == 0, err[-3000:]
    assert robot_code == 0, robot_err[-3000:]
    return err, json.loads(out), steps


def test_effort_topic_drives_a_torque_law_in_lockstep(tmp_path):
    """paper_line's backstepping over computed torque, its wheel torques on a Float64MultiArray to a rigid-body
    robot of the scenario's nominal mass, inertia, wheel radius and half axle; joints given right first (the order)."""
    from ddtrack.scenario import load_scenario

    scenario, duration = load_scenario(PAPER_LINE), 3.0
    robot_params = scenario.robot
    effort = {"topic": "/wheels/commands", "joints": ["right", "left"]} | {
        "mass": robot_params.mass,
        "inertia": robot_params.inertia,
        "radius": robot_params.wheel_radius,
        "half_axle": robot_params.half_axle,
    }
    bag = tmp_path / "line.mcap"
    args = ["--effort-topic", "/wheels/commands", "--joints", "right_wheel,left_wheel", "--bag", str(bag)]
    err, seen, steps = _in_lockstep(PAPER_LINE, duration, _domain(7), {"effort": effort}, args)
    reference = scenario.trajectory.build()
    assert f"stopped at the reference's end: {steps - 1} commands" in err
    assert len(seen["received"]) == steps and seen["received"][-1][1:] == [0.0, 0.0]  # then zero torques
    limit = float(scenario.robot.max_torque)
    assert all(abs(tau) <= limit for r in seen["received"] for tau in r[1:])
    end = reference(duration)
    x, y, _ = seen["pose"]
    error = math.hypot(x - float(end.x), y - float(end.y))
    # Starting at rest while the line moves at 0.5 m/s, the law closes the gap within a second; what is left at 3 s
    # is the 10 ms zero-order hold and the law's nominal centre of mass 5 cm ahead (this robot has it on the axle):
    # 2.4 mm measured; 1 cm would be a real fault (swapped wheels or torques of the wrong sign diverge at once)
    assert error < 0.01
    topics = _bag_topics(bag)
    assert sorted(topics) == ["/odom", "/reference", "/wheels/commands"]  # and no /cmd_vel
    assert len(topics["/wheels/commands"]) == steps and list(topics["/wheels/commands"][-1].data) == [0.0, 0.0]


def test_wheel_velocity_topic_drives_a_velocity_law_in_lockstep(tmp_path):
    """The figure eight's kinematic backstepping, its (v, omega) as wheel speeds on a Float64MultiArray to a robot
    that turns its wheels at them: the scenario's true wheels (radius 0.033 m where the law believes 0.03333 m),
    joints given left first (a TurtleBot's order, where the effort test gives right first)."""
    from ddtrack.scenario import load_scenario

    scenario, duration = load_scenario(FIGURE8), 5.0
    true, believed = scenario.plant_params(), scenario.robot
    wheels = {"topic": "/wheels/commands", "joints": ["left", "right"]}
    wheels |= {"radius": true.wheel_radius, "half_axle": true.half_axle}
    out = tmp_path / "eight"
    args = ["--wheel-velocity-topic", "/wheels/commands", "--joints", "left_wheel,right_wheel", "--out", str(out)]
    _, seen, steps = _in_lockstep(FIGURE8, duration, _domain(8), {"wheels": wheels}, args)
    reference = scenario.trajectory.build()
    assert len(seen["received"]) == steps and seen["received"][-1][1:] == [0.0, 0.0]  # then the wheels stop
    end = reference(duration)
    x, y, _ = seen["pose"]
    # 0.65 mm measured after 5 s (the 1 % wheel radius error is what feedback corrects); a robot that takes the
    # joints in the other order ends 18.6 mm off
    assert math.hypot(x - float(end.x), y - float(end.y)) < 0.005
    # each array is W nu of the command the run folder records, on the wheels the law believes (left first)
    columns = pq.read_table(out / "timeseries.parquet").to_pydict()
    radius, half = float(believed.wheel_radius), float(believed.half_axle)
    assert len(columns["v_cmd"]) == steps - 1  # every command but the final stop, which the robot received last
    for (_, left, right), v, omega in zip(seen["received"], columns["v_cmd"], columns["omega_cmd"], strict=False):
        assert right == pytest.approx((v + half * omega) / radius, rel=1e-12, abs=1e-12)
        assert left == pytest.approx((v - half * omega) / radius, rel=1e-12, abs=1e-12)
    topics = _bag_topics(out / "drive.mcap")
    assert sorted(topics) == ["/odom", "/reference", "/wheels/commands"]  # and no /cmd_vel


def test_wheel_speeds_keep_the_curvature_within_the_wheels_limit():
    """Two wheels too fast are slowed by one factor (omega / v kept) to the limit; slow ones pass unchanged."""
    from ddtrack.model import RobotParams
    from ddtrack.ros.joint_groups import wheel_speeds, within_wheel_limit

    nominal = RobotParams(wheel_radius=0.033, half_axle=0.08)
    v, omega = within_wheel_limit(0.5, 2.0, nominal, limit=6.0)
    assert omega / v == pytest.approx(2.0 / 0.5) and max(map(abs, wheel_speeds(v, omega, nominal))) == pytest.approx(
        6.0
    )
    assert within_wheel_limit(0.1, 0.5, nominal, limit=6.0) == (0.1, 0.5)
    assert within_wheel_limit(5.0, 0.0, nominal, limit=None) == (5.0, 0.0)
