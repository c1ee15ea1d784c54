"""Bad input, fuzzed: mutated scenario files, ``--set`` overrides and sweep files either run or are refused
with exit code 2 and a one-or-two-line message naming the field, no traceback, nothing written.

The mutations are the plain functions of bench/fuzz_inputs.py (loaded by path), driven here by Hypothesis;
``python bench/fuzz_inputs.py --cases 3000`` runs many more and tallies the outcomes per kind.
"""

from __future__ import annotations

import importlib.util
import itertools
import os
import random
import sys
import time
from pathlib import Path

import pytest
from conftest import ROOT, SCENARIOS
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

_spec = importlib.util.spec_from_file_location("fuzz_inputs", ROOT / "bench" / "fuzz_inputs.py")
FUZZ = importlib.util.module_from_spec(_spec)
sys.modules["fuzz_inputs"] = FUZZ  # dataclasses look their module up
_spec.loader.exec_module(FUZZ)

SCENARIO_BASES = FUZZ.scenario_bases()
SWEEP_BASES = FUZZ.sweep_bases()
#: kinds whose every mutant is invalid: each must be refused (the others may also be accepted)
ALWAYS_REFUSED = {
    "wrong_type",
    "unknown_key",
    "misspelt_key",
    "nan_inf",
    "nonpositive",
    "window_outside",
    "gains_out_of_range",
    "bad_waypoints",
    "invalid_utf8",
    "bad_design",
}
FUZZ_SETTINGS = settings(
    derandomize=True,
    max_examples=100,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
_counter = itertools.count()


@st.composite
def mutants(draw, kind: str, bases: list) -> object:
    """A mutant of one of ``bases`` by the named mutation kind (a named strategy per kind)."""
    base = draw(st.sampled_from(bases))
    return FUZZ.make(kind, draw(st.randoms(use_true_random=False)), base)


SCENARIO_MUTANTS = {kind: mutants(kind, SCENARIO_BASES) for kind in FUZZ.SCENARIO_KINDS}
SWEEP_MUTANTS = {kind: mutants(kind, SWEEP_BASES) for kind in FUZZ.SWEEP_KINDS}


def judged(mutant, tmp_path: Path, **options) -> str:
    """Judge ``mutant`` in a fresh folder; fail on anything but a run or a clean refusal."""
    outcome, detail = FUZZ.judge(mutant, tmp_path / f"case{next(_counter)}", **options)
    event(f"{mutant.kind}: {outcome}")
    assert outcome != "bad", detail
    if mutant.kind in ALWAYS_REFUSED:
        assert outcome == "refused", f"{mutant.kind} was accepted: {mutant.note}"
    return outcome


@pytest.mark.parametrize("kind", FUZZ.SCENARIO_KINDS)
@FUZZ_SETTINGS
@given(data=st.data())
def test_mutated_scenarios_validate_or_are_refused_cleanly(kind, data, tmp_path):
    judged(data.draw(SCENARIO_MUTANTS[kind]), tmp_path)


@pytest.mark.parametrize("kind", FUZZ.SWEEP_KINDS)
@settings(FUZZ_SETTINGS, max_examples=40)
@given(data=st.data())
def test_mutated_sweep_files_are_refused_before_any_cluster(kind, data, tmp_path):
    judged(data.draw(SWEEP_MUTANTS[kind]), tmp_path, sweep=True)


@pytest.mark.slow
def test_accepted_value_mutants_also_run(tmp_path):
    """The first three huge-value mutants that validate also run (shortened, each compiles: ~1-3 s) to exit
    code 0 or 1, or are refused cleanly: the simulation, metrics and figures survive what validation lets
    through."""
    rng, ran = random.Random(3), []
    for _ in range(200):
        mutant = FUZZ.make("huge", rng, rng.choice(SCENARIO_BASES))
        if "simulation" in mutant.note:
            continue  # the shortened run would override it
        outcome, detail = FUZZ.judge(mutant, tmp_path / f"case{next(_counter)}", run=True)
        assert outcome != "bad", detail
        if detail.startswith("run exit"):
            ran.append(mutant.note)
            if len(ran) == 3:
                break
    assert len(ran) == 3, ran


def test_the_bench_tally_has_no_bad_case(capsys, tmp_path):
    """The bench script's own loop, on a few cases of every kind: its table ends with 0 bad cases."""
    assert FUZZ.main(["--cases", "120", "--runs", "0", "--seed", "7", "--workdir", str(tmp_path)]) == 0
    table = capsys.readouterr().out
    last = next(line for line in table.splitlines() if line.startswith("| all | all |"))
    assert last.endswith("| 0 |") and "| 120 |" in last


# --- regressions: each of these was a traceback, a hang or a message without the field ---------------


def test_seed_beyond_int64_is_refused_not_a_traceback(tmp_path, cli):
    """simulation.seed = 2**63 validated, then jax.random.PRNGKey raised OverflowError in `ddtrack run`."""
    for args in (["--set", f"simulation.seed={2**63}"], ["--seed", str(2**63)]):
        code, out, err = cli("run", SCENARIOS / "circle.toml", *args, "--out", tmp_path / "out")
        assert (code, out) == (2, "") and err.startswith("error: simulation.seed: ")
        assert not (tmp_path / "out").exists()
    code, _, _ = cli("validate", SCENARIOS / "circle.toml", "--set", f"simulation.seed={2**63 - 1}")
    assert code == 0


@pytest.mark.parametrize(
    "override, field",
    [
        ("trajectory.center=[1e308, 0]", "trajectory.center[0]"),
        ("initial.pose=[0, 1e300, 0]", "initial.pose[1]"),
        ("trajectory.radius=1e308", "trajectory.radius"),
    ],
)
def test_huge_coordinates_are_refused(tmp_path, cli, override, field):
    """A centre of 1e308 m validated, ran, wrote metrics.json, then matplotlib's tick locator raised
    ("arange: cannot compute length") and left half a run folder; a start of 2**64 m raised LinAlgError."""
    code, out, err = cli("run", SCENARIOS / "circle.toml", "--set", override, "--out", tmp_path / "out")
    assert (code, out) == (2, "") and err.startswith(f"error: {field}: ") and len(err.splitlines()) == 1
    assert not (tmp_path / "out").exists()


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs named pipes")
def test_a_pipe_or_device_is_refused_not_read_forever(tmp_path, cli):
    """A waypoints file or scenario that is a pipe blocked forever; /dev/zero filled the memory."""
    (tmp_path / "points.csv").unlink(missing_ok=True)
    os.mkfifo(tmp_path / "points.csv")
    scenario = tmp_path / "case.toml"
    scenario.write_text((SCENARIOS / "waypoints.toml").read_text().replace("waypoints.csv", "points.csv"))
    started = time.perf_counter()
    code, out, err = cli("validate", scenario)
    assert (code, out) == (2, "") and err.startswith("error: trajectory.file: ") and "not a regular file" in err
    code, out, err = cli("validate", tmp_path / "points.csv")
    assert (code, out) == (2, "") and "not a regular file" in err
    if Path("/dev/zero").exists():
        code, out, err = cli("validate", "/dev/zero")
        assert (code, out) == (2, "") and "not a regular file" in err
    assert time.perf_counter() - started < 10


def test_a_file_over_64_mib_is_refused(tmp_path, cli):
    big = tmp_path / "big.toml"
    with big.open("wb") as f:
        f.truncate(64 * 2**20 + 1)  # sparse: nothing is written to the disk
    code, out, err = cli("validate", big)
    assert (code, out) == (2, "") and "larger than 64 MiB" in err


def test_a_bad_seed_count_in_a_sweep_names_seeds_count(tmp_path, cli):
    """seeds = {count = false} said 'seeds: Input should be a valid integer' (the union's int member)."""
    (tmp_path / "s.toml").write_bytes((SCENARIOS / "paper_line.toml").read_bytes())
    sweep = tmp_path / "sweep.toml"
    sweep.write_text('scenario = "s.toml"\nseeds = {start = 1, count = false}\n[grid]\n"robot.mass" = [9.0]\n')
    code, out, err = cli("sweep", sweep, "--out", tmp_path / "out")
    assert (code, out) == (2, "") and err.startswith("error: seeds.count: ")
    assert not (tmp_path / "out").exists()


def test_a_square_too_small_for_distinct_corners_is_refused(tmp_path, cli):
    """trajectory.side = 5e-324 validated, then `ddtrack run` raised ValueError ('point 1 repeats point 0')."""
    code, out, err = cli(
        "run", SCENARIOS / "paper_square.toml", "--set", "trajectory.side=5e-324", "--out", tmp_path / "out"
    )
    assert (code, out) == (2, "") and err.startswith("error: trajectory.side: ")
    assert not (tmp_path / "out").exists()
