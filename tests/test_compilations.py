"""A long-lived process releases its compiled programs before Linux's mapping limit (ddtrack.compilations): XLA
crashes in a compile at the limit, which a sweep's worker or a test session would otherwise reach."""

from __future__ import annotations

import sys

import jax
import jax.numpy as jnp
import pytest
from conftest import SCENARIOS

import ddtrack
from ddtrack import compilations
from ddtrack.runner import run

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="mapping counts are read from Linux's /proc")


def test_the_counts_are_read_from_the_system():
    with open("/proc/sys/vm/max_map_count") as limit:
        assert compilations.mapping_limit() == int(limit.read())
    held = compilations.memory_mappings()
    assert held is not None and 0 < held < compilations.mapping_limit()


def test_programs_are_released_only_past_the_share():
    program = jax.jit(lambda x: jnp.sin(x) * 3.0)
    program(jnp.ones(3))
    assert program._cache_size() == 1
    assert not compilations.release_compilations(share=1.0)  # a process at its limit could not compile
    assert program._cache_size() == 1
    assert compilations.release_compilations(share=0.0)
    assert program._cache_size() == 0
    assert float(program(jnp.zeros(3))[0]) == 0.0  # a released program compiles again when called


def test_a_distinct_run_holds_hundreds_of_mappings_and_releasing_returns_them():
    scenario = ddtrack.load_scenario(
        SCENARIOS / "paper_line.toml", overrides=["simulation.duration=0.3", "simulation.metric_window=[0, 0.3]"]
    )
    compilations.release_compilations(share=0.0)
    before = compilations.memory_mappings()
    run(scenario, seed=0)
    grown = compilations.memory_mappings() - before
    assert grown > 100  # why a process that compiles run after run reaches the limit
    compilations.release_compilations(share=0.0)
    assert compilations.memory_mappings() - before < 0.2 * grown


def test_a_sweep_task_releases_first(monkeypatch):
    import ddtrack.studies.tasks as tasks

    calls = []
    monkeypatch.setattr(tasks, "release_compilations", lambda: calls.append(1))
    monkeypatch.setattr(tasks, "prepare_batch", lambda *a, **k: (None, None))
    monkeypatch.setattr(tasks, "cells_rows", lambda cells, size: [[{"seed": 0, "status": "ok"}]])
    records = tasks.run_cells([(None, {}, [("key", 0)])], 2)
    assert calls == [1] and records[0]["status"] == "ok"
