"""bench/control_loop.py: python-control's simulation of the paper line case is the same closed loop as
ddtrack's, at least as accurate (skipped without python-control: pip install -e '.[bench]')."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("control")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))

import control_loop
from python_loop import params_from_scenario


def test_python_control_loop_matches_ddtrack_over_the_transient():
    # the first 2 s hold the saturated transient, where ddtrack's RK4 error is largest (3.1e-4 at 0.67 s)
    scenario = control_loop.paper_line(duration=2.0)
    params = params_from_scenario(scenario)
    states = control_loop.simulate(params)
    ddtrack_states = control_loop.ddtrack_states(scenario)
    truth = control_loop.reference(params)

    assert states.shape == ddtrack_states.shape == (200, 5)
    # both are within ~3e-4 of the reference, so within 1e-3 of each other; a modelling difference
    # (a missing friction term, an unheld disturbance, a clamp) shows at 1e-2 or more
    assert np.max(np.abs(states - ddtrack_states)) <= 1e-3
    # "matching accuracy": the chosen solver tolerances are no less accurate than ddtrack's fixed RK4
    assert np.max(np.abs(states - truth)) <= np.max(np.abs(ddtrack_states - truth))
