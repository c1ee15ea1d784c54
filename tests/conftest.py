"""Shared fixtures: paths of the shipped scenarios and a helper that runs the CLI in-process."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import ddtrack  # noqa: F401  (turns on float64 before any test builds an array)
from ddtrack.cli import main

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "scenarios"


def central_difference(f, x: np.ndarray, h: float) -> np.ndarray:
    """d f / d x by central differences, one column per component of ``x``."""
    columns = []
    for j in range(x.size):
        step = np.zeros_like(x)
        step[j] = h
        columns.append((np.asarray(f(x + step)) - np.asarray(f(x - step))) / (2 * h))
    return np.stack(columns, axis=-1)


@pytest.fixture
def cli(capsys):
    """Run ``ddtrack ARGS`` in-process; return (exit code, stdout, stderr)."""

    def invoke(*args: str) -> tuple[int, str, str]:
        code = main([str(a) for a in args])
        out, err = capsys.readouterr()
        return code, out, err

    return invoke
