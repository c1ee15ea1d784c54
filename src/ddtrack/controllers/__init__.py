"""Controllers: the protocol, inner loops, Kanayama backstepping (model.md §2) and the open-loop replay."""

from .backstepping import (
    KANAYAMA_GAINS,
    MAX_VELOCITY,
    MAX_YAW_RATE,
    Backstepping,
    KanayamaGains,
    StrictTerm,
    VelocityClamps,
    clamp_command,
    kanayama_command,
    kanayama_command_rate,
    lyapunov,
)
from .base import Cascade, Controller, Logs, TorqueLaw, VelocityCommand, VelocityLaw, VelocityOutput
from .dither import Dithered
from .inner import ComputedTorque, HeldLoop, InnerLoopParameters, WheelPD
from .nn import MLP, Scales, init_mlp
from .nn_adaptive import (
    AdaptiveMemory,
    Emulator,
    NNAdaptiveBackstepping,
    NNAdaptiveParameters,
    cost_gradient,
    emulator_scales,
    error_jacobian_body,
    gain_sensitivity,
    one_step_coefficient,
)
from .replay import Replay

__all__ = [
    "KANAYAMA_GAINS",
    "MAX_VELOCITY",
    "MAX_YAW_RATE",
    "MLP",
    "AdaptiveMemory",
    "Backstepping",
    "Cascade",
    "ComputedTorque",
    "Controller",
    "Dithered",
    "Emulator",
    "HeldLoop",
    "InnerLoopParameters",
    "KanayamaGains",
    "Logs",
    "NNAdaptiveBackstepping",
    "NNAdaptiveParameters",
    "Replay",
    "Scales",
    "StrictTerm",
    "TorqueLaw",
    "VelocityClamps",
    "VelocityCommand",
    "VelocityLaw",
    "VelocityOutput",
    "WheelPD",
    "clamp_command",
    "cost_gradient",
    "emulator_scales",
    "error_jacobian_body",
    "gain_sensitivity",
    "init_mlp",
    "kanayama_command",
    "kanayama_command_rate",
    "lyapunov",
    "one_step_coefficient",
]
