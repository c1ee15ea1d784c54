"""The README's commands do what the README says: its tour prints what it shows (every command the README shows runs,
in order, in a scratch folder, reduced where the full one takes minutes: tests/documented.py), and its documentation
site serves. Its first command, the install, is tests/test_install.py."""

from __future__ import annotations

import json
import os
import subprocess
import time
import urllib.request
from pathlib import Path

import pytest
from conftest import ROOT
from documented import BIN, DOCUMENTS, ELSEWHERE, REDUCED, documented, matches, options, run_tour, shown_commands


def test_the_command_finder_and_matcher():
    text = "x `ddtrack list plants` and `ddtrack run DIR`\n```console\n$ ddtrack a\nout 1\n$ ddtrack b\n```\n"
    text += "```bash\ndo this  # why\n# a comment\n```\n```toml\n$ no\n```\n"
    assert [(s.command, s.output) for s in shown_commands(text)] == [
        ("ddtrack a", ("out 1",)),
        ("ddtrack b", ()),
        ("do this", ()),
        ("ddtrack list plants", ()),
    ]
    assert matches("| a | ... | c |", "| a | b | x | c |") and not matches("| a | ... | c |", "| a | b |")
    assert options("ddtrack mc x -n 5 --vary=a --out d") == {"-n", "--vary", "--out"}


def test_every_documented_command_runs_in_ci_as_written_or_reduced():
    """The tables of tests/documented.py name only commands the documents show, and a reduced command is the
    documented one's command with the same options (smaller numbers, a shorter horizon through --set), or the part of
    it this machine can run (a completion script written, where no zsh or fish is installed to source it)."""
    shown = {(document, step.command) for document in DOCUMENTS for step in documented(document)}
    assert len(shown) > 40
    assert set(REDUCED) <= shown and set(ELSEWHERE) <= shown, (set(REDUCED) | set(ELSEWHERE)) - shown
    assert not set(REDUCED) & set(ELSEWHERE)
    for (_, command), reduced in REDUCED.items():
        same = reduced.split()[:2] == command.split()[:2] and options(command) <= options(reduced)
        assert same or reduced in command, reduced


@pytest.mark.slow
def test_the_readme_tour_prints_what_the_readme_shows(tmp_path):
    printed = run_tour("README.md", tmp_path)
    assert sum(1 for step, _ in printed if step.output) >= 5, "the tour shows the output of at least five commands"
    check_reproduce_folder(tmp_path / "runs" / "reproduce")
    assert (tmp_path / "runs" / "bench" / "leaderboard.md").is_file()


def check_reproduce_folder(out: Path) -> None:
    """What the tour's ``ddtrack reproduce`` wrote besides its table: the paired improvements, the CSV, the figures."""
    table = json.loads((out / "table1.json").read_text())
    assert table["seeds"] == 5 and set(table["cases"]) == {"paper_line", "paper_square"}
    for entry in table["cases"].values():
        bs, nn = entry["controllers"]["backstepping"], entry["controllers"]["nn_adaptive"]
        assert len(nn["e_tr_mean"]["values"]) == 5 and nn["e_tr_mean"]["ci_low"] <= nn["e_tr_mean"]["mean"]
        # the paired improvement is computed from the per-seed values
        paired = [100 * (b - n) / b for b, n in zip(bs["e_tr_mean"]["values"], nn["e_tr_mean"]["values"], strict=True)]
        assert entry["improvement"]["nn_adaptive"]["values"] == pytest.approx(paired)
        assert entry["paper"]["backstepping"] in (0.0547, 0.0976)
    rows = (out / "table1.csv").read_text().splitlines()
    assert rows[0] == "case,controller,statistic,mean,ci_low,ci_high,n,paper" and len(rows) == 1 + 2 * (4 + 4 + 1)
    figures = sorted(p.name for p in (out / "figures").iterdir())
    assert len(figures) == 8 and "paper_line_gains.png" in figures and "paper_square_path.png" in figures
    assert (out / "table1.md").read_text().startswith("# Table 1, reproduced (5 seeds")


def test_the_docs_site_serves():
    """``mkdocs serve`` (the README's documentation section) serves the site on 127.0.0.1; stopped once it has."""
    port = 18000 + (time.time_ns() // 1000) % 1000
    server = subprocess.Popen(
        [str(BIN / "mkdocs"), "serve", "--dev-addr", f"127.0.0.1:{port}", "--no-livereload"],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env=os.environ | {"NO_MKDOCS_2_WARNING": "1"},
    )
    try:
        deadline, page = time.monotonic() + 240, ""
        while time.monotonic() < deadline and server.poll() is None:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/guide/", timeout=5) as response:
                    page = response.read().decode()
                break
            except OSError:
                time.sleep(1)
        assert "ddtrack run SCENARIO" in page, server.stderr.read() if server.poll() is not None else "no page"
    finally:
        server.terminate()
        server.wait(timeout=30)
