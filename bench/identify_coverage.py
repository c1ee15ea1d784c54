"""Does ``ddtrack identify`` recover a known robot within the uncertainty it reports? (docs/identification.md)

A Pioneer 3-DX's published lag model (theta of Martins et al., with laser) is driven by ``ddtrack excite``'s plan
(60 s at 20 Hz, seed 0, 60 % of its top speeds) under each condition below; each seed draws new measurement noise
(and its own plan levels with ``--new-plans``). For every seed the identified theta and its standard errors give
z = (theta_hat - theta) / std; a 95 % interval covers the truth when |z| <= 1.96. Printed per condition: the
coverage of the 95 % intervals (over seeds and the six parameters, and per parameter), the median relative
standard error, the coverage of the fitted command delay's 95 % interval, how often the speeds' reading
(instants or odometry's interval means) was found, the worst held-out fit, and the seconds per fit (the log's
generation not counted). ``--window inf`` fits the output error over the whole record in one simulation (as
before the 2 s windows), to compare.

    python bench/identify_coverage.py [--seeds 50] [--window 2.0] [--only timing] [--json]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from ddtrack import enable_float64
from ddtrack.model.lag import PIONEER_3DX_WITH_LASER
from ddtrack.sysid import LAG, excitation_plan, identify_lag, lag_log
from ddtrack.sysid.output_error import WINDOW

THETA = np.array(PIONEER_3DX_WITH_LASER)
#: name -> (lag_log keywords, the delay [s] and reading to find); the odometry_rate ones log the speeds on their
#: own clock, integrated exactly apart from the fit (:func:`ddtrack.sysid.timed_lag_log`), as a robot's two topics do
CONDITIONS = {
    "noise": ({"noise": (0.005, 0.01)}, 0.0, False),
    "noise + 100 ms latency": ({"noise": (0.005, 0.01), "delay": 0.1}, 0.1, False),
    "2000-count encoders + noise + 50 ms latency": (
        {"noise": (0.002, 0.005), "encoder_counts": 2000, "delay": 0.05},
        0.05,
        True,
    ),
    "timing: equal rates (20/20 Hz), 60 ms latency": (
        {"noise": (0.005, 0.01), "delay": 0.06, "odometry_rate": 20.0},
        0.06,
        False,
    ),
    "timing: commands 20 Hz, odometry 30 Hz, 60 ms latency": (
        {"noise": (0.005, 0.01), "delay": 0.06, "odometry_rate": 30.0},
        0.06,
        False,
    ),
    "timing: commands 20 Hz, odometry 50 Hz (encoders), 60 ms latency": (
        {"noise": (0.002, 0.005), "encoder_counts": 2000, "delay": 0.06, "odometry_rate": 50.0},
        0.06,
        True,
    ),
    "timing: a delay of 1.5 samples (75 ms at 20/20 Hz)": (
        {"noise": (0.005, 0.01), "delay": 0.075, "odometry_rate": 20.0},
        0.075,
        False,
    ),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=50)
    parser.add_argument("--new-plans", action="store_true", help="each seed also draws its own plan")
    parser.add_argument("--window", type=float, default=WINDOW, help="output-error window [s]; inf: whole record")
    parser.add_argument("--only", default="", help="run only the conditions whose name contains this")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    enable_float64()
    results = {}
    for name, (conditions, delay, interval_mean) in CONDITIONS.items():
        if args.only not in name:
            continue
        z, relative, delay_z, readings, fits, seconds = [], [], [], 0, [], 0.0
        for seed in range(args.seeds):
            plan = excitation_plan(max_speed=1.2, max_yaw_rate=5.24, seed=seed if args.new_plans else 0)
            log = lag_log(THETA, plan, seed=seed, **conditions)
            start = time.perf_counter()
            fit = identify_lag(log, window=args.window)
            seconds += time.perf_counter() - start
            z.append((fit.params - THETA) / fit.std)
            relative.append(fit.std / np.abs(THETA))
            delay_z.append((fit.delay - delay) / fit.delay_std)
            readings += fit.interval_mean is interval_mean
            fits.append(min(fit.fit_percent.values()))
        z_all = np.array(z)
        covered = np.abs(z_all) <= 1.96
        results[name] = {
            "seeds": args.seeds,
            "coverage_95": float(covered.mean()),
            "coverage_95_per_parameter": dict(zip(LAG.names, covered.mean(axis=0).tolist(), strict=True)),
            "z_std_per_parameter": dict(zip(LAG.names, z_all.std(axis=0).tolist(), strict=True)),
            "median_relative_std": dict(zip(LAG.names, np.median(relative, axis=0).tolist(), strict=True)),
            "delay_coverage_95": float(np.mean(np.abs(delay_z) <= 1.96)),
            "delay_median_abs_z": float(np.median(np.abs(delay_z))),
            "reading_found": readings / args.seeds,
            "worst_held_out_fit_percent": float(min(fits)),
            "seconds_per_fit": seconds / args.seeds,
        }
    if args.json:
        print(json.dumps(results, indent=2))
        return
    for name, r in results.items():
        print(f"{name}: {r['seeds']} seeds")
        print(f"  95 % intervals covering the truth: {100 * r['coverage_95']:.1f} % (over seeds and parameters)")
        for p in LAG.names:
            print(
                f"    {p}: coverage {100 * r['coverage_95_per_parameter'][p]:5.1f} %, std of z "
                f"{r['z_std_per_parameter'][p]:.2f}, median relative std {100 * r['median_relative_std'][p]:.3g} %"
            )
        print(
            f"  delay's 95 % interval covering the truth {100 * r['delay_coverage_95']:.0f} %, reading found "
            f"{100 * r['reading_found']:.0f} %, worst held-out fit {r['worst_held_out_fit_percent']:.1f} %, "
            f"{r['seconds_per_fit']:.2f} s per fit"
        )


if __name__ == "__main__":
    main()
