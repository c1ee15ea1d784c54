"""The package stands alone: no user-facing text sends a user to files they do not have (the developers' SPEC or
DESIGN), every "model.md §x.y" citation lands on a section of docs/model.md, and every relative link in the README
and docs lands on a file and, with an anchor, on a heading."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import pytest
from conftest import ROOT

USER_FACING = [
    ROOT / "README.md",
    *sorted((ROOT / "docs").glob("*.md")),
    *sorted((ROOT / "src").rglob("*.py")),
    *sorted((ROOT / "examples").glob("*.py")),
    *sorted((ROOT / "scenarios").glob("*.toml")),
]
MARKDOWN = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def anchors(markdown: str) -> set[str]:
    """GitHub's heading anchors: lower case, punctuation dropped, spaces to hyphens."""
    found = set()
    for heading in re.findall(r"^#+ (.+)$", markdown, flags=re.M):
        slug = re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")
        found.add(slug)
    return found


def model_sections() -> set[str]:
    return set(re.findall(r"^#+ (\d+(?:\.\d+)?)[. ]", (ROOT / "docs" / "model.md").read_text(), flags=re.M))


@pytest.mark.parametrize("path", USER_FACING, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_citation_of_files_users_do_not_have(path):
    text = path.read_text()
    assert not re.search(r"\bSPEC\b|\bDESIGN \d|SPEC\.md|DESIGN\.md", text), path


def test_model_md_has_every_cited_section():
    sections = model_sections()
    assert {"0", "1", "2", "3", "4", "5", "6", "1.3", "2.4", "2.5", "3.6", "3.7", "4.4"} <= sections
    cited = {m for path in USER_FACING for m in re.findall(r"model(?:\.md)? §(\d+(?:\.\d+)?)", path.read_text())}
    assert cited and cited <= sections, cited - sections


@pytest.mark.parametrize("path", MARKDOWN, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_land(path):
    text = re.sub(r"```.*?```", "", path.read_text(), flags=re.S)  # code blocks hold no links
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"[a-z]+:", target):
            continue
        file, _, anchor = target.partition("#")
        linked = (path.parent / file).resolve() if file else path
        assert linked.exists(), f"{path.name}: {target}"
        if anchor and linked.suffix == ".md":
            assert anchor in anchors(linked.read_text()), f"{path.name}: {target}"


def test_the_guide_documents_velocity_command_plotting_and_completion():
    from ddtrack import plotting
    from ddtrack.controllers import VelocityCommand

    guide = (ROOT / "docs" / "guide.md").read_text()
    assert all(f"| `{field}` |" in guide for field in VelocityCommand._fields)
    public = [name for name in dir(plotting) if name.startswith("plot_")]
    assert public and all(f"`{name}(" in guide for name in public)
    assert "_DDTRACK_COMPLETE=bash_source ddtrack" in guide


def test_the_site_builds_strict(tmp_path):
    """`mkdocs build --strict` (README, "Documentation"): every page in the navigation, no broken link or anchor, no
    docstring the API reference cannot read; a warning fails it. Needs no network."""
    config = ROOT / "mkdocs.yml"
    built = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(config), "-d", str(tmp_path / "site")],
        capture_output=True,
        text=True,
        env=os.environ | {"NO_MKDOCS_2_WARNING": "1"},
        timeout=300,
    )
    assert built.returncode == 0, built.stderr[-4000:]
    api = (tmp_path / "site" / "api" / "runner" / "index.html").read_text()
    assert all(f'id="ddtrack.runner.{name}"' in api for name in ("run", "run_batch", "prepare"))
    assert 'id="ddtrack.studies.batches.monte_carlo"' in api
