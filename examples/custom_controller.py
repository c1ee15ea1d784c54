"""A custom controller, registered from Python and run by name: ``kind = "integral_kanayama"``.

The law is Kanayama's (paper eq. 12) plus integral action on the along-track error: unmodelled wheel
friction makes plain backstepping lag its reference by a few centimetres (model.md §4.5), and the integral
removes that lag. It lives in the small plugin package ``examples/plugin`` (its law, its ``[controller]``
config over the shared inner loop, and the entry point that registers it when the package is pip-installed,
docs/plugins.md). Here it is imported from that folder, registered with ``ddtrack.register_controller``, and run
by name on the paper's straight-line case next to the shipped backstepping, on the same plant and disturbance
draws.

    python examples/custom_controller.py [SCENARIO]
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent / "plugin" / "src"))  # the plugin, not installed here

from ddtrack_integral_kanayama import IntegralKanayamaConfig

import ddtrack

ddtrack.enable_float64()  # ddtrack computes in float64: once, before any JAX array
ddtrack.register_controller(IntegralKanayamaConfig, has_kanayama_gains=True, differentiable=True)

default = Path(__file__).resolve().parents[1] / "scenarios" / "paper_line.toml"
path = sys.argv[1] if len(sys.argv) > 1 else default
for name in ("backstepping", "integral_kanayama"):
    scenario = ddtrack.load_scenario(path, controller=name)  # the file's [controller], switched to this kind
    sim = scenario.simulation
    result = ddtrack.run(scenario)
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
