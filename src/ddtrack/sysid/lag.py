"""The velocity-lag model of a base that takes velocity commands (Martins et al., model.md §1.8), as
``ddtrack identify`` fits it (docs/identification.md). It is linear in theta = (theta_1 .. theta_6)::

    v*     = theta_1 v_dot     - theta_3 omega^2 + theta_4 v
    omega* = theta_2 omega_dot + theta_5 v omega + theta_6 omega
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..model.lag import LagPlant
from .fit import SpeedFit, SpeedLog, SpeedModel, identify, simulate
from .output_error import WINDOW


def _rate(theta, speed, command):
    """(v_dot, omega_dot) of the lag plant under a held command."""
    return LagPlant(theta=theta).derivative(jnp.concatenate([jnp.zeros(3), speed]), command, jnp.zeros(2))[3:]


def _regressors(speed: np.ndarray, rate: np.ndarray, command: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    v, w = speed[:, 0], speed[:, 1]
    zero = np.zeros_like(v)
    rows_v = np.column_stack([rate[:, 0], zero, -(w**2), v, zero, zero])
    rows_w = np.column_stack([zero, rate[:, 1], zero, zero, v * w, w])
    return np.concatenate([rows_v, rows_w]), np.concatenate([command[:, 0], command[:, 1]])


LAG = SpeedModel(
    name="lag",
    names=("theta_1", "theta_2", "theta_3", "theta_4", "theta_5", "theta_6"),
    units=("s", "s", "s m/rad^2", "1", "s/m", "1"),
    meanings=(
        "v's inertia (lag = theta_1 / theta_4)",
        "omega's inertia (lag = theta_2 / theta_6)",
        "omega^2 feeding v (centripetal coupling)",
        "v's damping (DC gain 1 / theta_4)",
        "v omega slowing omega (coupling)",
        "omega's damping (DC gain 1 / theta_6)",
    ),
    rate=_rate,
    regressors=_regressors,
    positive=(0, 1),
    couplings=(2, 4),
    input_names=("the v command", "the omega command"),
)


def identify_lag(log: SpeedLog, *, max_delay: float = 0.3, window: float = WINDOW) -> SpeedFit:
    """The lag model (theta_1..theta_6) and command delay of the base that recorded ``log`` (its commands as
    ``log.command``), the output error over windows of ``window`` [s]."""
    return identify(LAG, log, max_delay=max_delay, window=window)


def lag_time_constants(theta: np.ndarray) -> tuple[float, float]:
    """Lags of v and omega without the coupling terms [s]: theta_1 / theta_4, theta_2 / theta_6."""
    lag_v, lag_w = np.asarray(LagPlant(theta=jnp.asarray(theta, float)).time_constants())
    return float(lag_v), float(lag_w)


def simulate_speeds(
    theta: np.ndarray, t: np.ndarray, command: np.ndarray, start: np.ndarray, *, interval_mean: bool = False
) -> np.ndarray:
    """(v, omega) of the lag model at the times ``t`` [s] from ``start``, each command held until the next time."""
    return simulate(LAG, np.asarray(theta, dtype=float), t, command, start, interval_mean)
