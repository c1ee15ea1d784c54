"""How steadily ``ddtrack robot --mode realtime`` keeps its period (docs/benchmarks.md, "Live loops").

    python bench/live_robot.py [--seconds 5] [--json]

Runs ``ddtrack robot scenarios/burger_cmd_vel_figure8.toml --mode realtime`` at 20 Hz and at 100 Hz (the scenario's
``simulation.control_period`` overridden to 0.05 and 0.01 s) for about ``--seconds`` each, driven by a simple
publisher (ddtrack's own ``Participant``) that sends a constant ``/cmd_vel`` at the same rate and times the
arrival of each ``/clock``. It reports, per rate, the periods received, the period jitter (median and 99th
percentile of |actual - nominal| between consecutive ``/clock`` arrivals, in ms), the late arrivals (gaps over 1.5
nominal periods; the robot catches up after one, so none is lost), the missed periods (the robot's own count of
periods it fell more than a whole period behind, after which it keeps time from then on), and the stretch (the
arrivals' span over the nominal one: how far the run fell behind the wall clock). Everything stays on the
loopback (the tests' Cyclone DDS configuration), in a domain of its own.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from dds_helpers import loopback_environment

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "scenarios" / "burger_cmd_vel_figure8.toml"
RATES = (20, 100)  # [Hz]


def measure(rate: int, seconds: float, domain: int, folder: Path) -> dict:
    """One realtime run at ``rate`` Hz, driven and timed from another process; its period figures."""
    from ddtrack.ros import Participant
    from ddtrack.ros.messages import twist

    period = 1.0 / rate
    overrides = [f"simulation.control_period={period}", f"simulation.duration={seconds}"]
    overrides.append(f"simulation.metric_window=[0.0,{seconds}]")
    command = [sys.executable, "-m", "ddtrack", "robot", str(SCENARIO), "--mode", "realtime", "--overwrite"]
    command += [item for override in overrides for item in ("--set", override)] + ["--out", str(folder)]
    env = loopback_environment(domain)
    os.environ.update(CYCLONEDDS_URI=env["CYCLONEDDS_URI"], ROS_DOMAIN_ID=str(domain))
    robot = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    arrivals: list[float] = []
    with Participant(domain) as node:
        commands = node.publisher("/cmd_vel", "geometry_msgs/msg/Twist")
        clock = node.subscriber("/clock", "rosgraph_msgs/msg/Clock")
        deadline = time.monotonic() + seconds + 120  # the robot starts (JAX, its compiled period) first
        while robot.poll() is None and time.monotonic() < deadline:
            received = clock.wait(timeout=0.5)
            now = time.monotonic()
            arrivals += [now] * len(received)
            if received:
                commands.publish(twist(0.15, 0.4))
    out, err = robot.communicate(timeout=60)
    if robot.returncode != 0:
        raise SystemExit(f"ddtrack robot failed ({robot.returncode}): {err[-2000:]}")
    gaps = np.diff(np.asarray(arrivals))
    deviation = np.abs(gaps - period) * 1e3
    late = int(np.sum(gaps > 1.5 * period))
    missed = int(out.split(" periods late")[0].rsplit(" ", 1)[-1]) if " periods late" in out else None
    return {
        "rate_hz": rate,
        "periods": len(arrivals),
        "jitter_median_ms": float(np.median(deviation)),
        "jitter_p99_ms": float(np.percentile(deviation, 99)),
        "late_arrivals": late,
        "missed": missed,
        "stretch": float((arrivals[-1] - arrivals[0]) / (period * (len(arrivals) - 1))),
        "summary": out.strip(),
    }


def main() -> None:
    """Measure each rate and print a table (or JSON)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    import ddtrack

    ddtrack.enable_float64()
    scratch = Path(os.environ.get("TMPDIR", "/tmp")) / f"ddtrack_live_bench_{os.getpid()}"
    results = [
        measure(rate, args.seconds, (os.getpid() + i) % 200 + 20, scratch / f"{rate}hz") for i, rate in enumerate(RATES)
    ]
    if args.json:
        print(json.dumps(results, indent=2))
        return
    print("rate [Hz]  periods  jitter median [ms]  jitter p99 [ms]  late arrivals  missed  stretch")
    for r in results:
        print(
            f"{r['rate_hz']:>9}  {r['periods']:>7}  {r['jitter_median_ms']:>18.3f}  {r['jitter_p99_ms']:>15.3f}"
            f"  {r['late_arrivals']:>13}  {r['missed']!s:>6}  {r['stretch']:>7.4f}"
        )


if __name__ == "__main__":
    main()
