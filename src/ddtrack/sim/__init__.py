"""The simulator: fixed-step RK4 under a zero-order hold, one ``lax.scan`` per run (docs/architecture.md)."""

from .batch import simulate_alone, simulate_batch, stack, vmap_runs
from .integrators import rk4, rk4_step
from .result import REMEDIES, STATUS_NAMES, SimResult, remedy, timeseries
from .sensitivity import NominalPeriod
from .simulate import DIVERGENCE_SPEED, Draws, period_status, plant_period, simulate

__all__ = [
    "DIVERGENCE_SPEED",
    "REMEDIES",
    "STATUS_NAMES",
    "Draws",
    "NominalPeriod",
    "SimResult",
    "period_status",
    "plant_period",
    "remedy",
    "rk4",
    "rk4_step",
    "simulate",
    "simulate_alone",
    "simulate_batch",
    "stack",
    "timeseries",
    "vmap_runs",
]
