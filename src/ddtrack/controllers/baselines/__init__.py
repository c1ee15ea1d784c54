"""Baseline controllers on the same plant and inner loops as the paper's (issue 5), one module each."""

from .adaptive import AdaptiveBacksteppingParameters, AdaptiveComputedTorque, regressor
from .ltv_lqr import LTVLQRParameters, LTVUnicycleLQR, lqr_gain, solve_dare, unicycle_error_model
from .martins import (
    AdaptiveDynamicCompensator,
    CompensatorMemory,
    CompensatorParameters,
    compensator_command,
    lag_regressor,
)
from .mppi import MPPI, MPPICost, MPPIMemory, MPPIParameters, preview, rollout
from .pure_pursuit import PurePursuitParameters, RegulatedPurePursuit, find_carrot, pursuit_curvature
from .sliding_mode import SlidingModeParameters, SlidingModeTorque, switching_term

__all__ = [
    "MPPI",
    "AdaptiveBacksteppingParameters",
    "AdaptiveComputedTorque",
    "AdaptiveDynamicCompensator",
    "CompensatorMemory",
    "CompensatorParameters",
    "LTVLQRParameters",
    "LTVUnicycleLQR",
    "MPPICost",
    "MPPIMemory",
    "MPPIParameters",
    "PurePursuitParameters",
    "RegulatedPurePursuit",
    "SlidingModeParameters",
    "SlidingModeTorque",
    "compensator_command",
    "find_carrot",
    "lag_regressor",
    "lqr_gain",
    "preview",
    "pursuit_curvature",
    "regressor",
    "rollout",
    "solve_dare",
    "switching_term",
    "unicycle_error_model",
]
