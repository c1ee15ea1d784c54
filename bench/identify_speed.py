"""How long does ``ddtrack identify`` take on a 60 s log at 200 Hz? (docs/identification.md, "How long a fit takes")

For each model (lag, body, motor) a 60 s synthetic log at 200 Hz of a known robot is fitted twice, each time with
new noise: the first fit compiles (cold), the second reuses the compiled programs (warm, what a second log in the
same session costs). Printed: wall and CPU seconds of each fit (CPU counts every core the fit kept busy).

    python bench/identify_speed.py [--json] [--model motor]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ddtrack import enable_float64
from ddtrack.model.lag import PIONEER_3DX_WITH_LASER
from ddtrack.model.motors import DCMotor
from ddtrack.model.params import RobotParams
from ddtrack.sysid import (
    body_log,
    excitation_plan,
    identify_body,
    identify_lag,
    identify_motor,
    lag_log,
    motor_log,
    reversing_steps,
    torque_plan,
)

RATE, DURATION = 200.0, 60.0
#: a torque-driven body (M_v, m d, M_w, b_w, tau_c), tests/test_identify.py's
BODY_WHEELS = (0.05, 0.25)
BODY = np.array([12.0 + 2 * 0.002 / 0.05**2, 12.0 * 0.08, 0.7 + 12.0 * 0.08**2 + 2 * 0.002 * 0.25**2 / 0.05**2,
                 0.005, 0.05])  # fmt: skip
#: a TurtleBot3-sized voltage-driven robot, as tests/test_identify_motor.py's (its drive's time constant is 13 ms)
MOTOR = DCMotor(resistance=8.5, torque_constant=1.2, back_emf=1.6, efficiency=0.9, supply_voltage=11.1,
                current_limit=1.3)  # fmt: skip
ROBOT = RobotParams(mass=1.3, inertia=0.012, com_offset=-0.03, wheel_radius=0.033, half_axle=0.08,
                    viscous_friction=0.002, coulomb_friction=0.01, wheel_inertia=0.00202)  # fmt: skip


def fits():
    """name -> a function of the seed that builds a log and fits it, returning the fit's seconds (wall, CPU)."""
    plan = excitation_plan(max_speed=1.2, max_yaw_rate=5.24, duration=DURATION, rate=RATE, seed=0)
    t, torque = torque_plan(max_torque=1.5, duration=DURATION, rate=RATE, seed=0)
    volts = reversing_steps(amplitude=6.0, duration=DURATION, rate=RATE, seed=0)

    def timed(fit, log):
        wall, cpu = time.perf_counter(), time.process_time()
        fit(log)
        return time.perf_counter() - wall, time.process_time() - cpu

    radius, half = BODY_WHEELS
    return {
        "lag": lambda seed: timed(
            identify_lag, lag_log(np.array(PIONEER_3DX_WITH_LASER), plan, noise=(0.005, 0.01), delay=0.1, seed=seed)
        ),
        "body": lambda seed: timed(
            lambda log: identify_body(log, wheel_radius=radius, half_axle=half),
            body_log(BODY, t, torque, wheel_radius=radius, half_axle=half, noise=(0.002, 0.005), delay=0.02, seed=seed),
        ),
        "motor": lambda seed: timed(
            lambda log: identify_motor(log, wheel_radius=0.033, half_axle=0.08),
            motor_log(ROBOT, MOTOR, *volts, noise=(0.002, 0.01), current_noise=0.005, delay=0.02, seed=seed),
        ),
    }


def cli_runs() -> list[float]:
    """Wall seconds of two ``ddtrack identify`` processes on the motor log, a fresh compilation cache between them."""
    volts = reversing_steps(amplitude=6.0, duration=DURATION, rate=RATE, seed=0)
    log = motor_log(ROBOT, MOTOR, *volts, noise=(0.002, 0.01), current_noise=0.005, delay=0.02, seed=0)
    with tempfile.TemporaryDirectory() as folder:
        table = Path(folder) / "log.csv"
        columns = np.column_stack([log.speeds.t, log.speeds.command, log.speeds.speed, log.current])
        header = "t [s],u_r [V],u_l [V],v [m/s],omega [rad/s],i_r [A],i_l [A]"
        np.savetxt(table, columns, delimiter=",", header=header, comments="", fmt="%.17g")
        command = [sys.executable, "-m", "ddtrack", "identify", str(table), "--model", "motor", "--mass", "1.3",
                   "--wheel-radius", "0.033", "--half-axle", "0.08", "--out", str(Path(folder) / "motor.toml"),
                   "--overwrite"]  # fmt: skip
        environment = os.environ | {"DDTRACK_CACHE_DIR": str(Path(folder) / "cache")}
        seconds = []
        for _ in range(2):
            start = time.perf_counter()
            subprocess.run(command, env=environment, check=True, capture_output=True)
            seconds.append(time.perf_counter() - start)
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--cli", action="store_true", help="time two ddtrack identify processes on the motor log")
    parser.add_argument(
        "--model", choices=("lag", "body", "motor"), action="append", help="only this model (repeatable)"
    )
    args = parser.parse_args()
    enable_float64()
    if args.cli:
        first, second = cli_runs()
        summary = f"ddtrack identify --model motor: first process {first:.1f} s, second (cache warm) {second:.1f} s"
        print(json.dumps({"first_process": first, "second_process": second}) if args.json else summary)
        return
    results = {}
    for name, fit in fits().items():
        if args.model and name not in args.model:
            continue
        (cold_wall, cold_cpu), (warm_wall, warm_cpu) = fit(0), fit(1)
        results[name] = {"cold_wall": cold_wall, "cold_cpu": cold_cpu, "warm_wall": warm_wall, "warm_cpu": warm_cpu}
        if not args.json:
            print(
                f"{name}: cold {cold_wall:.1f} s wall ({cold_cpu:.1f} s CPU), warm {warm_wall:.1f} s wall "
                f"({warm_cpu:.1f} s CPU)",
                flush=True,
            )
    if args.json:
        print(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
