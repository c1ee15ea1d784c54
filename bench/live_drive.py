"""``ddtrack drive``'s wall-clock loop: how evenly it ticks at 20 Hz and 100 Hz (docs/benchmarks.md).

Each rate runs ``ddtrack drive --clock wall --dry-run`` on the TurtleBot3 figure eight for about 5 s, with
``simulation.control_period`` overridden, fed by a plain odometry publisher in this process at 50 Hz (the rate of
a TurtleBot3's /odom); the loop's own summary gives the missed periods and the jitter, |actual - nominal| period
(median and 99th percentile, in ms). DDS stays on the loopback, in a domain of this run's own.

Usage::

    PYTHONPATH=src python bench/live_drive.py [--seconds 5]
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "scenarios" / "burger_cmd_vel_figure8.toml"
LOOPBACK = (
    '<CycloneDDS><Domain><General><Interfaces><NetworkInterface name="lo"/></Interfaces>'
    "<AllowMulticast>false</AllowMulticast></General>"
    '<Discovery><Peers><Peer address="127.0.0.1"/></Peers><ParticipantIndex>auto</ParticipantIndex></Discovery>'
    "</Domain></CycloneDDS>"
)
SUMMARY = re.compile(r"missed periods (\d+); jitter median ([\d.]+) ms, 99th percentile ([\d.]+) ms")


def publish_odometry(domain: int, stop: threading.Event, rate: float = 50.0) -> None:
    """Odometry of a robot standing at the reference's start, at ``rate`` Hz, until ``stop``."""
    from ddtrack.ros.dds import Participant
    from ddtrack.ros.messages import header, message, no_covariance, planar_pose, twist

    with Participant(domain) as node:
        odom = node.publisher("/odom", "nav_msgs/msg/Odometry")
        while not stop.is_set():
            now = time.time_ns()
            pose = message(
                "geometry_msgs/msg/PoseWithCovariance", pose=planar_pose(0, 0, 0.785), covariance=no_covariance()
            )
            speed = message("geometry_msgs/msg/TwistWithCovariance", twist=twist(0, 0), covariance=no_covariance())
            odom.publish(
                message(
                    "nav_msgs/msg/Odometry",
                    header=header(now, "odom"),
                    child_frame_id="base_footprint",
                    pose=pose,
                    twist=speed,
                )
            )
            time.sleep(1.0 / rate)


def measure(period: float, seconds: float, domain: int) -> tuple[int, int, float, float]:
    """(periods, missed, median jitter [ms], 99th percentile [ms]) of one dry-run drive at ``period`` s."""
    stop = threading.Event()
    feeder = threading.Thread(target=publish_odometry, args=(domain, stop), daemon=True)
    feeder.start()
    env = dict(os.environ, CYCLONEDDS_URI=LOOPBACK, ROS_DOMAIN_ID=str(domain))
    with tempfile.TemporaryDirectory() as scratch:
        overrides = [f"simulation.control_period={period}", f"simulation.duration={seconds}"]
        overrides += [f"simulation.metric_window=[0, {seconds}]"]
        argv = [sys.executable, "-m", "ddtrack", "drive", str(SCENARIO), "--clock", "wall", "--dry-run"]
        argv += [arg for o in overrides for arg in ("--set", o)] + ["--bag", f"{scratch}/drive.mcap"]
        done = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=120)
    stop.set()
    feeder.join()
    found = SUMMARY.search(done.stderr)
    if done.returncode != 0 or found is None:
        sys.exit(f"ddtrack drive failed ({done.returncode}):\n{done.stderr[-2000:]}")
    missed, median, p99 = int(found[1]), float(found[2]), float(found[3])
    return round(seconds / period), missed, median, p99


def main() -> None:
    """Measure both rates and print a Markdown table for docs/benchmarks.md."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0)
    args = parser.parse_args()
    domain = 20 + os.getpid() % 200
    os.environ["CYCLONEDDS_URI"] = LOOPBACK  # this process's odometry publisher too
    print("| rate | periods | missed | jitter median [ms] | jitter 99th percentile [ms] |")
    print("|---|---|---|---|---|")
    for hz in (20, 100):
        periods, missed, median, p99 = measure(1.0 / hz, args.seconds, domain)
        print(f"| {hz} Hz | {periods} | {missed} | {median:.3f} | {p99:.3f} |", flush=True)


if __name__ == "__main__":
    main()
