"""The recorded heading and its reference are continuous the same way; only e_theta is wrapped."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import ddtrack
from ddtrack.sim import timeseries

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"


@pytest.mark.parametrize("name", ["paper_square", "figure_eight"])
def test_theta_and_theta_ref_are_unwrapped_alike(name):
    spec = ddtrack.load_scenario(SCENARIOS / f"{name}.toml")
    c = timeseries(ddtrack.run(spec))
    gap = c["theta_ref"] - c["theta"]
    # the gap between the two recorded headings is the (wrapped) heading error itself, never a 2 pi jump
    np.testing.assert_allclose(gap, c["e_theta"], atol=1e-9)
    assert np.max(np.abs(c["e_theta"])) <= np.pi
    # continuous: the square's corners turn the reference by pi/2 in one step, a wrap would jump by 2 pi
    assert np.max(np.abs(np.diff(c["theta_ref"]))) < np.pi / 2 + 1e-9
    assert np.max(np.abs(np.diff(c["theta"]))) < np.pi / 2
