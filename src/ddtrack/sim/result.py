"""The outcome of a simulation."""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from typing import Any, NamedTuple

import jax
import numpy as np
from jax import Array

from ..layout import BODY, POSTURE_ERROR, WHEEL_TORQUES
from ..trajectories import Reference

STATUS_NAMES = ("ok", "diverged", "non_finite")
REMEDIES = {
    "ok": "",
    "diverged": "the tracking error or the speed left its bounds: lower the gains, move the initial pose "
    "closer to the reference, or raise simulation.divergence_error",
    "non_finite": "the state or the control became NaN/inf: shorten simulation.control_period, raise "
    "simulation.substeps, or check the controller",
}


def remedy(status: str, columns: dict, warnings: Sequence[dict] = ()) -> str:
    """What to try after a failed run, naming its likely cause: an inner loop that the scenario's control period
    makes unstable (its ``sampled_inner_loop_unstable`` warning, from ``metrics.json``'s ``warnings``), else from the
    run's own record (``columns``, the :func:`timeseries` up to the failure): a run that spent most of its time
    against the torque limit or a clamp failed because the robot could not do what was asked, not because of its
    gains."""
    named = [warning["message"] for warning in warnings if warning.get("code") == "sampled_inner_loop_unstable"]
    if status != "ok" and named:
        return str(named[0])
    saturated = columns.get("saturated")  # absent for a controller that logs no saturation
    # over at least 20 periods: a run that fails at once says nothing by its saturation
    if status == "diverged" and saturated is not None and len(saturated) >= 20 and np.mean(saturated > 0.5) >= 0.5:
        return (
            f"the torque limit or a velocity clamp acted in {100 * np.mean(saturated > 0.5):.3g} % of the periods "
            "before it: the robot could not do what the reference asked; slow the reference, raise "
            "robot.max_torque or the controller's clamps if the robot allows, or start closer to the reference"
        )
    return REMEDIES[status]


class SimResult(NamedTuple):
    """Time series of a closed-loop run, one row per control period k (t_k = k T_c).

    Rows after a failure repeat the frozen last state; :attr:`n_valid` says how many rows count.
    A batch (:func:`ddtrack.run_batch`) adds a leading run axis to every array.

    Attributes
    ----------
    t : Array, shape (N,)
        Sample times t_k [s].
    state : Array, shape (N, 5)
        The true BODY state [x, y, theta, v, omega] at t_k [m, m, rad, m/s, rad/s], as the plant observes it.
    reference : Reference
        The reference at t_k, each field of shape (N,).
    error : Array, shape (N, 3)
        Posture error [e_x, e_y, e_theta] of the true state [m, m, rad] (model.md §2.2).
    control : Array, shape (N, 2)
        Plant input held over [t_k, t_k+1): wheel torques [N m], or (v [m/s], omega [rad/s]).
    logs : dict of str to Array
        The controller's logged scalars, each (N,).
    status : Array
        0 ok, 1 diverged, 2 non_finite (:attr:`status_name`).
    failure_index : Array
        First failing row k, or -1.
    plant_state : dict of str to Array
        The plant's other states (its ``state_layout`` less BODY's), by name, each (N,); empty for BODY plants.
    """

    t: Array  #: (N,) sample times [s]
    state: Array  #: (N, 5) true state x_k = [x, y, theta, v, omega] at t_k
    reference: Reference  #: fields of shape (N,)
    error: Array  #: (N, 3) posture error [e_x, e_y, e_theta] of the true state (model.md §2.2)
    control: Array  #: (N, 2) plant input held over [t_k, t_k+1): torques [N m] or (v, omega)
    logs: dict  #: name -> (N,) logged scalars
    status: Array  #: 0 ok, 1 diverged, 2 non_finite
    failure_index: Array  #: first failing row k, or -1
    plant_state: dict  #: name -> (N,) the plant's states beyond BODY (e.g. wheel angles)

    @property
    def status_name(self) -> str:
        """``"ok"``, ``"diverged"`` or ``"non_finite"``."""
        return STATUS_NAMES[int(self.status)]

    @property
    def n_valid(self) -> int:
        """Rows 0..n_valid-1 are the run; for a failed run, the last one is the step that failed."""
        k = int(self.failure_index)
        return int(np.shape(self.t)[0]) if k < 0 else k + 1

    @property
    def failure_time(self) -> float | None:
        """When the run failed [s], or None for a run that did not."""
        k = int(self.failure_index)
        return None if k < 0 else float(self.t[k])


# an exported program (ddtrack.compilations.exported) returns one: its output structure must be serializable
jax.export.register_namedtuple_serialization(SimResult, serialized_name="ddtrack.SimResult")


#: the documented columns that lead ``timeseries.parquet``, in order; the other logs and plant states follow
LEADING_COLUMNS = ("t", *BODY.names, "x_ref", "y_ref", "theta_ref", "v_ref", "omega_ref", *POSTURE_ERROR.names,
                   "e_tr", "v_cmd", "omega_cmd", "tau_r", "tau_l")  # fmt: skip


def recorded_columns(result: SimResult, names: Collection[str] | None = None) -> dict[str, Any]:
    """The recorded series of ``result`` by their column names, as they are: ``t``, the BODY state, the reference
    (``x_ref, y_ref, v_ref, omega_ref``), the posture error, every logged channel and the plant's states beyond BODY.
    Only those in ``names`` when given: inside a jitted batch (every array with its run axis), XLA then drops the
    rest of the recording. :func:`finished_columns` turns them into ``timeseries.parquet``'s columns; a single run
    and a batch's metrics both go this one way."""
    reference = result.reference._asdict()
    columns = {"t": result.t, **BODY.columns(result.state)}
    columns |= {f"{name}_ref": reference[name] for name in ("x", "y", "v", "omega")}
    columns |= POSTURE_ERROR.columns(result.error) | dict(result.logs) | dict(result.plant_state)
    return columns if names is None else {name: value for name, value in columns.items() if name in names}


def finished_columns(recorded: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The documented columns (docs/guide.md) from one run's :func:`recorded_columns` (float64 NumPy arrays over its
    valid rows), computed on the host: ``theta_ref = theta + e_theta`` (continuous like theta; the reference's own
    is wrapped), e_tr = |(e_x, e_y)|, and NaN torques where no torque was applied (a velocity-input plant).
    Columns it cannot compute (a metrics batch keeps only what the metrics read) are left out."""
    columns = dict(recorded)
    nan = np.full(len(columns["t"]), np.nan)
    if "theta" in columns and "e_theta" in columns:
        columns["theta_ref"] = columns["theta"] + columns["e_theta"]
    if "e_x" in columns and "e_y" in columns:
        columns["e_tr"] = np.hypot(columns["e_x"], columns["e_y"])
    columns |= {
        name: columns.get(name, nan) for name in WHEEL_TORQUES.names
    }  # named by the simulator for torque plants
    return {name: columns.pop(name) for name in LEADING_COLUMNS if name in columns} | columns


def timeseries(result: SimResult) -> dict[str, np.ndarray]:
    """The documented time-series columns (docs/guide.md) of the valid rows, as float64 NumPy arrays.

    ``t, x, y, theta, v, omega, x_ref, y_ref, theta_ref, v_ref, omega_ref, e_x, e_y, e_theta, e_tr,
    v_cmd, omega_cmd, tau_r, tau_l``, every logged scalar (``kx, ky, ktheta``, ``saturated``, ...) and the plant's
    states beyond BODY, by their names.
    Torques are NaN for a velocity-input plant; ``v_cmd`` and ``omega_cmd`` are absent where no velocity was
    commanded (a torque law that logs no velocity command). ``theta`` and ``theta_ref`` are both continuous
    (unwrapped, so plots show no 2 pi jumps): ``theta_ref = theta + e_theta``, where ``e_theta`` is the
    posture error wrapped to (-pi, pi], so ``theta_ref - theta`` is the true heading error.

    Parameters
    ----------
    result : SimResult
        A single run (not a batch).

    Returns
    -------
    dict of str to ndarray
        The columns of ``timeseries.parquet``, each of shape (n_valid,), in SI units: [s], [m], [rad],
        [m/s], [rad/s], [N m].
    """
    n = result.n_valid
    return finished_columns(
        {name: np.asarray(value, dtype=float)[:n] for name, value in recorded_columns(result).items()}
    )
