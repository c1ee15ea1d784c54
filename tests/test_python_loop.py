"""bench/python_loop.py's plain-Python NN-adaptive loop simulates what ddtrack simulates (SPEC 3.8).

bench/speed.py times that loop against ddtrack only after checking it on the whole 40 s paper line case;
this is the fast version of the check: 2 s runs, states compared to 1e-8 (the benchmark's tolerance;
measured about 1e-14), from the paper's start (saturated clamps and torques, gate closed) and from near the
line with the gains free after 0.3 s (emulator training and the gain law at work every period).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import ddtrack
from ddtrack.runner import run_setup

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

from python_loop import params_from_nn_setup, run_nn_adaptive  # noqa: E402

SHORT = ["controller.identification=false", "simulation.duration=2.0", "simulation.metric_window=[0.0, 2.0]"]


@pytest.mark.parametrize(
    "overrides, adapts",
    [
        ([], False),
        (["initial.pose=[0.0, 0.3, 0.5]", "controller.freeze_time=0.3"], True),
    ],
    ids=["paper_start", "near_line"],
)
def test_python_nn_loop_matches_ddtrack(overrides, adapts):
    scenario = ddtrack.load_scenario(
        ROOT / "scenarios" / "paper_line.toml", controller="nn_adaptive_backstepping", overrides=SHORT + overrides
    )
    setup, draws = ddtrack.prepare(scenario)
    result = run_setup(scenario, setup, draws)

    python = np.asarray(run_nn_adaptive(**params_from_nn_setup(scenario, setup)))

    assert python.shape == np.shape(result.state) == (200, 5)
    assert np.max(np.abs(python - np.asarray(result.state))) <= 1e-8
    gains = np.stack([result.logs[name] for name in ("kx", "ky", "ktheta")], axis=1)
    assert np.any(gains[-1] != gains[0]) == adapts  # the near-line case exercises the gain law


def test_refuses_an_option_it_does_not_implement():
    scenario = ddtrack.load_scenario(
        ROOT / "scenarios" / "paper_line.toml",
        controller="nn_adaptive_backstepping",
        overrides=SHORT + ['controller.error_jacobian="paper"'],
    )
    with pytest.raises(ValueError, match="error_jacobian"):
        params_from_nn_setup(scenario, ddtrack.prepare(scenario)[0])
