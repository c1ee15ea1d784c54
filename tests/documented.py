"""The commands the documents show, found in the documents themselves, and how CI runs each one.

A command is a ``$ `` line of a ``console`` block, a line of a ``bash`` block, a line of an indented block in the
example plugin's README, or an inline ```ddtrack ...``` span of prose that is a whole command (no placeholder such as
``DIR`` or ``[--seeds N]``). Each runs in CI: as written (its shown output compared line by line, "..." standing for
any text), reduced (:data:`REDUCED`: the same command and options with smaller numbers, through the same parsing),
or by the test :data:`ELSEWHERE` names. tests/test_readme.py and tests/test_guide.py run the documents' tours; a
document's new command runs there unless it is listed here, so none can be left out.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from conftest import ROOT

BIN = Path(sys.executable).parent  # the venv's bin: ddtrack and python3 as the documents call them
DOCUMENTS = ("README.md", "docs/guide.md", "examples/plugin/README.md")
_PLACEHOLDER = re.compile(r"\b[A-Z][A-Z_0-9]*\b|\[|\.\.\.|\|")
_SHORT = '--set simulation.duration=4 --set "simulation.metric_window=[1, 4]"'

#: (document, command) -> the reduced command CI runs instead (the documented one takes minutes)
REDUCED = {
    (
        "README.md",
        "ddtrack mc scenarios/circle.toml -n 500 --vary mass=uniform:0.2 --vary inertia=normal:0.1 "
        "--out runs/mc_circle",
    ): "ddtrack mc scenarios/circle.toml -n 16 --vary mass=uniform:0.2 --vary inertia=normal:0.1 --out runs/mc_circle",
    ("README.md", "ddtrack bench --suite quick --out runs/bench"): "ddtrack bench --suite quick --out runs/bench "
    f"--controllers backstepping,kinematic_backstepping {_SHORT}",
    (
        "docs/guide.md",
        "ddtrack bench --suite quick --controllers backstepping,ltv_lqr,kinematic_backstepping "
        "--out runs/bench --workers 2",
    ): "ddtrack bench --suite quick --controllers "
    f"backstepping,ltv_lqr,kinematic_backstepping --out runs/bench --workers 2 {_SHORT}",
    ("docs/guide.md", "ddtrack animate runs/square_nn"): "ddtrack animate runs/square_nn --speed 20 --fps 10",
    # no zsh or fish here: their completion scripts are written, not sourced
    ("docs/guide.md", 'eval "$(_DDTRACK_COMPLETE=zsh_source ddtrack)"'): "_DDTRACK_COMPLETE=zsh_source ddtrack",
    ("docs/guide.md", "_DDTRACK_COMPLETE=fish_source ddtrack | source"): "_DDTRACK_COMPLETE=fish_source ddtrack",
}

_CI = ".ci/run runs it, exactly (tests/test_package.py::test_ci_runs_the_readme_test_command)"
_FIRST = "tests/test_install.py::test_the_readme_first_command_installs_and_runs_in_a_new_venv"
_PLUGIN = "tests/test_plugins.py::test_the_example_plugin_installs_and_runs_through_run_and_mc"
#: (document, command) -> the test that runs it
ELSEWHERE = {
    (
        "README.md",
        "python3 -m venv .venv && .venv/bin/pip install -q -e . && .venv/bin/ddtrack run scenarios/paper_line.toml",
    ): _FIRST,
    ("README.md", "python3 -m venv .venv && .venv/bin/pip install -q -e '.[test]' && scripts/check"): _CI,
    ("README.md", ".venv/bin/pip install -q -e '.[test]'"): _CI,
    (
        "README.md",
        ".venv/bin/mkdocs build --strict",
    ): "scripts/check, and tests/test_docs.py::test_the_site_builds_strict",
    ("README.md", ".venv/bin/mkdocs serve"): "tests/test_readme.py::test_the_docs_site_serves",
    ("docs/guide.md", "python3 -m venv .venv && .venv/bin/pip install -e ."): _FIRST,
    ("docs/guide.md", "ddtrack tune scenarios/paper_line.toml --seeds 2 --steps 10 --out runs/tune"): "the README's "
    "tour (tests/test_readme.py), the same command and output",
    ("docs/guide.md", "python examples/custom_controller.py"): "tests/test_examples.py, which checks its numbers",
    ("docs/guide.md", ".venv/bin/pip install -e '.[test]' && .venv/bin/python -m pytest"): _CI,
    ("examples/plugin/README.md", "pip install examples/plugin"): _PLUGIN,
    ("examples/plugin/README.md", "ddtrack list controllers"): _PLUGIN,
    ("examples/plugin/README.md", "ddtrack mc scenarios/paper_line.toml --controllers integral_kanayama -n 3"): _PLUGIN,
}


@dataclass(frozen=True)
class Shown:
    """A command as a document shows it, and the output it shows after it (none: not shown)."""

    command: str
    output: tuple[str, ...]


def shown_commands(text: str, indented: bool = False) -> list[Shown]:
    """Every command of a Markdown document (see the module's docstring), in order of appearance; prose spans last."""
    shown: list[Shown] = []
    for language, block in re.findall(r"```(\w*)\n(.*?)\n```", text, flags=re.S):
        current: list[str] | None = None
        for line in block.splitlines():
            if language == "console" and line.startswith("$ "):
                current = []
                shown.append(Shown(line[2:].strip(), ()))
            elif language == "console" and current is not None:
                shown[-1] = Shown(shown[-1].command, (*shown[-1].output, line))
            elif language == "bash" and line.strip() and not line.lstrip().startswith("#"):
                shown.append(Shown(re.sub(r"\s+#.*$", "", line).strip(), ()))
    prose = re.sub(r"```.*?```", "", text, flags=re.S)
    if indented:
        shown += [Shown(line.strip(), ()) for line in re.findall(r"^ {4}(\S.*)$", prose, flags=re.M)]
    for span in re.findall(r"`(ddtrack [^`]+)`", prose):
        words = span.split()
        if len(words) > 2 and not _PLACEHOLDER.search(" ".join(words[1:])):
            shown.append(Shown(span, ()))
    return shown


def documented(document: str) -> list[Shown]:
    """The commands ``document`` (relative to the project's root) shows."""
    return shown_commands((ROOT / document).read_text(), indented=document.endswith("plugin/README.md"))


def matches(expected: str, actual: str) -> bool:
    """``actual`` is the ``expected`` line, where "..." stands for any text."""
    pattern = ".*".join(re.escape(part) for part in expected.split("..."))
    return re.fullmatch(pattern, actual.rstrip()) is not None


def options(command: str) -> set[str]:
    """The option names a command line gives (``--out``, ``-n``)."""
    return {word.split("=")[0] for word in shlex.split(command) if re.match(r"--?[a-z]", word)}


def _readers_last(step: Shown) -> int:
    """Commands that read a run folder (animate, report) run after those that write one, wherever they are shown."""
    words = step.command.split()
    return int(len(words) > 1 and words[0] == "ddtrack" and words[1] in ("animate", "report"))


def run_tour(document: str, scratch: Path) -> list[tuple[Shown, str]]:
    """Run every command ``document`` shows that is not run :data:`ELSEWHERE`, as written or :data:`REDUCED`, in
    ``scratch`` (which sees the project's scenarios and examples), readers of run folders last. Each must exit 0
    (2 where its shown output is an error), and a command run as written must print what the document shows.
    Returns (command, what it printed) of each."""
    for name in ("scenarios", "examples"):
        (scratch / name).symlink_to(ROOT / name)
    (scratch / "docs").mkdir()
    env = os.environ | {"PATH": f"{BIN}{os.pathsep}{os.environ['PATH']}"}
    printed = []
    for step in sorted((s for s in documented(document) if (document, s.command) not in ELSEWHERE), key=_readers_last):
        command = REDUCED.get((document, step.command), step.command)
        done = subprocess.run(
            ["bash", "-c", command], cwd=scratch, env=env, capture_output=True, text=True, timeout=600
        )
        refused = bool(step.output) and step.output[0].startswith("error:")
        assert done.returncode == (2 if refused else 0), f"{document}: {command}\n{done.stderr[-3000:]}"
        if step.output and command == step.command:
            actual = (done.stderr if refused else done.stdout).rstrip("\n").splitlines()
            assert len(actual) == len(step.output), (
                f"{document}: {command}: shows\n" + "\n".join(step.output) + "\nit printed\n" + "\n".join(actual)
            )
            for want, got in zip(step.output, actual, strict=True):
                assert matches(want, got), f"{document}: {command}: shows\n{want}\nit printed\n{got}"
        printed.append((step, done.stdout))
    return printed
