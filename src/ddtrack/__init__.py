"""ddtrack: trajectory-tracking controllers for differential-drive mobile robots, simulated in JAX.

Quick start::

    import ddtrack
    scenario = ddtrack.load_scenario("scenarios/paper_line.toml")
    result = ddtrack.run(scenario, seed=0)
    columns = ddtrack.timeseries(result)     # NumPy columns: t, x, y, ..., e_tr, tau_r, tau_l
"""
import jax as _jax

_jax.config.update("jax_enable_x64", True)  # float64 everywhere (DESIGN 1); set before any array exists

from .errors import ConfigError, DdtrackError, RunError  # noqa: E402
from .metrics import improvement, summarize, tracking_error  # noqa: E402
from .runner import monte_carlo, prepare, run, run_batch  # noqa: E402
from .scenario import Scenario, load_scenario, validate_scenario  # noqa: E402
from .sim import Draws, SimResult, simulate, timeseries  # noqa: E402
from .envs import register_envs as _register_envs  # noqa: E402,F401  (registers ddtrack/DiffDriveTracking-v0)

__version__ = "0.1.0"

__all__ = [
    "ConfigError", "DdtrackError", "Draws", "RunError", "Scenario", "SimResult", "improvement", "load_scenario",
    "monte_carlo", "prepare", "run", "run_batch", "simulate", "summarize", "timeseries", "tracking_error",
    "validate_scenario",
]
