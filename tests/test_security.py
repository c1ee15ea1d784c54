"""Security (issue 7, item 5): no pickle on results, scenario files cannot reach outside their folder, outputs stay
under the folder the user gave.

Checked elsewhere, not repeated here:

* the embedded Dask cluster listens on 127.0.0.1 only, every listening socket of the scheduler and the workers:
  tests/test_sweep.py::test_local_cluster_listens_on_loopback_only;
* the HTML report prints every string from user files as text (scenario name and description, waypoint file
  name, controller names as table rows and plot labels, in run, mc and bench folders, checked in the HTML, the
  SVG and a real browser): tests/test_report.py::test_every_user_string_stays_text.
"""

from __future__ import annotations

import ast
import os
import re
from pathlib import Path

import pytest
import tomli_w
from conftest import ROOT, SCENARIOS

from ddtrack.cli import folder_name
from ddtrack.errors import ConfigError
from ddtrack.scenario import load_scenario

PACKAGE = ROOT / "src" / "ddtrack"
UNSAFE_MODULES = {"pickle", "cPickle", "_pickle", "cloudpickle", "dill", "joblib", "shelve", "marshal"}
UNSAFE_CALLS = {"read_pickle", "to_pickle", "loads_pickle"}


def test_results_are_never_read_with_pickle():
    """Static: no module of the package imports a pickle-family module or calls a pickle reader, and every
    ``np.load`` passes ``allow_pickle=False``; results are Parquet and JSON only. (Dask pickles the sweep's tasks
    and their return values between its own processes on 127.0.0.1; that is Dask's transport, not ddtrack reading
    a result file: records are written and read back as JSON, sweep.write_record / sweep.read_records.)"""
    sources = sorted(PACKAGE.rglob("*.py"))
    assert len(sources) > 20
    for path in sources:
        tree = ast.parse(path.read_text(), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names = {alias.name.split(".")[0] for alias in node.names}
            elif isinstance(node, ast.ImportFrom):
                names = {(node.module or "").split(".")[0]} | {alias.name for alias in node.names}
            else:
                names = set()
            assert not names & UNSAFE_MODULES, f"{path.name}:{node.lineno} imports {names & UNSAFE_MODULES}"
            if isinstance(node, ast.Call):
                func = node.func
                name = func.attr if isinstance(func, ast.Attribute) else func.id if isinstance(func, ast.Name) else ""
                assert name not in UNSAFE_CALLS, f"{path.name}:{node.lineno} calls {name}"
                if name == "load" and isinstance(func, ast.Attribute) and ast.unparse(func.value) in ("np", "numpy"):
                    keywords = {k.arg: ast.unparse(k.value) for k in node.keywords}
                    assert keywords.get("allow_pickle") == "False", f"{path.name}:{node.lineno} np.load may unpickle"
    # the readers the package does use for results
    text = "\n".join(p.read_text() for p in sources)
    assert re.search(r"pq\.read_table\(", text) and "json.loads(" in text


def waypoint_scenario(folder: Path, file: str) -> Path:
    path = folder / "scenario.toml"
    path.write_text(
        tomli_w.dumps({"name": "w", "simulation": {"duration": 1.0}, "trajectory": {"kind": "waypoints", "file": file}})
    )
    return path


CSV = "x,y\n0,0\n1,1\n2,0\n"


@pytest.fixture
def outside(tmp_path) -> Path:
    """A readable CSV beside (not inside) the scenario's folder ``tmp_path / "scen"``."""
    (tmp_path / "scen").mkdir()
    secret = tmp_path / "secret.csv"
    secret.write_text(CSV)
    return secret


@pytest.mark.parametrize("how", ["absolute", "dotdot", "symlink", "symlinked_folder"])
def test_waypoints_file_cannot_leave_the_scenario_folder(tmp_path, outside, cli, how):
    folder = tmp_path / "scen"
    if how == "absolute":
        name = str(outside)
    elif how == "dotdot":
        name = "sub/../../secret.csv"
        (folder / "sub").mkdir()
    elif how == "symlink":
        name = "link.csv"
        os.symlink(outside, folder / name)
    else:
        name = "data/secret.csv"
        os.symlink(tmp_path, folder / "data")
    scenario = waypoint_scenario(folder, name)
    with pytest.raises(ConfigError) as raised:
        load_scenario(scenario)
    assert raised.value.field == "trajectory.file"
    assert "copy the CSV beside the scenario" in str(raised.value)
    out = tmp_path / "out"
    code, _, stderr = cli("run", scenario, "--out", out)
    assert code == 2 and stderr.startswith("error: trajectory.file: ") and "Traceback" not in stderr
    assert len(stderr.strip().splitlines()) <= 2 and not out.exists()


def test_waypoints_file_inside_the_folder_is_read(tmp_path):
    """A sub-folder, a harmless ``..`` and a symlink that stays inside are all fine (the shipped
    scenarios/waypoints.toml names a CSV beside it: tests/test_scenario.py)."""
    folder = tmp_path / "scen"
    (folder / "data").mkdir(parents=True)
    (folder / "data" / "path.csv").write_text(CSV)
    os.symlink(folder / "data" / "path.csv", folder / "link.csv")
    for name in ("data/path.csv", "data/../data/path.csv", "link.csv"):
        scenario = load_scenario(waypoint_scenario(folder, name))
        assert scenario.trajectory.points == [(0.0, 0.0), (1.0, 1.0), (2.0, 0.0)], name
    assert load_scenario(SCENARIOS / "waypoints.toml").trajectory.points is not None


@pytest.mark.parametrize(
    ("name", "folder"),
    [
        ("../../etc", "_.._etc"),
        ("a/b", "a_b"),
        ("/abs", "_abs"),
        ("..", "run"),
        (".hidden", "hidden"),
        ("paper_line", "paper_line"),
        ("<script>x</script>", "_script_x__script_"),
        ("é t", "__t"),
    ],
)
def test_folder_name_is_one_safe_component(name, folder):
    assert folder_name(name) == folder
    assert "/" not in folder and folder not in (".", "..", "")


def test_scenario_name_cannot_move_the_default_run_folder(tmp_path, cli, monkeypatch):
    """``ddtrack run`` without --out writes runs/NAME under the working folder; a name of ``../../escape`` stays
    inside runs/."""
    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    monkeypatch.chdir(work)
    data = {"name": "../../escape", "simulation": {"duration": 0.5}, "trajectory": {"kind": "line"}}
    (work / "s.toml").write_text(tomli_w.dumps(data))
    code, stdout, stderr = cli("run", "s.toml")
    assert code == 0, stderr
    assert (work / "runs" / "_.._escape" / "metrics.json").is_file()
    assert [p.name for p in tmp_path.iterdir()] == ["a"] and [p.name for p in (tmp_path / "a").iterdir()] == ["b"]
    assert "-> runs/_.._escape" in stdout
