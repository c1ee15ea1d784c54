"""Controllers: the protocol, inner loops, Kanayama backstepping (model.md §2) and the open-loop replay."""

from .backstepping import (
    KANAYAMA_GAINS,
    MAX_VELOCITY,
    MAX_YAW_RATE,
    Backstepping,
    clamp_command,
    kanayama_command,
    kanayama_command_rate,
    lyapunov,
)
from .base import Cascade, Controller, Logs, TorqueLaw, VelocityCommand, VelocityLaw, VelocityOutput
from .dither import Dithered
from .inner import ComputedTorque, HeldLoop, WheelPD
from .nn import MLP, Scales, init_mlp
from .nn_adaptive import (
    AdaptiveMemory,
    Emulator,
    NNAdaptiveBackstepping,
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
    "Logs",
    "NNAdaptiveBackstepping",
    "Replay",
    "Scales",
    "TorqueLaw",
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
