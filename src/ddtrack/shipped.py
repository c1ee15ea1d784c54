"""The scenarios shipped with ddtrack, found both in a source checkout and in an installed wheel."""

from __future__ import annotations

from pathlib import Path


def scenario_path(name: str) -> Path:
    """A shipped scenario by name (``paper_line``, ``training``, ...): inside the installed package
    (``ddtrack/_scenarios``), or in the source checkout's ``scenarios/``."""
    here = Path(__file__).resolve().parent
    for folder in (here / "_scenarios", here.parents[1] / "scenarios"):
        if (folder / f"{name}.toml").is_file():
            return folder / f"{name}.toml"
    raise FileNotFoundError(f"shipped scenario {name}.toml not found beside the package")
