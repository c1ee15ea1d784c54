"""The code-quality checks CI runs (scripts/check) are live: each catches a planted mistake, and passes the fix.

A check that cannot fail proves nothing, so each tool is run here on a small file with one deliberate mistake, as
CI runs it (the project's own configuration in pyproject.toml), and must name that mistake; the corrected file
must pass. The package itself is checked by scripts/check, before the tests.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# A user's script calling the typed public API: the first call passes a path where a scenario belongs.
WRONG_CALL = """
    from pathlib import Path

    import ddtrack
    from ddtrack.outdir import atomic_write

    result = ddtrack.run(Path("scenarios/paper_line.toml"), seed=0)
    atomic_write(Path("out.txt"), "not a writer")
"""
RIGHT_CALL = """
    from pathlib import Path

    import ddtrack
    from ddtrack.outdir import atomic_write

    result = ddtrack.run(ddtrack.load_scenario(Path("scenarios/paper_line.toml")), seed=0)
    atomic_write(Path("out.txt"), lambda f: f.write(b"text"))
"""


def _tool(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", *args], cwd=cwd, capture_output=True, text=True, timeout=300)


def _write(folder: Path, source: str) -> Path:
    path = folder / "user_script.py"
    path.write_text(textwrap.dedent(source).lstrip())
    return path


def test_the_type_checker_catches_a_wrong_call_into_ddtrack(tmp_path):
    cache = tmp_path / "cache"
    if (ROOT / ".mypy_cache").is_dir():  # scripts/check's own mypy run, just before: 5 s of analysis saved
        shutil.copytree(ROOT / ".mypy_cache", cache)  # a copy: mypy re-checks any module whose source changed
    config = ["--config-file", str(ROOT / "pyproject.toml"), "--cache-dir", str(cache)]
    wrong = _tool("mypy", *config, str(_write(tmp_path, WRONG_CALL)), cwd=tmp_path)
    assert wrong.returncode == 1, wrong.stdout + wrong.stderr
    errors = [line for line in wrong.stdout.splitlines() if ": error:" in line]
    assert len(errors) == 2, wrong.stdout
    assert re.search(r':6: error: Argument 1 to "run" has incompatible type "Path"; expected "Scenario"', wrong.stdout)
    assert re.search(r':7: error: Argument 2 to "atomic_write" has incompatible type "str"', wrong.stdout)
    right = _tool("mypy", *config, str(_write(tmp_path, RIGHT_CALL)), cwd=tmp_path)
    assert right.returncode == 0, right.stdout + right.stderr


@pytest.mark.parametrize(
    ("source", "code"),
    [
        # a closure over a loop variable: every callback would see the last value (bugbear B023)
        ("callbacks = []\nfor i in range(3):\n    callbacks.append(lambda: i)\n", "B023"),
        # zip silently drops the tail of the longer input (B905)
        ("pairs = list(zip([1, 2], [3]))\n", "B905"),
        # an import nothing uses (pyflakes F401)
        ("import os\n", "F401"),
    ],
)
def test_the_linter_catches_a_planted_bug(tmp_path, source, code):
    path = tmp_path / "planted.py"
    path.write_text(source)
    found = _tool("ruff", "check", "--no-cache", "--config", str(ROOT / "pyproject.toml"), str(path), cwd=tmp_path)
    assert found.returncode == 1 and code in found.stdout, found.stdout + found.stderr


def test_ci_runs_every_check_before_the_tests():
    script = (ROOT / "scripts" / "check").read_text()
    steps = [line for line in script.splitlines() if '"$python" -m ' in line and not line.startswith("#")]
    tools = [line.split('"$python" -m ')[1].split()[0] for line in steps]
    assert tools == ["ruff", "ruff", "mypy", "mkdocs", "pytest"]
    assert "--strict" in steps[3] and "set -euo pipefail" in script  # a warning or any failing step fails CI


def test_type_checkers_see_every_lazily_loaded_public_name():
    """``import ddtrack`` loads its public names on first use; the TYPE_CHECKING block must name the same ones, from
    the same modules, or a user's type checker would see ``Any`` (or nothing) where ddtrack has a typed function."""
    import ast

    import ddtrack

    tree = ast.parse((ROOT / "src" / "ddtrack" / "__init__.py").read_text())
    block = next(node for node in tree.body if isinstance(node, ast.If) and ast.unparse(node.test) == "TYPE_CHECKING")
    seen = {alias.name: node.module for node in block.body if isinstance(node, ast.ImportFrom) for alias in node.names}
    assert seen == ddtrack._SOURCES
