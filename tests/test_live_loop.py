"""``ddtrack drive`` against ``ddtrack robot`` (docs/ros.md): a ddtrack controller drives a ddtrack plant over DDS,
each in its own process, on the loopback only. In lockstep the run scores as the same scenario run offline, drive's
bag is a log ``identify`` fits, and the robot's run folder one ``export`` reads; on the wall clock it scores as the
scenario run offline with the latency measured from what the two recorded, within 10 %."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from dds_helpers import loopback_environment, worker_domain

from ddtrack.ros.drive import TICK_PHASE

ROOT = Path(__file__).resolve().parents[1]
FIGURE8 = ROOT / "scenarios" / "burger_cmd_vel_figure8.toml"
DURATION = 10.0  # [s] 200 periods at the scenario's 20 Hz: a quarter of the lap, both lobes' first turn
TIMING = ["--set", f"simulation.duration={DURATION}", "--set", f"simulation.metric_window=[0, {DURATION}]"]
TIMEOUT = 180  # [s] only stops a hung process
PERIOD = 0.05  # [s] the scenario's control period
DELAY = 0.05  # [s] its sensing.actuation_delay: the robot's plant applies it too, after /cmd_vel

pytestmark = pytest.mark.slow


def test_drive_against_robot_tracks_as_the_offline_run(tmp_path):
    """In lockstep the controller sees the odometry of x_k and its command is held over period k, as in the
    simulator (a latency of no period), so the live run's mean tracking error is the offline run's: the issue asked
    for 10 %; the transport's rounding (poses through quaternions, stamps in nanoseconds) is all that differs, and
    they agree to 1e-6 (2e-14 measured), which this asserts."""
    env = loopback_environment(worker_domain(40))
    live, offline = tmp_path / "live", tmp_path / "offline"
    commands = [
        [sys.executable, "-m", "ddtrack", "robot", str(FIGURE8), "--mode", "lockstep", *TIMING, "--out", str(live)],
        [
            sys.executable,
            "-m",
            "ddtrack",
            "drive",
            str(FIGURE8),
            "--clock",
            "odom",
            *TIMING,
            "--out",
            str(tmp_path / "drive"),
        ],
    ]
    started = [
        subprocess.Popen(c, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for c in commands
    ]
    try:
        outputs = [process.communicate(timeout=TIMEOUT) for process in started]
    finally:
        for process in started:
            process.kill()
    for process, (_, err) in zip(started, outputs, strict=True):
        assert process.returncode == 0, err[-3000:]
    live_error, offline_error = _mean_errors(live, offline)
    assert abs(live_error - offline_error) <= 1e-6 * offline_error, (live_error, offline_error)

    # what drive recorded is a log identify fits (commands and odometry on one clock), and the robot's run folder
    # is a run as the other commands read it
    def ddtrack(*args: str) -> str:
        done = subprocess.run([sys.executable, "-m", "ddtrack", *args], capture_output=True, text=True, timeout=TIMEOUT)
        assert done.returncode == 0, done.stderr[-3000:]
        return done.stdout + done.stderr

    fitted = ddtrack("identify", str(tmp_path / "drive" / "drive.mcap"))
    assert 'model = "lag"' in fitted and "fit on the held-out last quarter" in fitted
    assert "wrote" in ddtrack("export", str(live), "--to", str(tmp_path / "live.mcap"))
    assert (tmp_path / "live.mcap").stat().st_size > 0
    # and drive's own run folder: the odometry it received scored against the reference, which export reads too
    driven = json.loads((tmp_path / "drive" / "metrics.json").read_text())
    assert driven["warnings"][0]["code"] == "measured_pose" and driven["e_tr_mean"] > 0
    assert "wrote" in ddtrack("export", str(tmp_path / "drive"), "--to", str(tmp_path / "drive.csv"))


def test_drive_against_robot_in_realtime_tracks_as_the_offline_run_with_the_measured_latency(tmp_path):
    """On the wall clock, each side keeping its own period, a command reaches the plant later than in the simulator
    (where the command from x_k acts over period k): the robot holds the latest /cmd_vel received when its period
    starts. This measures that latency from what the two processes recorded, runs the scenario offline with it
    added to the actuation delay, and compares the mean tracking errors.

    Drive's ticks fall half a period after the odometry's arrivals (``TICK_PHASE``), so its tick k has x_k and its
    command reaches the robot before period k + 1: one period from x_k to the plant, every period (199 of 199 in
    each of three runs, one beside a busy loop), and the live mean e_tr equals the offline run's with one period more
    of actuation delay to 12 digits (4.4240969704 mm both). The issue asked for 10 %, which this asserts: a late
    tick now and then on a loaded machine changes the latency of a period, which the measured mean carries. Before
    the half-period phase, ticks in phase with the odometry raced it (0 to 3 periods, live 4 % to 24 % below the
    offline run), and a reference a period behind the robot's clock scored +71 %."""
    env = loopback_environment(worker_domain(41))
    live, offline, driven = tmp_path / "live", tmp_path / "offline", tmp_path / "drive"
    ddtrack = [sys.executable, "-m", "ddtrack"]
    pipes = {"env": env, "stdout": subprocess.PIPE, "stderr": subprocess.PIPE, "text": True}
    # drive first: it compiles, then starts its period timer at the first odometry, which must be the robot's x_0;
    # the robot waits for no one in realtime, so a drive still compiling would start at a later period, its reference
    # behind the robot's, which scores against its own t_k = k T (94 ms behind: 7.6 mm measured, 4.4 offline)
    drive = subprocess.Popen([*ddtrack, "drive", str(FIGURE8), *TIMING, "--out", str(driven)], **pipes)
    try:
        waiting = ""
        while "waiting for" not in waiting and drive.poll() is None:
            waiting = drive.stderr.readline()
        robot = subprocess.Popen(
            [*ddtrack, "robot", str(FIGURE8), "--mode", "realtime", *TIMING, "--out", str(live)], **pipes
        )
        try:
            outputs = [process.communicate(timeout=TIMEOUT) for process in (robot, drive)]
        finally:
            robot.kill()
    finally:
        drive.kill()
    for process, (_, err) in zip((robot, drive), outputs, strict=True):
        assert process.returncode == 0, err[-3000:]
    late, to_answer, to_send = _latencies(driven, live, PERIOD)
    # drive's t = 0 is the robot's t_0 but for one publication and its delivery, and its first tick half a period on
    assert 0.0 < late - TICK_PHASE * PERIOD < PERIOD / 2, late
    # one period (drive's tick k answers x_k, the robot holds it from period k + 1); two where a loaded machine
    # delayed a tick past the robot's next period, none where it delayed the robot's take; more is a broken clock
    assert np.all((to_answer >= 0) & (to_answer <= 3)), _counts(to_answer)
    latency = float(np.mean(to_answer)) * PERIOD
    delay = round(DELAY + latency, 4)  # any delay is allowed: a fraction of a period splits it between two commands
    live_error, offline_error = _mean_errors(live, offline, "--set", f"sensing.actuation_delay={delay}")
    figures = (
        f"t = 0 {1e3 * late:.1f} ms after x_0; periods from x_j to the plant {_counts(to_answer)}, from drive's "
        f"tick {_counts(to_send)}; latency {latency:.4f} s; e_tr mean live {live_error:.12g}, "
        f"offline {offline_error:.12g}"
    )
    print(figures)
    assert abs(live_error - offline_error) <= 0.10 * offline_error, figures


def _mean_errors(live: Path, offline: Path, *options: str) -> tuple[float, float]:
    """The live run's mean e_tr and that of the scenario run offline (with ``options``) into ``offline``; both ok."""
    command = [sys.executable, "-m", "ddtrack", "run", str(FIGURE8), *TIMING, *options, "--out", str(offline)]
    subprocess.run(command, check=True, capture_output=True, timeout=TIMEOUT)
    measured = [json.loads((folder / "metrics.json").read_text()) for folder in (live, offline)]
    assert [m["status"] for m in measured] == ["ok", "ok"]
    return measured[0]["e_tr_mean"], measured[1]["e_tr_mean"]


def _counts(periods: np.ndarray) -> dict[int, int]:
    """How many times each number of periods occurs (drive's tick can come after the robot's period: -1)."""
    return {int(value): int(count) for value, count in zip(*np.unique(periods, return_counts=True), strict=True)}


def _wrapped(angle: np.ndarray) -> np.ndarray:
    """Angles [rad] in [-pi, pi): drive's run folder unwraps its headings, the bag's quaternions do not."""
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


def _latencies(drive: Path, live: Path, period: float) -> tuple[float, np.ndarray, np.ndarray]:
    """What the two processes recorded, on one machine's wall clock: (how long after the stamp of x_0 drive's t = 0
    came [s]; for each robot period k from the first command on, k - j, with x_j the odometry its command answered;
    and k - i, with i drive's tick that sent it).

    Drive's bag has the odometry it received with the robot's stamps (t_0 + j T: the wall clock in realtime) and
    each command at its nominal wall time t = 0 + i T; drive's run folder the pose each command answered; the
    robot's run folder the odometry it published and the command it held over each period."""
    from ddtrack.ros.messages import quaternion_yaw, stamp_nanoseconds
    from ddtrack.ros.reading import open_bag, topic_messages

    with open_bag(drive / "drive.mcap") as reader:
        odometry = [m for _, m in topic_messages(reader, "/odom", ("nav_msgs/msg/Odometry",), option="/odom")]
        start = topic_messages(reader, "/cmd_vel", ("geometry_msgs/msg/Twist",), option="/cmd_vel")[0][0]
    stamps = np.array([stamp_nanoseconds(m.header) for m in odometry])
    poses = np.array(
        [(m.pose.pose.position.x, m.pose.pose.position.y, quaternion_yaw(m.pose.pose.orientation)) for m in odometry]
    )
    sent = pq.read_table(drive / "timeseries.parquet").to_pydict()
    held = pq.read_table(live / "timeseries.parquet").to_pydict()
    # the first odometry drive received is the robot's x_0: else drive's t = 0 would be a later period's
    assert np.allclose(poses[0], [held[f"odom_{c}"][0] for c in ("x", "y", "theta")], rtol=0.0, atol=1e-12)
    step = round(period * 1e9)
    assert np.all((stamps - stamps[0]) % step == 0), "the robot stamps x_j with t_0 + j T"
    answered = []  # j of each command: the odometry whose pose it answered, exactly as received
    for x, y, theta in zip(sent["x"], sent["y"], sent["theta"], strict=True):
        same = np.flatnonzero((poses[:, 0] == x) & (poses[:, 1] == y) & (np.abs(_wrapped(poses[:, 2] - theta)) < 1e-9))
        assert same.size, f"no odometry received at ({x}, {y}, {theta})"
        answered.append((stamps[same[0]] - stamps[0]) // step)
    # which command the robot held over each period: drive's, in the order sent (zero until the first arrives)
    values = list(zip(sent["v_cmd"], sent["omega_cmd"], strict=True))
    to_answer, to_send, i = [], [], 0
    for k, u in enumerate(zip(held["v_cmd"], held["omega_cmd"], strict=True)):
        if not to_answer and u == (0.0, 0.0):
            continue
        i = values.index(u, i)  # ValueError: the robot held a command drive did not compute
        to_answer.append(k - answered[i])
        to_send.append(k - i)
    return (start - stamps[0]) / 1e9, np.array(to_answer), np.array(to_send)
