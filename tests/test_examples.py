"""Every script in examples/ runs (as a user would run it, in a fresh interpreter) and prints what it promises.

A script may name its arguments for the test in a comment ``# test-args: ...`` (a shorter run). Each one
needs an entry in CHECKS, so a new example cannot go untested.
"""

from __future__ import annotations

import ast
import os
import re
import shlex
import subprocess
import sys

import pytest
from conftest import ROOT

EXAMPLES = sorted((ROOT / "examples").glob("*.py"))
NUMBER = r"([-+]?\d+(?:\.\d*)?)"


def number(pattern: str, text: str) -> list[float]:
    """The numbers captured by ``pattern`` (NUMBER groups) in ``text``; fails when it does not match."""
    found = re.search(pattern, text)
    assert found, f"{pattern!r} not in the output:\n{text}"
    return [float(group) for group in found.groups()]


def check_custom_controller(out: str) -> None:
    (baseline,) = number(rf"backstepping\s+status ok, e_tr_mean {NUMBER} m", out)
    (integral,) = number(rf"integral_kanayama\s+status ok, e_tr_mean {NUMBER} m", out)
    assert baseline == pytest.approx(0.046, abs=0.001)  # the paper's line case (README, SPEC 4.5)
    assert integral < baseline / 5  # the integral removes the friction-induced lag


def check_custom_trajectory(out: str) -> None:
    # at the crossing the lemniscate's speed is a w / sqrt(2), w = 2 pi / 60 s, a = 3 m; its yaw rate is 0
    speed, omega = number(rf"speed {NUMBER} m/s, yaw rate {NUMBER} rad/s", out)
    assert speed == pytest.approx(3 * 2 * 3.141592653589793 / 60 / 2**0.5, abs=5e-4) and omega == 0.0
    (error,) = number(rf"status ok, e_tr_mean {NUMBER} m", out)
    assert 0.0 < error < 0.1


def check_monte_carlo(out: str) -> None:
    mean, low, high = number(rf"6 of 6 runs ok; e_tr_mean {NUMBER} m, 95 % CI \[{NUMBER}, {NUMBER}\] m", out)
    assert low < mean < high and 0.03 < mean < 0.06
    (light,) = number(rf"low friction\s+\d+ runs, mean e_tr {NUMBER}", out)
    (heavy,) = number(rf"high friction\s+\d+ runs, mean e_tr {NUMBER}", out)
    assert light < heavy  # more unmodelled friction, more lag


def check_load_parquet(out: str) -> None:
    rows, end = number(rf"{NUMBER} rows x \d+ columns, t = 0 \.\. {NUMBER} s", out)
    assert rows == 4000 and end == pytest.approx(39.99)  # 40 s at T_c = 10 ms
    right, left, mean = number(rf"peak \|torque\|: right {NUMBER} N m, left {NUMBER} N m; e_tr_mean {NUMBER} m", out)
    assert 0 < right <= 10.0 and 0 < left <= 10.0  # the actuator limit, max_torque
    assert mean == pytest.approx(0.046, abs=0.001)


def check_random_agent(out: str) -> None:
    steps, seconds, final, total = number(
        rf"{NUMBER} steps \({NUMBER} s\), status ok, final e_tr {NUMBER} m, return {NUMBER}", out
    )
    assert steps == 200 and seconds == pytest.approx(2.0)
    # the same episode replayed here (same seeds, same sampled actions) ends where the example says it did
    import gymnasium

    env = gymnasium.make(
        "ddtrack.envs:ddtrack/DiffDriveTracking-v0",
        scenario=ROOT / "scenarios" / "paper_line.toml",
        action_mode="gains",
    )
    env.action_space.seed(0)
    env.reset(seed=0)
    replayed = 0.0
    for _ in range(200):
        _, reward, _, _, info = env.step(env.action_space.sample())
        replayed += reward
    env.close()
    assert final == pytest.approx(info["e_tr"], abs=5e-4) and total == pytest.approx(replayed, abs=0.05)


def check_identify_and_tune(out: str) -> None:
    """The summary it prints is the one docs/identification.md shows (the guide's numbers come from this run)."""
    summary = out[out.index("identified: lags") : out.index("every file is in")].strip().splitlines()
    guide = (ROOT / "docs" / "identification.md").read_text()
    for line in summary:
        assert line in guide, f"docs/identification.md does not show this line of the worked example:\n{line}"
    assert "| tuned | backstepping |" in out and "| default | backstepping |" in out  # compared by bench --scenario
    (delay,) = number(rf"command delay {NUMBER} s", out)
    assert delay == pytest.approx(0.05, abs=1e-3)  # the real robot's hidden latency, found to its model's error
    better, low, _ = number(rf"tuned over default: {NUMBER} \[{NUMBER}, {NUMBER}\] % lower", out)
    assert low > 0 and better > 0


CHECKS = {
    "identify_and_tune.py": check_identify_and_tune,
    "custom_controller.py": check_custom_controller,
    "custom_trajectory.py": check_custom_trajectory,
    "monte_carlo.py": check_monte_carlo,
    "load_parquet.py": check_load_parquet,
    "random_agent.py": check_random_agent,
}


def test_every_example_is_documented_and_checked():
    assert len(EXAMPLES) >= 4
    for path in EXAMPLES:
        assert ast.get_docstring(ast.parse(path.read_text())), f"{path.name} has no module docstring"
        assert path.name in CHECKS, f"examples/{path.name} has no check: add one to CHECKS in tests/test_examples.py"


@pytest.mark.slow
@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.name)
def test_example_runs(path, tmp_path, tmp_path_factory):
    # the README's install has no pandas (nor the test extra): an example that imports it fails here
    blocker = tmp_path_factory.mktemp("no_pandas")
    (blocker / "pandas").mkdir()
    (blocker / "pandas" / "__init__.py").write_text("raise ImportError('pandas is not part of the install')\n")
    env = os.environ | {"PYTHONPATH": os.pathsep.join(filter(None, (str(blocker), os.environ.get("PYTHONPATH"))))}
    env["TMPDIR"] = str(tmp_path_factory.mktemp("tmp"))  # an example's temporary folders: pytest cleans them
    args = re.search(r"^# test-args:(.*)$", path.read_text(), flags=re.M)
    command = [sys.executable, str(path), *(shlex.split(args.group(1)) if args else [])]
    done = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True, timeout=600, env=env)
    assert done.returncode == 0, f"{' '.join(command)} exited {done.returncode}:\n{done.stderr[-3000:]}"
    CHECKS[path.name](done.stdout)
    assert list(tmp_path.iterdir()) == []  # an example leaves nothing behind in the working folder
