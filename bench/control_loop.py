"""The paper's line case simulated with python-control (``control.input_output_response``).

    python bench/control_loop.py [--json] [--repeats N] [--ddtrack-repeats M]

What a python-control user would write for the closed loop of ``ddtrack.run`` on
``scenarios/paper_line.toml`` (fixed-gain backstepping over computed torque, 40 s), timed as
``control_bs_s``. The dynamics and the controller are bench/python_loop.py's functions, imported,
so only the simulation machinery differs from the plain Python loop:

* plant: a continuous-time ``control.nlsys`` with state (x, y, theta, v, omega) and four inputs,
  the wheel torques and the wheel-torque disturbances; its right-hand side is
  ``python_loop.derivative`` (friction included);
* controller: a discrete-time, static ``control.nlsys`` with ``dt = T_c`` whose output is
  ``python_loop.backstepping_step`` at the sample time (reference, posture error, Kanayama law,
  clamps, computed torque), then the plant's torque limit.

**How the sampled loop is represented.** ddtrack samples the state at t_k = k T_c, holds the torque
and the disturbance over [t_k, t_k + T_c) (zero-order hold) and integrates the plant by RK4. In
python-control 0.10 a continuous and a discrete system cannot be interconnected:
``control.interconnect`` of a ``dt=0`` and a ``dt=0.01`` system raises ``ValueError: Systems have
incompatible timebases``, and ``input_output_response`` simulates one system, all continuous (by
``scipy.integrate.solve_ivp``) or all discrete. A continuous-time controller would be a different
closed loop (no sampling delay). So the loop here is the usual python-control idiom for sampled
control: per control period, evaluate the discrete controller on the sampled state, then call
``input_output_response`` on the plant over [t_k, t_k + T_c] with the held inputs as a constant
input signal and the previous call's final state as ``X0``: 4000 calls for the 40 s run. This is
exactly ddtrack's zero-order hold; only the integrator differs (solve_ivp's adaptive method,
restarted at every sample, instead of 10 fixed RK4 steps).

**Accuracy.** The time is only comparable at matching accuracy. The reference is the same sampled
loop by python_loop's RK4 at REFERENCE_REFINEMENT x the substeps (0.1 ms; doubling them again moves it
by <= 3e-7). ddtrack's own error against it is 3.1e-4 (max over every recorded state component,
reached in the first second's transient). With RK45, python-control's default method, the error is
6.6e-4 at python-control's default tolerances, 1.3e-4 at rtol 1e-6, atol 1e-8 and 2.4e-7 at
rtol 1e-7, atol 1e-9, while the run time stays the same: RK45 takes one step per 10 ms period at all these
tolerances, and the cost is per-call overhead. So RTOL = 1e-7 is the loosest decade clearly no less
accurate than ddtrack; docs/benchmarks.md ("python-control") has the table.

    import control_loop
    control_loop.time_control(5)   # {"control_bs_s": ..., "control_max_abs_state_difference": ..., ...}
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from pathlib import Path

import jax
import numpy as np

import ddtrack

sys.path.insert(0, str(Path(__file__).resolve().parent))

from python_loop import (
    backstepping_step,
    clamp,
    derivative,
    line_reference,
    params_from_scenario,
    run_backstepping,
)

ddtrack.enable_float64()  # ddtrack computes in float64: once, before any JAX array

ROOT = Path(__file__).resolve().parent.parent
SCENARIO = ROOT / "scenarios" / "paper_line.toml"

METHOD = "RK45"  # scipy.integrate.solve_ivp method
RTOL = 1e-7
ATOL = 1e-9
REFERENCE_REFINEMENT = 10  # the reference's RK4 substeps per ddtrack substep


def _control():
    try:
        import control
    except ImportError as exc:
        raise ImportError("bench/control_loop.py needs python-control: pip install -e '.[bench]'") from exc
    return control


def systems(params: dict) -> tuple:
    """(plant, controller): the continuous-time plant and the discrete-time controller as python-control
    nonlinear I/O systems; ``params`` is what ``python_loop.params_from_scenario`` returns."""
    ct = _control()
    robot, line = params["plant"], params["line"]
    step = backstepping_step(params["nominal"], params["gains"])

    def plant_rhs(t, x, u, _params):
        # tolist(): python_loop's scalar maths runs on Python floats, faster than on NumPy scalars
        return derivative(robot, x.tolist(), *u.tolist())

    def control_law(t, _x, y, _params):
        tau, _ = step(t, y.tolist(), line_reference(line, t), ())
        return [clamp(tau[0], robot.max_torque), clamp(tau[1], robot.max_torque)]  # the plant's limit, as ddtrack

    plant = ct.nlsys(
        plant_rhs,
        None,
        name="plant",
        inputs=["tau_r", "tau_l", "dist_r", "dist_l"],
        states=["x", "y", "theta", "v", "omega"],
    )
    controller = ct.nlsys(
        None,
        control_law,
        name="controller",
        inputs=["x", "y", "theta", "v", "omega"],
        outputs=["tau_r", "tau_l"],
        dt=params["control_period"],
    )
    return plant, controller


def disturbance_at(params: dict, t: float) -> tuple[float, float]:
    """Wheel-torque disturbance at t [N m], held over the period like the torque (as in python_loop.simulate)."""
    d = params["disturbance"]
    return tuple(b + a * math.sin(d.frequency * t + p) for b, a, p in zip(d.bias, d.amplitude, d.phase, strict=True))


def simulate(params: dict, *, method: str = METHOD, rtol: float = RTOL, atol: float = ATOL) -> np.ndarray:
    """The closed loop by python-control; returns the states x_0 .. x_{N-1}, shape (N, 5), the rows of
    ``ddtrack.SimResult.state``."""
    ct = _control()
    plant, controller = systems(params)
    period = params["control_period"]
    n_steps = params["n_steps"]
    solver = {"rtol": rtol, "atol": atol}
    states = np.empty((n_steps, 5))
    x = np.asarray(params["x0"], dtype=float)
    for k in range(n_steps):
        t = k * period
        states[k] = x
        held = [*controller.output(t, [], x), *disturbance_at(params, t)]
        response = ct.input_output_response(
            plant, [t, t + period], np.column_stack([held, held]), x, solve_ivp_method=method, solve_ivp_kwargs=solver
        )
        x = response.states[:, -1]
    return states


def reference(params: dict) -> np.ndarray:
    """The same sampled loop by python_loop's RK4 with REFERENCE_REFINEMENT x the substeps."""
    fine = {**params, "substeps": params["substeps"] * REFERENCE_REFINEMENT}
    return np.asarray(run_backstepping(**fine))


def paper_line(duration: float | None = None):
    """scenarios/paper_line.toml, optionally shortened to ``duration`` seconds (for the test)."""
    overrides = (
        [] if duration is None else [f"simulation.duration={duration}", f"simulation.metric_window=[0.0, {duration}]"]
    )
    return ddtrack.load_scenario(SCENARIO, overrides=overrides)


def ddtrack_states(scenario) -> np.ndarray:
    """``ddtrack.run(scenario).state`` as a NumPy array, shape (N, 5)."""
    return np.asarray(jax.block_until_ready(ddtrack.run(scenario)).state)


def timings(fn, repeats: int) -> list[float]:
    """Wall times [s] of ``repeats`` calls of ``fn`` (which must wait for its own result)."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return times


def time_control(
    repeats: int, *, ddtrack_result: np.ndarray | None = None, reference_result: np.ndarray | None = None
) -> dict:
    """Median and minimum wall time of ``repeats`` python-control runs of the paper line case, after one
    untimed run (the first pays one-off costs such as scipy's lazily loaded submodules), and that run's max |difference|
    from ddtrack's states (``ddtrack_result``, computed here when not given) and, when
    ``reference_result`` is given, from the reference."""
    control = _control()
    scenario = paper_line()
    params = params_from_scenario(scenario)
    if ddtrack_result is None:
        ddtrack_result = ddtrack_states(scenario)
    states = simulate(params)
    times = timings(lambda: simulate(params), repeats)
    figures = {
        "control_bs_s": statistics.median(times),
        "control_bs_min_s": min(times),
        "control_max_abs_state_difference": float(np.max(np.abs(states - ddtrack_result))),
        "control_method": METHOD,
        "control_rtol": RTOL,
        "control_atol": ATOL,
        "control_repeats": repeats,
        "control_version": control.__version__,
    }
    if reference_result is not None:
        figures["control_max_abs_error_vs_reference"] = float(np.max(np.abs(states - reference_result)))
    return figures


def load_average() -> list[float]:
    try:
        return [float(v) for v in Path("/proc/loadavg").read_text().split()[:3]]
    except OSError:
        return []


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of lines")
    parser.add_argument("--repeats", type=int, default=5, help="timed python-control runs [default 5]")
    parser.add_argument("--ddtrack-repeats", type=int, default=10, help="timed ddtrack runs [default 10]")
    args = parser.parse_args(argv)
    if args.repeats < 1 or args.ddtrack_repeats < 1:
        parser.error("--repeats and --ddtrack-repeats must be >= 1")
    _control()  # fail before the slow part
    load_start = load_average()
    scenario = paper_line()
    ddtrack_result = ddtrack_states(scenario)  # the first run compiles; not timed
    ddtrack_times = timings(lambda: jax.block_until_ready(ddtrack.run(scenario)), args.ddtrack_repeats)
    params = params_from_scenario(scenario)
    python_times = timings(lambda: run_backstepping(**params), 3)  # for context: the plain Python loop
    truth = reference(params)
    figures = time_control(args.repeats, ddtrack_result=ddtrack_result, reference_result=truth)
    single = statistics.median(ddtrack_times)
    figures.update(
        {
            "ddtrack_max_abs_error_vs_reference": float(np.max(np.abs(ddtrack_result - truth))),
            "single_bs_s": single,
            "single_bs_min_s": min(ddtrack_times),
            "ddtrack_repeats": args.ddtrack_repeats,
            "python_loop_bs_s": statistics.median(python_times),
            "ratio_control_over_ddtrack": figures["control_bs_s"] / single,
            "ratio_control_over_ddtrack_min": figures["control_bs_min_s"] / min(ddtrack_times),
            "load_average_start": load_start,
            "load_average_end": load_average(),
        }
    )
    if args.json:
        print(json.dumps(figures, indent=2))
    else:
        for key, value in figures.items():
            print(f"{key:<40} {value}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
