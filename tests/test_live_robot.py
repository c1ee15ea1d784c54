"""``ddtrack robot`` (docs/ros.md): a scenario's plant as a ROS 2 robot, driven over DDS by a node that is not
ddtrack's (plain Cyclone DDS with ROS 2's type names, standing for a user's ROS 2 node), in lockstep.

Each test starts its processes on the loopback only, in a DDS domain of its own.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from dds_helpers import ROS2_TYPES, loopback_environment, worker_domain

ROOT = Path(__file__).resolve().parents[1]
FIGURE8 = ROOT / "scenarios" / "burger_cmd_vel_figure8.toml"
SHORT = ["--set", "simulation.duration=1.5", "--set", "simulation.metric_window=[0.0,1.5]"]
PERIOD = 0.05  # [s] the scenario's control period
PROCESS_TIMEOUT = 120  # [s] only stops a hung process
# a planner's path (t [s], x, y [m], yaw [rad]): a straight line away from the figure eight's start at (0, 0)
PATH = [(0.1 * k, 0.2 + 0.01 * k, 0.1 + 0.005 * k, float(np.arctan2(0.005, 0.01))) for k in range(16)]

# A user's ROS 2 node as plain Cyclone DDS: ROS 2's IDL types (ros2_types.py) and topic names, nothing of ddtrack.
# It answers each /clock with one /cmd_vel (constant, or varying with the count of clocks), and prints the clocks and
# odometry it got.
# Patterns "path" and "nanpath" first publish a nav_msgs/Path on /plan, latched (reliable, transient local), as a
# planner does: PATH's poses, or the same with a NaN; "nanpath" then holds it until the test stops the node (the robot
# may match, take the path, refuse it and leave between two looks at the writer's matches: a node cannot tell).
DRIVER = ROS2_TYPES + textwrap.dedent(
    """
    import json, math, os, sys, time
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.qos import Policy, Qos
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic
    from cyclonedds.util import duration

    pattern, v, omega = sys.argv[1], float(sys.argv[2]), float(sys.argv[3])
    qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.Volatile, Policy.History.KeepLast(10))
    participant = DomainParticipant(int(os.environ["ROS_DOMAIN_ID"]))
    if pattern.endswith("path"):
        latched = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.TransientLocal,
                      Policy.History.KeepLast(1))
        plan = DataWriter(participant, Topic(participant, "rt/plan", Path), qos=latched)
        poses = []
        for t, x, y, yaw in json.loads(os.environ["DDTRACK_TEST_PATH"]):
            if pattern == "nanpath" and len(poses) == 3:
                x = float("nan")
            at = Time(int(t), round((t % 1) * 1e9))
            q = Quaternion(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
            poses.append(PoseStamped(Header(at, "odom"), Pose(Point(x, y, 0.0), q)))
        plan.write(Path(Header(Time(0, 0), "odom"), poses))
        if pattern == "nanpath":  # keeps the latched path until the test stops it, once the robot refused it and left
            time.sleep(90)
            sys.exit(1)
    clocks = DataReader(participant, Topic(participant, "rt/clock", Clock), qos=qos)
    odometry = DataReader(participant, Topic(participant, "rt/odom", Odometry), qos=qos)
    stamped = pattern.endswith("stamped")
    commands = DataWriter(participant, Topic(participant, "rt/cmd_vel", TwistStamped if stamped else Twist), qos=qos)
    got, odom, answered = [], [], 0
    last = time.monotonic() + 90  # the robot starts (JAX, the plant's program) before its first clock
    while time.monotonic() < last:
        for sample in odometry.take(N=100):
            if isinstance(sample, Odometry):
                q = sample.pose.pose.orientation
                yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
                stamp = sample.header.stamp.sec * 10**9 + sample.header.stamp.nanosec
                odom.append([stamp, sample.pose.pose.position.x, sample.pose.pose.position.y, yaw,
                             sample.twist.twist.linear.x, sample.twist.twist.angular.z, sample.pose.covariance[0]])
        new = [s for s in clocks.take(N=100) if isinstance(s, Clock)]
        if not new:
            time.sleep(0.0005)
            continue
        while answered == 0 and not commands.get_matched_subscriptions():  # before the first answer only
            time.sleep(0.005)
        for sample in new:
            got.append(sample.clock.sec * 10**9 + sample.clock.nanosec)
            k = len(got) - 1
            if pattern.startswith("quit") and k == 10:  # a driver that stops answering
                print(json.dumps({"clocks": got[:-1], "odom": odom, "answered": answered}))
                sys.exit(0)
            if pattern == "varying":
                speed, turn = v * (1 + 0.5 * math.sin(k / 3)), omega * math.cos(k / 5)
            else:
                speed, turn = v, omega
            twist = Twist(Vector3(speed, 0.0, 0.0), Vector3(0.0, 0.0, turn))
            stamp = Time(got[-1] // 10**9, got[-1] % 10**9)
            commands.write(TwistStamped(Header(stamp, "base_link"), twist) if stamped else twist)
            answered += 1
        last = time.monotonic() + 3  # the robot is done when its clock stops
    print(json.dumps({"clocks": got, "odom": odom, "answered": answered}))
    """
)


def _domain(offset: int) -> int:
    """A DDS domain of this test's own (test processes run in parallel)."""
    return worker_domain(offset)  # 1 to 12: this file's


def _drive(tmp_path: Path, name: str, offset: int, pattern: str = "constant", *options: str, code: int = 0):
    """Run ``ddtrack robot --mode lockstep`` and the driver node; (robot's stdout, driver's output, run folder)."""
    env = loopback_environment(_domain(offset)) | {"DDTRACK_TEST_PATH": json.dumps(PATH)}
    out = tmp_path / name
    robot_cmd = [sys.executable, "-m", "ddtrack", "robot", str(FIGURE8), "--mode", "lockstep", *SHORT, *options]
    robot_cmd += ["--out", str(out)]
    v, omega = 0.15, 0.4
    started = [
        subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        for cmd in (robot_cmd, [sys.executable, "-c", DRIVER, pattern, str(v), str(omega)])
    ]
    try:
        robot_out, robot_err = started[0].communicate(timeout=PROCESS_TIMEOUT)
        if pattern == "nanpath":  # the robot refused the path and left: nothing more to hear
            assert started[0].returncode == code, robot_err[-3000:]
            return robot_out + robot_err, None, out
        driver_out, driver_err = started[1].communicate(timeout=PROCESS_TIMEOUT)
    finally:
        for process in started:
            process.kill()
    assert started[0].returncode == code, robot_err[-3000:]
    assert started[1].returncode == 0, driver_err[-3000:]
    return robot_out + robot_err, json.loads(driver_out.splitlines()[-1]), out


def test_a_plain_ros_2_node_drives_the_robot_in_lockstep(tmp_path):
    summary, driven, folder = _drive(tmp_path, "run", 1)
    periods = 30  # 1.5 s at 20 Hz
    clocks = np.array(driven["clocks"])
    # one /clock per period and the end's, t_N (which the robot publishes and no longer waits on)
    assert len(clocks) == periods + 1 and driven["answered"] == periods + 1
    assert np.all(np.diff(clocks) == round(PERIOD * 1e9)) and clocks[0] == 0  # sim time from 0, one period apart
    odom = np.array(driven["odom"])
    assert len(odom) == periods + 1 and np.array_equal(odom[:, 0], clocks)  # x_0 .. x_N's odometry, stamped t_k
    x, y, yaw, v, omega = odom[:, 1:6].T
    # the Burger starts at (0, 0) heading 45 degrees: driven forward and turning left, x and y grow, yaw rises
    assert x[-1] > 0.05 and y[-1] > 0.0 and np.all(np.diff(x[5:]) > 0)
    assert np.all(np.diff(yaw[5:]) > 0) and yaw[-1] - yaw[0] > 0.2
    assert 0.1 < v[-1] < 0.2 and 0.3 < omega[-1] < 0.5  # the PI wheel loop reached the command
    assert odom[-1, 6] > 0.0  # the odometry estimate's covariance grows as it drives
    metrics = json.loads((folder / "metrics.json").read_text())
    assert metrics["status"] == "ok" and metrics["e_tr_mean"] > 0
    table = pq.read_table(folder / "timeseries.parquet")
    assert table.num_rows == periods and table.column("v_cmd").to_pylist()[-1] == pytest.approx(0.15)
    assert (folder / "ddtrack.json").is_file() and "lockstep, 30 periods" in summary
    # the report names what drove the plant, not the scenario's own controller, which did not run
    from ddtrack.report.render import render

    page = render(folder)
    assert "whatever published /cmd_vel (ddtrack robot, lockstep mode); the run ended done after 30 periods" in page
    assert "ddtrack robot/lockstep on figure_eight" in page and "kinematic_backstepping on" not in page


def test_a_path_on_a_topic_is_the_reference(tmp_path):
    _, driven, folder = _drive(tmp_path, "path", 6, "path", "--path-topic", "/plan")
    periods = 30  # the path's 1.5 s at 20 Hz
    assert len(driven["clocks"]) == periods + 1
    odom = np.array(driven["odom"])
    assert abs(odom[0, 1]) < 1e-9 and abs(odom[0, 2]) < 1e-9  # the start pose stays the scenario's (0, 0)
    table = pq.read_table(folder / "timeseries.parquet")
    t, x_ref, y_ref = (table.column(name).to_numpy() for name in ("t", "x_ref", "y_ref"))
    assert table.num_rows == periods and x_ref[0] == pytest.approx(0.2) and y_ref[0] == pytest.approx(0.1)
    knots = np.array([pose[:3] for pose in PATH[:15]])  # every other period is one of the path's poses
    assert np.allclose(np.column_stack([t, x_ref, y_ref])[::2], knots, rtol=0, atol=1e-9)
    metrics = json.loads((folder / "metrics.json").read_text())
    assert metrics["status"] == "ok" and metrics["e_tr_mean"] > 0.15  # scored against the path, 0.22 m away at t=0


def test_a_nan_path_and_no_path_are_refused(tmp_path):
    said, _, folder = _drive(tmp_path, "nan", 7, "nanpath", "--path-topic", "/plan", code=2)
    assert "Traceback" not in said and not folder.exists()
    assert said.strip().splitlines()[-1].startswith("error: --path-topic: the path on '/plan' has a NaN")
    done = _ddtrack(str(FIGURE8), "--mode", "fast", "--path-topic", "/none", "--timeout", "1", "--out", str(folder))
    assert done.returncode == 2 and "Traceback" not in done.stderr and not folder.exists()
    assert done.stderr.strip().splitlines()[-1] == "error: --path-topic: no nav_msgs/msg/Path on '/none' within 1 s"


def test_lockstep_is_deterministic(tmp_path):
    tables = []
    for i in range(2):
        _, driven, folder = _drive(tmp_path, f"run{i}", 2 + i, pattern="varying")
        assert len(driven["clocks"]) == 31  # t_0 .. t_30
        tables.append(pq.read_table(folder / "timeseries.parquet"))
    first, second = tables
    assert first.column_names == second.column_names
    for name in first.column_names:
        a, b = (np.asarray(t.column(name).to_numpy(zero_copy_only=False)) for t in tables)
        assert a.tobytes() == b.tobytes(), name


def test_a_silent_driver_ends_the_run_and_sigterm_stops_it(tmp_path):
    stamped = ("--twist-stamped", "--start", "1700000000.5")  # a TwistStamped driver, stamps from a given start
    said, driven, folder = _drive(tmp_path, "silent", 4, "quit-stamped", "--timeout", "1", *stamped, code=1)
    clocks = np.array(driven["clocks"])
    assert len(clocks) == 10 and "the driver stopped answering" in said
    assert clocks[0] == 1_700_000_000_500_000_000 and np.all(np.diff(clocks) == round(PERIOD * 1e9))
    table = pq.read_table(folder / "timeseries.parquet")
    assert table.num_rows == 10 and table.column("v_cmd").to_pylist()[-1] == pytest.approx(0.15)  # what was driven
    assert json.loads((folder / "metrics.json").read_text())["status"] == "ok"
    # realtime with nobody driving: zero velocity held; SIGTERM stops it, and the folder is still written
    out = tmp_path / "stopped"
    command = [sys.executable, "-m", "ddtrack", "robot", str(FIGURE8), "--mode", "realtime", "--out", str(out)]
    env = loopback_environment(_domain(5))
    process = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert process.stderr is not None and "robot on DDS domain" in process.stderr.readline()
        time.sleep(1.0)
        process.send_signal(signal.SIGTERM)
        said, _ = process.communicate(timeout=PROCESS_TIMEOUT)
    finally:
        process.kill()
    assert process.returncode == 0 and "stopped" in said
    rows = pq.read_table(out / "timeseries.parquet").num_rows
    assert 10 <= rows <= 40, rows  # about 1 s at 20 Hz
    assert np.all(pq.read_table(out / "timeseries.parquet").column("v_cmd").to_numpy() == 0.0)


def test_fast_mode_runs_the_duration_undriven(tmp_path):
    done = _ddtrack(str(FIGURE8), "--mode", "fast", *SHORT, "--out", str(tmp_path / "fast"))
    assert done.returncode == 0 and "fast, 30 periods (1.5 s), done" in done.stdout, done.stderr
    table = pq.read_table(tmp_path / "fast" / "timeseries.parquet")
    assert table.num_rows == 30 and not any(table.column("v_cmd").to_pylist())  # zero before any command


def _ddtrack(*args: str) -> subprocess.CompletedProcess:
    env = loopback_environment(_domain(9))
    command = [sys.executable, "-m", "ddtrack", "robot", *args]
    return subprocess.run(command, env=env, capture_output=True, text=True, timeout=PROCESS_TIMEOUT)


def test_a_torque_plant_and_an_unknown_mode_are_refused(tmp_path):
    done = _ddtrack(str(ROOT / "scenarios" / "paper_line.toml"), "--mode", "fast", "--out", str(tmp_path / "r"))
    assert done.returncode == 2 and "Traceback" not in done.stderr
    line, hint = done.stderr.strip().splitlines()  # ConfigError's line and its fix
    assert line.startswith("error: plant.model: 'dynamic' takes torque") and "velocity-input" in hint
    done = _ddtrack(str(FIGURE8), "--mode", "warp", "--out", str(tmp_path / "r"))
    assert done.returncode == 2 and "--mode" in done.stderr and "lockstep" in done.stderr
    assert not (tmp_path / "r").exists()
