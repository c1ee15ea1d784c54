"""A live drive's rows as a run folder (``ddtrack.ros.measured``): scored as ``ddtrack run`` scores a simulation."""

from __future__ import annotations

import numpy as np

import ddtrack
from ddtrack.ros.measured import MEASURED_POSE, measured_run
from ddtrack.shipped import scenario_path


def test_a_simulated_run_read_back_as_measured_rows_scores_the_same():
    """Rows made of a simulation's own states, references and commands give its columns and metrics back: the
    measured path and the simulated one compute the errors and metrics one way; the folder warns that its pose is
    measured."""
    scenario = ddtrack.load_scenario(
        scenario_path("burger_cmd_vel_figure8"),
        overrides=["simulation.duration=5", "simulation.metric_window=[0, 5]"],
    )
    simulated = ddtrack.timeseries(ddtrack.run(scenario))
    body = np.stack([simulated[name] for name in ("x", "y", "theta", "v", "omega")], axis=1)
    reference = np.stack([simulated[f"{name}_ref"] for name in ("x", "y", "theta", "v", "omega")], axis=1)
    rows = [
        (t, y, ref, v, w)
        for t, y, ref, v, w in zip(
            simulated["t"], body, reference, simulated["v_cmd"], simulated["omega_cmd"], strict=True
        )
    ]
    columns, metrics = measured_run(scenario, rows)
    for name in ("t", "x", "theta", "x_ref", "theta_ref", "e_x", "e_y", "e_tr", "v_cmd"):
        np.testing.assert_allclose(columns[name], simulated[name], rtol=0, atol=1e-12, err_msg=name)
    assert np.all(np.isnan(columns["tau_r"]))
    offline = ddtrack.summarize(
        simulated,
        status="ok",
        window=scenario.simulation.window,
        control_period=scenario.simulation.control_period,
        settling_threshold=scenario.simulation.settling_threshold,
    )
    assert abs(metrics["e_tr_mean"] - offline["e_tr_mean"]) <= 1e-12
    assert metrics["warnings"][0] == MEASURED_POSE
