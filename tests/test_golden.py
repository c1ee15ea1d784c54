"""Nothing the user sees moves: every shipped scenario x every controller, seed 0, against recorded metrics.

``tests/golden/metrics.json`` holds the metrics (``metrics.json`` of ``ddtrack run``: errors, effort, saturation,
grip, warnings, status) recorded before the plant and controller interfaces were redesigned (issue 14). Each
shipped scenario runs with its own controller over its whole length, and must track (mean e_tr under 0.2 m); with
every other controller it runs for its first 3 s (the NN-adaptive one with a 5 s, two-epoch identification), which
reaches every controller's code on every trajectory at a twentieth of the cost. A scenario a controller cannot run
is recorded with its refusal. Every number must agree to 1e-12 relative (or 1e-12 absolute, for values that are
zero up to rounding, such as the exact kinematic law's error on a straight leg). The numbers are XLA's, so they hold
for the JAX the file was recorded with (0.10.2): on another, a sampling controller amplifies the rounding (on JAX
0.8.0, mppi's final e_tr on paper_line moves in the 4th digit), and this test says where.

To record the file again, deliberately: ``python tests/test_golden.py`` (``python tests/test_golden.py NAME ...``
for only those scenarios), then say why in the commit.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import pytest
from conftest import simulate_unbatched

ROOT = Path(__file__).resolve().parents[1]
GOLDEN = ROOT / "tests" / "golden" / "metrics.json"
SHIPPED = sorted((ROOT / "scenarios").glob("*.toml"))
SHORT = ["simulation.duration=3", "simulation.metric_window=[0, 3]"]
SHORT_IDENTIFICATION = ["controller.identification_duration=5", "controller.epochs=2"]
TOLERANCE = 1e-12


def case_metrics(path: Path, controller: str | None) -> dict:
    """``metrics.json`` of the case, as ``ddtrack run`` writes it; ``controller`` None: the scenario's own, whole.

    The scenario's own case runs as ``ddtrack run`` runs it (row 0 of a batch of two). The 3 s cases of the other
    controllers run through the unbatched simulator (conftest.simulate_unbatched), whose program compiles about a
    quarter faster and traces three times faster. It rounds a few values differently in the last bit, and every
    metric still agrees with the record (made through the batch program) to 1e-12. That a run's bits are its batch
    row's is tests/test_determinism.py's to check, for every controller."""
    import ddtrack
    from ddtrack.errors import ConfigError
    from ddtrack.runner import prepare, run_record, run_setup

    overrides = []
    if controller is not None:
        overrides = [*SHORT, *(SHORT_IDENTIFICATION if controller == "nn_adaptive_backstepping" else [])]
    try:
        scenario = ddtrack.load_scenario(path, overrides=overrides, controller=controller)
        setup, draws = prepare(scenario, seed=0)  # refuses a controller whose commands the plant does not take
    except ConfigError as refused:
        return {"refused": str(refused)}
    result = run_setup(scenario, setup, draws) if controller is None else simulate_unbatched(scenario, setup, draws)
    return run_record(scenario, setup, result)[1]


# replay drives a plan of commands that no shipped scenario has: it has no case here (tests/test_replay.py runs it)
NOT_RECORDED = {"replay"}


def scenario_cases(path: Path) -> dict[str, dict]:
    from ddtrack.scenario import CONTROLLERS

    kinds = [kind for kind in CONTROLLERS if kind not in NOT_RECORDED]
    return {"own": case_metrics(path, None)} | {kind: case_metrics(path, kind) for kind in kinds}


def assert_same(recorded: object, now: object, where: str) -> None:
    if isinstance(recorded, dict) and isinstance(now, dict):
        assert sorted(recorded) == sorted(now), f"{where}: keys {sorted(recorded)} became {sorted(now)}"
        for key in recorded:
            assert_same(recorded[key], now[key], f"{where}.{key}")
    elif isinstance(recorded, list) and isinstance(now, list):
        assert len(recorded) == len(now), f"{where}: {recorded} became {now}"
        for i, (a, b) in enumerate(zip(recorded, now, strict=True)):
            assert_same(a, b, f"{where}[{i}]")
    elif isinstance(recorded, float) and isinstance(now, float | int) and not isinstance(now, bool):
        assert math.isclose(recorded, now, rel_tol=TOLERANCE, abs_tol=TOLERANCE), f"{where}: {recorded!r} -> {now!r}"
    else:
        assert recorded == now, f"{where}: {recorded!r} became {now!r}"


@pytest.mark.slow
@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.stem)
def test_every_shipped_scenario_and_controller_gives_its_recorded_metrics(path):
    recorded = json.loads(GOLDEN.read_text())[path.stem]
    now = json.loads(json.dumps(scenario_cases(path), allow_nan=False))  # as written to metrics.json
    assert now["own"]["status"] == "ok" and now["own"]["e_tr_mean"] < 0.2, now["own"]  # every shipped case tracks
    assert_same(recorded, now, path.stem)


def test_the_comparison_can_fail():
    """The tolerance is tight: a relative change of 1e-9 in one metric, a new warning, or a status fails it."""
    recorded = {"e_tr_mean": 0.05, "warnings": [], "status": "ok"}
    for changed in (
        {"e_tr_mean": 0.05 * (1 + 1e-9), "warnings": [], "status": "ok"},
        {"e_tr_mean": 0.05, "warnings": [{"code": "x"}], "status": "ok"},
        {"e_tr_mean": 0.05, "warnings": [], "status": "diverged"},
    ):
        with pytest.raises(AssertionError):
            assert_same(recorded, changed, "case")
    assert_same(recorded, {"e_tr_mean": 0.05 * (1 + 1e-13), "warnings": [], "status": "ok"}, "case")


if __name__ == "__main__":  # record the golden file (deliberately; see the module docstring)
    sys.path.insert(0, str(ROOT / "src"))
    import ddtrack

    ddtrack.enable_float64()  # as the test session does (conftest.py)
    names = set(sys.argv[1:])  # python tests/test_golden.py NAME ...: record only those scenarios, keep the rest
    unknown = names - {path.stem for path in SHIPPED}
    if unknown:
        sys.exit(f"no shipped scenario named {', '.join(sorted(unknown))}")
    golden = json.loads(GOLDEN.read_text()) if names else {}
    for path in SHIPPED:
        if not names or path.stem in names:
            golden[path.stem] = json.loads(json.dumps(scenario_cases(path), allow_nan=False))
    GOLDEN.parent.mkdir(exist_ok=True)
    GOLDEN.write_text(json.dumps(golden, indent=1, sort_keys=True) + "\n")
    print(f"wrote {GOLDEN.relative_to(ROOT)}: {sum(len(cases) for cases in golden.values())} cases")
