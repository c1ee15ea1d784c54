"""The README's tour matches what the commands print: every ``$ ddtrack ...`` line of a ``console`` block that shows
output is run, in order, in a scratch folder, and its output compared line by line ("..." stands for any text)."""

from __future__ import annotations

import json
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT

DDTRACK = Path(sys.executable).with_name("ddtrack")  # the console script installed beside this interpreter


def tour_commands(readme: str) -> list[tuple[str, list[str]]]:
    """(command, expected output lines) of every ``$ ddtrack`` line in the README's console blocks."""
    steps: list[tuple[str, list[str]]] = []
    for block in re.findall(r"```console\n(.*?)\n```", readme, flags=re.S):
        for line in block.splitlines():
            if line.startswith("$ "):
                steps.append((line[2:], []))
            elif steps:
                steps[-1][1].append(line)
    return steps


def matches(expected: str, actual: str) -> bool:
    pattern = ".*".join(re.escape(part) for part in expected.split("..."))
    return re.fullmatch(pattern, actual.rstrip()) is not None


def test_the_tour_parser_and_matcher():
    steps = tour_commands("x\n```console\n$ ddtrack a\nout 1\n$ ddtrack b\n```\n```bash\n$ no\n```\n")
    assert steps == [("ddtrack a", ["out 1"]), ("ddtrack b", [])]
    assert matches("| a | ... | c |", "| a | b | x | c |") and not matches("| a | ... | c |", "| a | b |")


@pytest.mark.slow
def test_the_readme_tour_prints_what_the_readme_shows(tmp_path):
    (tmp_path / "scenarios").symlink_to(ROOT / "scenarios")
    steps = [(command, lines) for command, lines in tour_commands((ROOT / "README.md").read_text()) if lines]
    assert len(steps) >= 5, "the tour shows the output of at least five commands"
    for command, expected in steps:
        argv = shlex.split(command)
        assert argv[0] == "ddtrack", command
        done = subprocess.run([str(DDTRACK), *argv[1:]], cwd=tmp_path, capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, f"{command}\n{done.stderr}"
        actual = done.stdout.rstrip("\n").splitlines()
        assert len(actual) == len(expected), (
            f"{command}: README shows\n" + "\n".join(expected) + "\nit printed\n" + done.stdout
        )
        for want, got in zip(expected, actual, strict=True):
            assert matches(want, got), f"{command}: README shows\n{want}\nit printed\n{got}"
    check_reproduce_folder(tmp_path / "runs" / "reproduce")


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
