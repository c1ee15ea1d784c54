"""A custom controller in about twenty lines: an outer velocity law over the shared inner loop.

The law is Kanayama's (paper eq. 12) plus integral action on the along-track error: unmodelled wheel
friction makes plain backstepping lag its reference by a few centimetres (model.md §4.5), and the integral
removes that lag. Its integral lives in ``memory``, which ``command`` returns instead of mutating
(docs/architecture.md).
It is composed with the computed-torque inner loop that the backstepping controllers share and run on the
paper's straight-line case next to the shipped backstepping, on the same plant and disturbance draws.

    python examples/custom_controller.py [SCENARIO]
"""

import dataclasses
import sys
from pathlib import Path

import jax
import jax.numpy as jnp

import ddtrack
from ddtrack.controllers import Cascade, ComputedTorque, VelocityCommand
from ddtrack.geometry import posture_error
from ddtrack.runner import run_setup

ddtrack.enable_float64()  # ddtrack computes in float64: once, before any JAX array


@jax.tree_util.register_dataclass  # the simulator is jitted: a controller is a pytree of its parameters
@dataclasses.dataclass(frozen=True)
class IntegralKanayama:
    """Kanayama's law with v_c += ki * integral of e_x. In: y = [x, y, theta, v, omega] and the reference;
    out: (v_c [m/s], omega_c [rad/s]) and its feed-forward derivative (the inner loop's K_c absorbs the rest)."""

    kx: float = 1.0  # [1/s]
    ky: float = 55.0  # [1/m^2]
    ktheta: float = 15.0  # [1/m]
    ki: float = 0.5  # [1/s^2]
    control_period: float = 0.01  # [s]
    gate: float = 0.2  # integrate only while the tracking error is below this [m] (no wind-up)

    def init(self, x0, ref0, key):
        return jnp.asarray(0.0)  # the integral of e_x [m s]

    def command(self, t, y, ref, memory):
        e_x, e_y, e_th = posture_error(y[0], y[1], y[2], ref.x, ref.y, ref.theta)  # model.md §2.2
        integral = memory + jnp.where(jnp.hypot(e_x, e_y) < self.gate, e_x * self.control_period, 0.0)
        v_c = ref.v * jnp.cos(e_th) + self.kx * e_x + self.ki * integral
        omega_c = ref.omega + ref.v * (self.ky * e_y + self.ktheta * jnp.sin(e_th))
        command = VelocityCommand(
            jnp.stack([v_c, omega_c]), jnp.stack([ref.v_dot, ref.omega_dot]), jnp.zeros(2), jnp.asarray(0.0)
        )  # no strict cross term, no velocity clamp
        return command, integral, {"integral_e_x": integral}  # logs: recorded, never fed back

    def observe(self, memory, saturated):
        return memory  # told whether the torque limit acted; this law ignores it


default = Path(__file__).resolve().parents[1] / "scenarios" / "paper_line.toml"
scenario = ddtrack.load_scenario(sys.argv[1] if len(sys.argv) > 1 else default)
sim = scenario.simulation
setup, draws = ddtrack.prepare(scenario)  # the plant, reference and random draws of the scenario's seed
law = IntegralKanayama(control_period=sim.control_period)
custom = dataclasses.replace(setup, controller=Cascade(law, ComputedTorque(setup.nominal, kc=(10.0, 10.0))))
for name, result in (
    ("backstepping", ddtrack.run(scenario)),
    ("integral_kanayama", run_setup(scenario, custom, draws)),
):
    metrics = ddtrack.summarize(
        ddtrack.timeseries(result),
        status=result.status_name,
        window=sim.window,
        control_period=sim.control_period,
        settling_threshold=sim.settling_threshold,
    )
    print(
        f"{name:<18} status {metrics['status']}, e_tr_mean {metrics['e_tr_mean']:.4f} m over "
        f"[{sim.window[0]:g}, {sim.window[1]:g}] s, "
        f"final {metrics['e_tr_final']:.4f} m"
    )
