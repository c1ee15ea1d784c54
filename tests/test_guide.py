"""The user guide's commands do what the guide says: every command it shows runs, in order, in a scratch folder
(readers of run folders after the commands that write them), reduced where the full one takes minutes, and those run
as written print what the guide shows (tests/documented.py)."""

from __future__ import annotations

import pytest
from conftest import ROOT
from documented import run_tour


@pytest.mark.slow
def test_the_guide_s_commands_print_what_the_guide_shows(tmp_path):
    printed = run_tour("docs/guide.md", tmp_path)
    commands = [step.command for step, _ in printed]
    assert "ddtrack sweep examples/sweep.toml --out runs/sweep --workers 2" in commands
    assert sum(1 for step, _ in printed if step.output) >= 10
    # the schema's Markdown, as the guide writes it, is the reference page the site publishes
    assert (tmp_path / "docs" / "reference.md").read_text() == (ROOT / "docs" / "reference.md").read_text()
    assert (tmp_path / "runs" / "bench" / "leaderboard.md").is_file()
    assert (tmp_path / "runs" / "square_nn" / "animation.gif").is_file()


def test_the_guide_shows_the_sweep_file_it_runs():
    import re

    guide = (ROOT / "docs" / "guide.md").read_text()
    (block,) = [b for b in re.findall(r"```toml\n(.*?)\n```", guide, flags=re.S) if b.startswith("scenario = ")]
    shipped = (ROOT / "examples" / "sweep.toml").read_text()
    assert shipped.rstrip("\n").endswith(block) and "examples/sweep.toml" in guide
