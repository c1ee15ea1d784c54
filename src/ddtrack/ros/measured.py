"""A live drive as a run folder: what ``ddtrack drive`` measured and sent, scored against its reference as
``ddtrack run`` scores a simulation, so that ``report``, ``export`` and ``animate`` read it (docs/ros.md).

The pose is the robot's odometry (or its /tf pose) as drive received it, not the ground truth a simulation knows:
the folder's metrics say so in a warning, since a drifting odometry tracks its reference well on paper.
"""

from __future__ import annotations

from collections.abc import Sequence

import jax.numpy as jnp
import numpy as np

from ..geometry import posture_error
from ..layout import BODY, POSTURE_ERROR
from ..runner import run_metrics
from ..scenario import Scenario
from ..sim.result import finished_columns
from ..studies.recorded import MEASURED

#: the warning every measured run carries
MEASURED_POSE = {
    "code": MEASURED,
    "message": "the pose is the robot's odometry as ddtrack drive received it, not ground truth: its errors are "
    "the tracking errors the robot believed it had (an odometry that drifts looks on track)",
}

Row = tuple[float, Sequence[float], Sequence[float], float, float]  #: (t, measured BODY, reference, the command)


def measured_run(
    scenario: Scenario, rows: Sequence[Row], *, commands: tuple[str, str] = ("v_cmd", "omega_cmd"), status: str = "ok"
) -> tuple[dict, dict]:
    """(columns, metrics) of a live drive, one row per command it sent.

    Parameters
    ----------
    scenario : Scenario
        The scenario driven (its window, thresholds and robot for the metrics).
    rows : sequence of (t, y, ref, command_0, command_1)
        t [s] the reference time; y the measured BODY vector [x, y, theta, v, omega] the command answered; ref the
        reference (x, y, theta, v, omega); the command sent.
    commands : (str, str)
        The command's column names: ``v_cmd, omega_cmd`` [m/s, rad/s], or ``tau_r, tau_l`` [N m] (an effort topic).
    status : str
        The run's status (``ok`` unless drive stopped it for a failure).

    Returns
    -------
    tuple of dict
        ``timeseries.parquet``'s columns (:func:`ddtrack.sim.result.finished_columns`) and ``metrics.json``
        (:func:`ddtrack.runner.run_metrics`, with the :data:`MEASURED_POSE` warning).
    """
    t = np.array([row[0] for row in rows], dtype=float)
    measured = np.array([row[1] for row in rows], dtype=float).reshape(-1, len(BODY))
    reference = np.array([row[2] for row in rows], dtype=float).reshape(-1, 5)
    body = BODY.columns(measured)
    body["theta"] = np.unwrap(body["theta"])  # a yaw from quaternions jumps at +-pi; the columns are continuous
    x_ref, y_ref, theta_ref, v_ref, omega_ref = reference.T
    error = np.asarray(
        posture_error(*(jnp.asarray(c) for c in (body["x"], body["y"], body["theta"], x_ref, y_ref, theta_ref)))
    )
    recorded = {"t": t, **body, "x_ref": x_ref, "y_ref": y_ref, "v_ref": v_ref, "omega_ref": omega_ref}
    recorded |= POSTURE_ERROR.columns(error.T)
    recorded |= {name: np.array([row[3 + i] for row in rows], dtype=float) for i, name in enumerate(commands)}
    columns = finished_columns(recorded)
    metrics = run_metrics(scenario, columns, status=status)
    metrics["warnings"] = [MEASURED_POSE, *metrics["warnings"]]
    return columns, metrics
