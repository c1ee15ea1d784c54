"""Controllers: the protocol, inner loops and Kanayama backstepping (SPEC 2)."""
from .backstepping import Backstepping, clamp_command, kanayama_command, kanayama_command_rate, lyapunov
from .base import Cascade, Controller, Logs, TorqueLaw, VelocityCommand, VelocityLaw
from .inner import ComputedTorque, WheelPD

__all__ = [
    "Backstepping", "Cascade", "ComputedTorque", "Controller", "Logs", "TorqueLaw", "VelocityCommand", "VelocityLaw",
    "WheelPD", "clamp_command", "kanayama_command", "kanayama_command_rate", "lyapunov",
]
