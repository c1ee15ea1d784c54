"""From a robot's log to tuned gains and back: excite, record, identify, tune, compare, export.

The "real" robot is a TurtleBot3 Burger the rest of the script does not see: 30 % heavier than its preset (a
payload), on a floor of grip 0.6, its servos' PI wheel loop behind 50 ms of latency, its wheels free to slip
(``plant.model = "slip_velocity"``). The script, as a user would with a real one:

1. ``ddtrack excite``: a plan of timed cmd_vel within the Burger's top speeds;
2. drives it on the real robot, open loop (``[controller] kind = "replay"``), and ``ddtrack export`` records the run
   as a bag of /cmd_vel and /odom;
3. ``ddtrack identify``: the lag model and command delay of the recorded base;
4. ``ddtrack tune``: backstepping's gains over cmd_vel, tuned on the identified model (a figure eight);
5. ``ddtrack bench --scenario default.toml --scenario tuned.toml``: the default and the tuned gains track that figure
   eight on the real robot, over the same seeds, and the leaderboard pairs them by seed;
6. ``ddtrack export``: the tuned run as a bag for Foxglove.

    python examples/identify_and_tune.py [--out DIR] [--seeds N] [--steps N]
"""

import argparse
import json
import tempfile
import tomllib
from pathlib import Path

from ddtrack.cli import main

RUNS = ("default", "tuned")


def ddtrack(*words: object) -> None:
    """Run a ddtrack command as the shell would; stop the script if it fails."""
    code = main([str(word) for word in words])
    if code != 0:
        raise SystemExit(f"ddtrack {' '.join(map(str, words))} exited {code}")


# the real robot: what the rest of the script never reads
REAL = """[robot]
preset = "turtlebot3_burger"
[plant]
model = "slip_velocity"
mass = 1.3
floor_friction = 0.6
[sensing]
actuation_delay = 0.05
"""
FIGURE_EIGHT = """[trajectory]
kind = "figure_eight"
size = 0.5
period = 40.0
"""
TRACKING = """[simulation]
duration = 40.0
control_period = 0.05
substeps = 50
metric_window = [10.0, 40.0]
[randomize]
mass = { distribution = "uniform", relative = 0.1 }
"""


def identify_and_tune(out: Path, seeds: int, steps: int) -> None:
    """Steps 1 to 6, every file into ``out``; then what they found."""
    # 1. the plan, and 2. the real robot driven by it, recorded
    ddtrack("excite", "--preset", "turtlebot3_burger", "--duration", 60, "--out", out / "plan.csv", "--overwrite")
    (out / "real_excite.toml").write_text(
        'name = "real_excite"\n[simulation]\nduration = 60.0\ncontrol_period = 0.05\nsubsteps = 50\n'
        + REAL
        + '[trajectory]\nkind = "line"\nspeed = 0.05\n[controller]\nkind = "replay"\nfile = "plan.csv"\n'
    )
    ddtrack("run", out / "real_excite.toml", "--out", out / "excite_run", "--overwrite")
    ddtrack("export", out / "excite_run", "--to", out / "log.mcap", "--overwrite")

    # 3. identify the recorded base
    ddtrack("identify", out / "log.mcap", "--out", out / "identified.toml", "--overwrite")
    identified = (out / "identified.toml").read_text()

    # 4. tune backstepping over cmd_vel on the identified model
    (out / "model.toml").write_text(
        'name = "identified_burger"\n'
        + TRACKING
        + '[robot]\npreset = "turtlebot3_burger"\n'
        + identified
        + FIGURE_EIGHT
        + '[controller]\nkind = "backstepping"\ninner = "none"\n'
    )
    ddtrack("tune", out / "model.toml", "--seeds", 1, "--steps", steps, "--out", out / "tune", "--overwrite")
    tuned = json.loads((out / "tune" / "tune.json").read_text())["gains"]

    # 5. default and tuned gains on the real robot: a file each, differing only in [controller], benched on common seeds
    controller = '[controller]\nkind = "backstepping"\ninner = "none"\n'
    track = 'name = "real_track"\n' + TRACKING + REAL + FIGURE_EIGHT + controller
    (out / "default.toml").write_text(track)
    (out / "tuned.toml").write_text(track + f"gains = [{', '.join(map(repr, tuned))}]\n")
    bench = [word for name in RUNS for word in ("--scenario", out / f"{name}.toml")]
    ddtrack("bench", *bench, "--seeds", seeds, "--out", out / "bench", "--overwrite")

    # 6. the tuned run, for Foxglove
    ddtrack("run", out / "tuned.toml", "--out", out / "tuned_run", "--overwrite")
    ddtrack("export", out / "tuned_run", "--to", out / "tuned_run.mcap", "--overwrite")

    fragment = tomllib.loads(identified)
    lag, delay = fragment["plant"]["lag"], fragment.get("sensing", {}).get("actuation_delay", 0.0)
    board = {e["entry"]: e for e in json.loads((out / "bench" / "leaderboard.json").read_text())["leaderboard"]}
    better = board["tuned"]["improvement"]  # paired by seed: both entries meet the same mass draws
    print()
    lags = f"lags {lag[0] / lag[3]:.3g} s (v) and {lag[1] / lag[5]:.3g} s (omega)"
    print(f"identified: {lags}, command delay {delay:.3g} s")
    print(f"tuned on the identified model: gains {', '.join(f'{g:.4g}' for g in tuned)}")
    for name in RUNS:
        summary = board[name]["e_tr_mean"]
        print(
            f"{name} gains on the real robot, {seeds} seeds: mean e_tr {summary['mean']:.3g} "
            f"[{summary['ci_low']:.3g}, {summary['ci_high']:.3g}] m"
        )
    print(
        f"tuned over default: {better['mean']:.3g} [{better['ci_low']:.3g}, "
        f"{better['ci_high']:.3g}] % lower (paired over seeds)"
    )
    print(f"every file is in {out}")


if __name__ == "__main__":  # the bench's Dask workers import this file: only the script itself runs the steps
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=None, help="folder for every file [default: a temporary folder]")
    parser.add_argument("--seeds", type=int, default=5, help="seeds of the comparison on the real robot")
    parser.add_argument("--steps", type=int, default=30, help="gradient steps of the tuning")
    args = parser.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="ddtrack-identify-"))
    out.mkdir(parents=True, exist_ok=True)
    identify_and_tune(out, args.seeds, args.steps)
