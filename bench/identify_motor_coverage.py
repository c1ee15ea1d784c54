"""Does ``ddtrack identify --model motor`` recover a known robot within the uncertainty it reports?
(docs/identification.md)

A Burger-sized robot (1.3 kg, its XL430 servos' reflected rotor inertia on each wheel, a motor 10 % stronger than
the datasheet's behind a 90 % gearbox, a little viscous and Coulomb friction) is driven by voltage steps
(``ddtrack excite --volts 6``: 16 s at 50 Hz, seed 0) acting 20 ms after they are logged; each seed draws new
noise on the measured speeds (2 mm/s, 0.01 rad/s) and currents (5 mA). For every seed the five drivetrain
constants and the armature's R_a and k_e with their standard errors give z = (estimate - truth) / std; a 95 %
interval covers the truth when |z| <= 1.96. Printed: the coverage (over seeds and parameters, and per
parameter), the std of z, the median relative standard error, how often the delay's 95 % interval holds it, and
seconds per fit.

    python bench/identify_motor_coverage.py [--seeds 50] [--json]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from ddtrack import enable_float64
from ddtrack.model.motors import DCMotor
from ddtrack.model.params import RobotParams
from ddtrack.sysid import drive_constants, identify_motor, motor_log, reversing_steps
from ddtrack.sysid.motor import NAMES

RADIUS, HALF = 0.033, 0.08
ROBOT = RobotParams(
    mass=1.3, inertia=0.012, com_offset=-0.03, wheel_radius=RADIUS, half_axle=HALF, viscous_friction=0.002,
    coulomb_friction=0.01, wheel_inertia=0.00202,
)  # fmt: skip
MOTOR = DCMotor(
    resistance=8.5, torque_constant=1.2, back_emf=1.6, efficiency=0.9, supply_voltage=11.1, current_limit=1.3
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=50)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    enable_float64()
    names = (*NAMES, "R_a", "k_e")
    truth = np.concatenate([drive_constants(ROBOT, MOTOR), [MOTOR.resistance, MOTOR.back_emf]])
    t, voltage = reversing_steps(amplitude=6.0, duration=16.0, rate=50.0, seed=0)
    z, relative, delays, seconds = [], [], 0, 0.0
    for seed in range(args.seeds):
        log = motor_log(ROBOT, MOTOR, t, voltage, noise=(0.002, 0.01), current_noise=0.005, delay=0.02, seed=seed)
        start = time.perf_counter()
        fit = identify_motor(log, wheel_radius=RADIUS, half_axle=HALF, max_delay=0.04)
        seconds += time.perf_counter() - start
        assert fit.armature is not None
        estimate = np.concatenate([fit.drive.params, [fit.armature.resistance, fit.armature.back_emf]])
        std = np.concatenate([fit.drive.std, fit.armature.std])
        z.append((estimate - truth) / std)
        relative.append(std / np.abs(truth))
        delays += abs(fit.drive.delay - 0.02) <= 1.96 * fit.drive.delay_std
    z_all = np.array(z)
    covered = np.abs(z_all) <= 1.96
    result = {
        "seeds": args.seeds,
        "coverage_95": float(covered.mean()),
        "coverage_95_per_parameter": dict(zip(names, covered.mean(axis=0).tolist(), strict=True)),
        "z_std_per_parameter": dict(zip(names, z_all.std(axis=0).tolist(), strict=True)),
        "median_relative_std": dict(zip(names, np.median(relative, axis=0).tolist(), strict=True)),
        "delay_coverage_95": delays / args.seeds,
        "seconds_per_fit": seconds / args.seeds,
    }
    if args.json:
        print(json.dumps(result, indent=2))
        return
    print(f"{args.seeds} seeds: 95 % intervals covering the truth {100 * result['coverage_95']:.1f} %")
    for name in names:
        print(
            f"  {name}: coverage {100 * result['coverage_95_per_parameter'][name]:5.1f} %, std of z "
            f"{result['z_std_per_parameter'][name]:.2f}, median relative std "
            f"{100 * result['median_relative_std'][name]:.3g} %"
        )
    print(
        f"the delay's 95 % interval holds it on {100 * result['delay_coverage_95']:.0f} % of seeds, "
        f"{result['seconds_per_fit']:.2f} s per fit"
    )


if __name__ == "__main__":
    main()
