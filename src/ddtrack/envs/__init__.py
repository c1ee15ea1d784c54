"""Gymnasium environments: ``ddtrack/DiffDriveTracking-v0``, a thin shell over the simulator's plant step.

``import ddtrack`` (or ``import ddtrack.envs``) registers the environment, so either of these works::

    import ddtrack, gymnasium
    env = gymnasium.make("ddtrack/DiffDriveTracking-v0", scenario="scenarios/paper_line.toml", action_mode="gains")

    import gymnasium   # ddtrack not imported: the "module:id" form imports ddtrack.envs first
    env = gymnasium.make("ddtrack.envs:ddtrack/DiffDriveTracking-v0", scenario="scenarios/paper_line.toml")

(Gymnasium 1.0 removed the ``gymnasium.envs`` entry-point plugins of 0.26-0.29, so registering on import is the
way. ``import ddtrack`` itself stays light: it registers the environment right after Gymnasium's own import,
whether Gymnasium comes before or after ddtrack.)
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

from .tracking import ACTION_MODES, DEFAULT_EFFORT_WEIGHT, DiffDriveTrackingEnv

ENV_ID = "ddtrack/DiffDriveTracking-v0"


def register_envs() -> None:
    """Register ``ddtrack/DiffDriveTracking-v0`` with Gymnasium; calling it again does nothing.

    The episode length is the scenario's (``simulation.duration / control_period`` periods): the environment
    truncates by itself, so no ``TimeLimit`` wrapper is added.
    """
    if ENV_ID not in registry:
        register(id=ENV_ID, entry_point="ddtrack.envs.tracking:DiffDriveTrackingEnv")


register_envs()

__all__ = ["ACTION_MODES", "DEFAULT_EFFORT_WEIGHT", "ENV_ID", "DiffDriveTrackingEnv", "register_envs"]
