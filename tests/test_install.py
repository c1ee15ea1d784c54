"""The README's first command, exactly as written: a new virtual environment, ddtrack installed into it with its
dependencies (nothing of the test environment), and the paper's line run."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT
from documented import documented


@pytest.mark.slow
def test_the_readme_first_command_installs_and_runs_in_a_new_venv(tmp_path):
    """The README's first command, exactly, on a copy of the project: a new virtual environment (nothing of the test
    environment in it), the package installed with its dependencies, and the paper's line run."""
    (first, *_) = documented("README.md")
    assert first.command.startswith("python3 -m venv .venv && ") and "[test]" not in first.command
    project = tmp_path / "ddtrack"
    ignored = shutil.ignore_patterns(".venv", ".git", "runs", "site", "__pycache__", "*.egg-info", ".*cache")
    shutil.copytree(ROOT, project, ignore=ignored)
    python = Path(sys.base_prefix) / "bin" / "python3"  # the interpreter this venv was made from, not the venv
    command = first.command.replace("python3 ", f"{python} ", 1)
    done = subprocess.run(["bash", "-c", command], cwd=project, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.startswith("paper_line: backstepping on line, seed 0, 40 s -> runs/paper_line")
    assert "mean 0.0460 m" in done.stdout
    assert (project / "runs" / "paper_line" / "metrics.json").is_file()
    site = subprocess.run(
        [str(project / ".venv" / "bin" / "python"), "-c", "import sys; print(sys.prefix != sys.base_prefix)"],
        capture_output=True,
        text=True,
        check=True,
    )
    assert site.stdout.strip() == "True"
