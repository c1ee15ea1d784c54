"""``ddtrack excite``: a plan of timed velocity commands to drive on a robot so that its log identifies the lag model
(docs/identification.md).

Held steps of random level and length excite a lag of a few tenths of a second at every frequency that matters:
first the forward speed alone (the robot drives straight, back and forth), then the yaw rate alone (it turns in
place), then both at once (arcs, which the coupling terms theta_3 and theta_5 need), then a stop. Every command
stays within ``fraction`` of the robot's top speed and yaw rate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

REST = 1.0  #: [s] at rest at the start and the end
HOLD = (0.6, 2.5)  #: [s] shortest and longest hold of one level


@dataclass(frozen=True)
class Plan:
    """Velocity commands (v [m/s], omega [rad/s]) at times t [s], each held until the next."""

    t: np.ndarray
    v: np.ndarray
    omega: np.ndarray

    def reach(self) -> float:
        """Farthest the robot gets from its start [m] if it followed the commands exactly (the floor it needs)."""
        dt = np.diff(self.t, append=self.t[-1])
        heading = np.concatenate([[0.0], np.cumsum(self.omega * dt)[:-1]])
        x = np.cumsum(self.v * np.cos(heading) * dt)
        y = np.cumsum(self.v * np.sin(heading) * dt)
        return float(np.max(np.hypot(x, y)))


def excitation_plan(
    *,
    max_speed: float,
    max_yaw_rate: float,
    duration: float = 60.0,
    rate: float = 20.0,
    seed: int = 0,
    fraction: float = 0.6,
) -> Plan:
    """Commands every 1 / ``rate`` s for ``duration`` s: rest, forward-speed steps, yaw-rate steps, arcs, rest.

    Levels are drawn from ``seed``: forward speeds in [-0.5, 1] x ``fraction`` x ``max_speed`` (more forward
    than back), yaw rates in [-1, 1] x ``fraction`` x ``max_yaw_rate``."""
    if not (max_speed > 0 and max_yaw_rate > 0 and 0 < fraction <= 1 and rate > 0):
        raise ValueError("max_speed, max_yaw_rate and rate must be > 0, fraction in (0, 1]")
    if duration < 8 * REST:
        raise ValueError(f"duration {duration:g} s is too short: give at least {8 * REST:g} s")
    rng = np.random.default_rng(seed)
    t = np.arange(round(duration * rate)) / rate
    v, omega = np.zeros_like(t), np.zeros_like(t)
    moving = duration - 2 * REST
    phases = [(REST, REST + 0.25 * moving, True, False), (REST + 0.25 * moving, REST + 0.5 * moving, False, True)]
    phases.append((REST + 0.5 * moving, REST + moving, True, True))
    for start, end, drive, turn in phases:
        begin = start
        while begin < end:
            hold = min(rng.uniform(*HOLD), end - begin)
            span = (t >= begin) & (t < begin + hold)
            if drive:
                v[span] = fraction * max_speed * rng.uniform(-0.5, 1.0)
            if turn:
                omega[span] = fraction * max_yaw_rate * rng.uniform(-1.0, 1.0)
            begin += hold
    return Plan(t=t, v=v, omega=omega)
