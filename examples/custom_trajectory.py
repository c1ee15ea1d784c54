"""A custom reference: the lemniscate of Bernoulli, tracked by the shipped backstepping controller.

A trajectory is any pytree with ``__call__(t) -> Reference`` (the Trajectory protocol, model.md §2.1). Subclassing
``ParametricCurve`` needs only the position: the heading, speed, yaw rate and their derivatives (which the
computed-torque loop feeds forward) come from forward-mode autodiff of ``position``. The run reuses the
figure-eight scenario's robot, plant, disturbance, noise and controller with this reference in its place.

    python examples/custom_trajectory.py [--duration SECONDS]
"""

# test-args: --duration 20
import argparse
import dataclasses
from pathlib import Path

import jax.numpy as jnp

import ddtrack
from ddtrack.runner import run_setup
from ddtrack.trajectories import ParametricCurve

ddtrack.enable_float64()  # ddtrack computes in float64: once, before any JAX array


@ddtrack.pytree_dataclass  # a frozen dataclass and a pytree: changing a field never recompiles the simulator
class Bernoulli(ParametricCurve):
    """Lemniscate of Bernoulli of half-width ``a`` [m], both lobes in ``period`` [s]; it never stops."""

    a: float = 3.0
    period: float = 60.0

    def position(self, t):
        s = 2.0 * jnp.pi * t / self.period + jnp.pi / 2  # start at the crossing point, heading down-left
        d = 1.0 + jnp.sin(s) ** 2
        return jnp.stack([self.a * jnp.cos(s) / d, self.a * jnp.sin(s) * jnp.cos(s) / d])


parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--duration", type=float, default=60.0, help="seconds to simulate (one figure: 60)")
args = parser.parse_args()

ref0 = Bernoulli()(0.0)
print(
    f"reference at t = 0: ({float(ref0.x):.2f}, {float(ref0.y):.2f}) m, heading {float(ref0.theta):.3f} rad, "
    f"speed {float(ref0.v):.3f} m/s, yaw rate {float(ref0.omega):.3f} rad/s"
)
base = Path(__file__).resolve().parents[1] / "scenarios" / "figure_eight.toml"
scenario = ddtrack.load_scenario(
    base,
    overrides=[
        f"simulation.duration={args.duration}",
        f"simulation.metric_window=[{args.duration / 4}, {args.duration}]",
    ],
)
setup, draws = ddtrack.prepare(scenario)
x0 = jnp.array([ref0.x, ref0.y - 0.3, ref0.theta, 0.0, 0.0])  # start 0.3 m off the path, at rest
setup = dataclasses.replace(setup, trajectory=Bernoulli(), x0=x0)
result = run_setup(scenario, setup, draws)
sim = scenario.simulation
metrics = ddtrack.summarize(
    ddtrack.timeseries(result),
    status=result.status_name,
    window=sim.window,
    control_period=sim.control_period,
    settling_threshold=sim.settling_threshold,
)
print(
    f"backstepping on the lemniscate: status {metrics['status']}, e_tr_mean {metrics['e_tr_mean']:.4f} m "
    f"over [{sim.window[0]:g}, {sim.window[1]:g}] s, settling {metrics['settling_time']} s"
)
