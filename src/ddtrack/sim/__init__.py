"""The simulator: fixed-step RK4 under a zero-order hold, one ``lax.scan`` per run (docs/architecture.md)."""

from ..integrators import rk4, rk4_step
from .batch import repeated, simulate_alone, simulate_batch, stack, vmap_runs
from .result import REMEDIES, STATUS_NAMES, SimResult, remedy, timeseries
from .sensitivity import NominalPeriod
from .simulate import (
    DIVERGENCE_ERROR,
    DIVERGENCE_SPEED,
    ClosedLoop,
    Draws,
    HeldInput,
    measured,
    period_record,
    period_status,
    plant_period,
    recorded,
    require_matching_input,
    simulate,
)

__all__ = [
    "DIVERGENCE_ERROR",
    "DIVERGENCE_SPEED",
    "REMEDIES",
    "STATUS_NAMES",
    "ClosedLoop",
    "Draws",
    "HeldInput",
    "NominalPeriod",
    "SimResult",
    "measured",
    "period_record",
    "period_status",
    "plant_period",
    "recorded",
    "remedy",
    "repeated",
    "require_matching_input",
    "rk4",
    "rk4_step",
    "simulate",
    "simulate_alone",
    "simulate_batch",
    "stack",
    "timeseries",
    "vmap_runs",
]
