"""``ddtrack drive`` against ``ddtrack robot`` (docs/ros.md): a ddtrack controller drives a ddtrack plant over DDS,
each in its own process, on the loopback only, in lockstep; the run scores as the same scenario run offline, drive's
bag is a log ``identify`` fits, and the robot's run folder one ``export`` reads."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from dds_helpers import loopback_environment

ROOT = Path(__file__).resolve().parents[1]
FIGURE8 = ROOT / "scenarios" / "burger_cmd_vel_figure8.toml"
DURATION = 10.0  # [s] 200 periods at the scenario's 20 Hz: a quarter of the lap, both lobes' first turn
TIMING = ["--set", f"simulation.duration={DURATION}", "--set", f"simulation.metric_window=[0, {DURATION}]"]
TIMEOUT = 180  # [s] only stops a hung process

pytestmark = pytest.mark.slow


def test_drive_against_robot_tracks_as_the_offline_run(tmp_path):
    """In lockstep the controller sees the odometry of x_k and its command is held over period k, as in the
    simulator (a latency of no period), so the live run's mean tracking error is the offline run's: the issue asked
    for 10 %; the transport's rounding (poses through quaternions, stamps in nanoseconds) is all that differs, and
    they agree to 1e-6 (2e-14 measured), which this asserts."""
    env = loopback_environment(20 + (os.getpid() * 7 + 3) % 200)
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
    subprocess.run(
        [sys.executable, "-m", "ddtrack", "run", str(FIGURE8), *TIMING, "--out", str(offline)],
        check=True,
        capture_output=True,
        timeout=TIMEOUT,
    )
    measured = {
        name: json.loads((folder / "metrics.json").read_text())
        for name, folder in [("live", live), ("offline", offline)]
    }
    assert measured["live"]["status"] == measured["offline"]["status"] == "ok"
    live_error, offline_error = measured["live"]["e_tr_mean"], measured["offline"]["e_tr_mean"]
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
