"""``ddtrack report``: one self-contained page per result folder, checked in a real headless Chromium (Debian's
``chromium``, driven by Playwright): it loads offline without console errors or requests, every figure has a size,
the tables hold the folder's numbers, and strings from user files stay text (never markup, never script)."""

from __future__ import annotations

import importlib.util
import json
import os
import re
import shutil
import subprocess
import tomllib
from html.parser import HTMLParser
from pathlib import Path

import browser
import numpy as np
import pytest
import tomli_w
from conftest import SCENARIOS

from ddtrack.cli import main
from ddtrack.errors import RunError
from ddtrack.report import KINDS, decimate, detect_kind, environment, render, write_report

SHORT = ["simulation.duration=4", "simulation.metric_window=[1, 4]", "initial.pose=[0, 0.3, 0]"]
SCRIPT = "<script>alert(1)</script>"
ONERROR = '"onerror=alert(1)'
PAYLOAD = f"{SCRIPT} x{ONERROR} <img src=x onerror=alert(2)>"
MAX_REPORT_BYTES = 2_000_000  # a page to open from a mail or a CI artifact, not a data dump


def _sets(*overrides: str) -> list[str]:
    return [arg for override in overrides for arg in ("--set", override)]


def _nn_scenario(folder: Path) -> Path:
    """paper_line, short, starting near the line, NN-adaptive without the (slow) identification: switching to
    backstepping (mc --controllers) drops the NN-only keys."""
    data = tomllib.loads((SCENARIOS / "paper_line.toml").read_text())
    data["controller"] = {"kind": "nn_adaptive_backstepping", "identification": False}
    data["simulation"] |= {"duration": 4.0, "metric_window": [1.0, 4.0]}
    data["initial"]["pose"] = [0.0, 0.3, 0.0]
    path = folder / "nn_line.toml"
    path.write_text(tomli_w.dumps(data))
    return path


# --- folders of every kind ------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory):
    """A short NN-adaptive run (its gains move) and its report."""
    base = tmp_path_factory.mktemp("report_run")
    out = base / "run"
    assert main(["run", str(_nn_scenario(base)), "--out", str(out)]) == 0
    assert main(["report", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def mc_folder(tmp_path_factory):
    base = tmp_path_factory.mktemp("report_mc")
    out = base / "mc"
    assert (
        main(
            [
                "mc",
                str(_nn_scenario(base)),
                "-n",
                "4",
                "--controllers",
                "backstepping,nn_adaptive_backstepping",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    assert main(["report", str(out)]) == 0
    return out


TINY_CONTROLLERS = ["backstepping", "backstepping_tuned"]


@pytest.fixture(scope="module")
def bench_folder(tmp_path_factory):
    """A tiny finished bench suite (the real runner on an in-process Dask cluster; tuned gains given)."""
    from distributed import Client, LocalCluster

    from ddtrack.studies.suite import Suite, run_suite

    out = tmp_path_factory.mktemp("report_bench")
    (out / "tuned.toml").write_text('[controller]\nkind = "backstepping"\ngains = [2.0, 80.0, 20.0]\n')  # no tuning
    suite = Suite(
        trajectories=("line", "circle"),
        levels=("paper",),
        seeds=2,
        robustness_mass=(1.0, 1.5),
        robustness_friction=(1.0, 3.0),
        tune_steps=1,
        overrides=tuple(SHORT[:2]),
    )
    with (
        LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster,
        Client(cluster) as client,
    ):
        run_suite(suite, TINY_CONTROLLERS, out, client)
    write_report(out)
    return out


@pytest.fixture(scope="module")
def reproduce_folder(tmp_path_factory):
    """A reproduce folder from the real Table 1 code on made-up per-seed metrics (running both paper cases takes
    half a minute; ``ddtrack reproduce`` itself is tested in test_cli), with PNG figures beside it."""
    import matplotlib.pyplot as plt

    from ddtrack.scenario import load_scenario
    from ddtrack.shipped import scenario_path
    from ddtrack.studies.reproduce import CASES, CaseResult, summarise_case

    out = tmp_path_factory.mktemp("report_reproduce")
    cases = {}
    for k, name in enumerate(CASES):
        case = CaseResult(scenario=load_scenario(scenario_path(name)))
        for variant, level in (("backstepping", 0.05), ("nn_adaptive", 0.02)):
            case.metrics[variant] = [
                {
                    "status": "ok",
                    "e_tr_mean": level * (1 + 0.1 * s + 0.05 * k),
                    "e_tr_rms": level * 1.1,
                    "e_tr_max": level * 2,
                    "settling_time": 6.0 + s,
                    "final_gains": [1.0 + s, 55.0, 15.0],
                }
                for s in range(3)
            ]
        cases[name] = summarise_case(name, case)
    table = {"seeds": 3, "ablations": False, "cases": cases, "elapsed_s": 1.0}
    (out / "table1.json").write_text(json.dumps(table, indent=2))
    (out / "figures").mkdir()
    for name in CASES:
        fig, ax = plt.subplots(figsize=(4, 3))
        ax.plot([0, 1], [0, 1])
        fig.savefig(out / "figures" / f"{name}_path.png", dpi=60)
        plt.close(fig)
    write_report(out)
    return out


# --- the page, parsed ----------------------------------------------------------------------------------------


class Page(HTMLParser):
    """Elements, attributes and text of a page, as a browser's tokenizer sees them."""

    def __init__(self, html: str) -> None:
        super().__init__(convert_charrefs=True)
        self.tags: list[str] = []
        self.attributes: list[tuple[str, str, str | None]] = []
        self.text: list[tuple[str, str]] = []  # (enclosing tag, text)
        self.ids: list[str] = []
        self._open: list[str] = []
        self.feed(html)

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)
        self.attributes += [(tag, name, value) for name, value in attrs]
        self.ids += [value for name, value in attrs if name == "id"]
        self._open.append(tag)

    def handle_endtag(self, tag):
        if tag in self._open:
            while self._open.pop() != tag:
                pass

    def handle_data(self, data):
        self.text.append((self._open[-1] if self._open else "", data))

    def rows(self, table_id: str, html: str) -> int:
        match = re.search(rf'<table id="{re.escape(table_id)}">.*?</table>', html, flags=re.S)
        assert match, f"no table {table_id}"
        return len(re.findall(r"<tr>", match.group(0).split("<tbody>")[1]))


def _assert_self_contained(html: str) -> Page:
    page = Page(html)
    assert "script" not in page.tags and not [a for a in page.attributes if a[1].startswith("on")]
    for tag, name, value in page.attributes:  # nothing to fetch: same-page anchors and data: images only
        if name in ("src", "href", "xlink:href", "action", "poster"):
            assert value.startswith(("#", "data:image/png;base64,")), (tag, name, value)
    assert not re.search(r"url\((?!#)|@import|@font-face", html)
    assert len(page.ids) == len(set(page.ids)), "ids repeat: two inline SVGs would share clip paths"
    for reference in re.findall(r'(?:href="#|url\(#)([^")]+)', html):
        assert reference in page.ids, reference
    assert len(html.encode()) < MAX_REPORT_BYTES
    return page


# --- the browser ---------------------------------------------------------------------------------------------


@pytest.fixture(scope="session")
def chromium(tmp_path_factory):
    """Debian's chromium under Playwright; installed by apt when missing (as root). Missing and not installable:
    a failure where CI is set, a skip elsewhere."""
    reason = browser.ensure_chromium()
    if reason is None and importlib.util.find_spec("playwright") is None:
        reason = "the playwright package is missing: pip install -e '.[test]'"
    if reason is not None:
        if os.environ.get("CI"):
            pytest.fail(f"browser tests need chromium: {reason}")
        pytest.skip(f"browser tests need chromium: {reason}")
    with browser.chromium_context(tmp_path_factory.mktemp("chromium-profile")) as context:
        yield context


def _load(chromium, html: Path, screenshot: Path):
    """Open the report; assert a clean load and that every figure has a size; save a full-page screenshot."""
    page, log = browser.open_page(chromium, html)
    assert log.console_errors == [] and log.page_errors == [], (log.console_errors, log.page_errors)
    assert log.dialogs == [] and log.requests == [], (log.dialogs, log.requests)
    graphics = page.evaluate(browser.GRAPHICS_JS)
    assert graphics, "no figure on the page"
    for g in graphics:
        assert g["width"] > 50 and g["height"] > 50 and g["decoded"], g
    page.screenshot(path=str(screenshot), full_page=True)
    assert screenshot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    return page, graphics


def _rows(page, table_id: str) -> int:
    return page.locator(f"table#{table_id} tbody tr").count()


# --- tests ---------------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_run_report_in_chromium(run_folder, chromium, tmp_path):
    html = run_folder / "report.html"
    metrics = json.loads((run_folder / "metrics.json").read_text())
    scenario = tomllib.loads((run_folder / "scenario.toml").read_text())
    _assert_self_contained(html.read_text())
    page, graphics = _load(chromium, html, browser.screenshot_path(tmp_path, "report_run.png"))
    figures = {g["id"] for g in graphics}
    assert {"fig-path", "fig-states", "fig-errors", "fig-torques", "fig-gains"} <= figures  # the gains moved
    assert _rows(page, "metrics-table") == len(metrics) - 1  # every key but final_gains, which has its own table
    assert _rows(page, "gains-table") == 3
    finals = page.locator("table#gains-table tbody tr td:nth-child(3)").all_inner_texts()
    assert [float(v) for v in finals] == pytest.approx(metrics["final_gains"], rel=5e-4)  # 4 significant digits
    sections = [k for k, v in scenario.items() if isinstance(v, dict)]
    assert page.locator("section#scenario table").count() == len(sections) + 1  # plus the top-level keys
    assert page.locator("h1").inner_text() == scenario["name"]
    mean = page.locator("table#metrics-table tbody tr", has_text="mean e_tr").locator("td").nth(1).inner_text()
    assert float(mean) == pytest.approx(metrics["e_tr_mean"], rel=5e-4)


@pytest.mark.slow
def test_mc_report_in_chromium(mc_folder, chromium, tmp_path):
    html = mc_folder / "report.html"
    summary = json.loads((mc_folder / "summary.json").read_text())
    _assert_self_contained(html.read_text())
    page, graphics = _load(chromium, html, browser.screenshot_path(tmp_path, "report_mc.png"))
    assert {"fig-etr", "fig-improvement", "fig-final-gains"} <= {g["id"] for g in graphics}
    assert _rows(page, "mc-table") == 2 and _rows(page, "improvement-table") == 1
    assert _rows(page, "runs-table") == 2 * 4
    gain = summary["improvement"]["nn_adaptive_backstepping"]["mean"]
    shown = page.locator("table#improvement-table tbody td").nth(2).inner_text().split()[0]
    assert float(shown) == pytest.approx(gain, rel=5e-3)


@pytest.mark.slow
def test_bench_report_in_chromium(bench_folder, chromium, tmp_path):
    html = bench_folder / "report.html"
    board = json.loads((bench_folder / "leaderboard.json").read_text())["leaderboard"]
    _assert_self_contained(html.read_text())
    page, graphics = _load(chromium, html, browser.screenshot_path(tmp_path, "report_bench.png"))
    assert {"fig-distributions", "fig-robustness"} <= {g["id"] for g in graphics}
    assert _rows(page, "leaderboard-table") == len(TINY_CONTROLLERS)
    names = page.locator("table#leaderboard-table tbody td:nth-child(2)").all_inner_texts()
    assert names == [e["controller"] for e in board]  # in the leaderboard's order (ranked)
    assert _rows(page, "cells-table") == len(TINY_CONTROLLERS)
    assert page.locator("table#cells-table thead th").count() == 1 + 2  # controller, line / paper, circle / paper


def test_reproduce_report_shows_table_1_beside_the_paper(reproduce_folder, chromium, tmp_path):
    from ddtrack.studies.reproduce import PAPER_TABLE

    html = (reproduce_folder / "report.html").read_text()
    _assert_self_contained(html)
    page, graphics = _load(
        chromium, reproduce_folder / "report.html", browser.screenshot_path(tmp_path, "report_reproduce.png")
    )
    assert [g["tag"] for g in graphics].count("img") == 2 and "fig-table1" in {g["id"] for g in graphics}
    assert _rows(page, "table1") == 4  # two cases x two controllers
    cells = page.locator("table#table1 tbody tr").all()
    for row, (case, variant) in zip(
        cells, [(c, v) for c in PAPER_TABLE for v in ("backstepping", "nn_adaptive")], strict=True
    ):
        texts = row.locator("td").all_inner_texts()
        assert texts[1] == variant and float(texts[3]) == PAPER_TABLE[case][variant]
    assert _rows(page, "gains-table") == 2 * 3  # the NN controller's final gains, per case and seed


@pytest.mark.slow
def test_every_user_string_stays_text(tmp_path, chromium):
    """Names, descriptions, labels and file names holding markup are printed as text: no element, no attribute,
    no script comes out of them, in the HTML or in the SVG matplotlib draws; in the browser, no dialog opens and
    the text is there to read."""
    run = _payload_run(tmp_path)
    mc = _payload_mc(tmp_path)
    bench = _payload_bench(tmp_path)
    for folder in (run, mc, bench):
        html = render(folder)
        page = _assert_self_contained(html)
        assert SCRIPT not in html  # the payload's tags, escaped (&lt;script&gt;) wherever they are printed
        assert "<img src=x" not in html
        texts = {tag for tag, text in page.text if PAYLOAD in text}
        assert "td" in texts or "h1" in texts, texts  # in a table cell or the title, as text
        if folder in (mc, bench):  # drawn by matplotlib (tick labels, titles; shortened): SVG <text>, escaped
            assert any(tag == "text" and text.startswith(SCRIPT) for tag, text in page.text)
        out = tmp_path / f"{folder.name}.html"
        out.write_text(html)
        browser_page, log = browser.open_page(chromium, out)
        assert log.dialogs == [] and log.page_errors == [] and log.console_errors == []
        assert browser_page.evaluate("document.scripts.length") == 0
        assert browser_page.evaluate("document.querySelectorAll('img:not([src^=\"data:\"])').length") == 0
        assert PAYLOAD in browser_page.locator("main").inner_text()
        browser_page.screenshot(
            path=str(browser.screenshot_path(tmp_path, f"report_escaping_{folder.name}.png")), full_page=True
        )
    toml = render(run)
    assert "&lt;script&gt;alert(1)&lt;/script&gt; x&#34;onerror=alert(1)" in toml  # file name, in the TOML <pre>
    assert environment().autoescape is True
    assert "|safe" not in (Path(__file__).parents[1] / "src/ddtrack/templates/report.html.j2").read_text()


def _payload_run(tmp_path: Path) -> Path:
    """A real run whose scenario name, description and waypoint file carry the payload; the stored scenario then
    edited by hand to name the file (a resolved scenario holds the points inline)."""
    folder = tmp_path / "scenario"
    folder.mkdir()
    csv = folder / f"{SCRIPT}{ONERROR}.csv"  # '/' in '</script>' makes a sub-folder: fine, it is a path
    csv.parent.mkdir(parents=True, exist_ok=True)
    csv.write_text("x,y\n0,0\n1,1\n2,0\n")  # not flat: rundir's path figure fails on a flat path with a long title
    scenario = folder / "payload.toml"
    scenario.write_text(
        tomli_w.dumps(
            {
                "name": PAYLOAD,
                "description": PAYLOAD,
                "simulation": {"duration": 2.0, "metric_window": [0.0, 2.0]},
                "trajectory": {"kind": "waypoints", "file": f"{SCRIPT}{ONERROR}.csv", "speed": 0.5},
                "controller": {"kind": "backstepping"},
            }
        )
    )
    out = tmp_path / "run"
    assert main(["run", str(scenario), "--out", str(out)]) == 0
    stored = tomllib.loads((out / "scenario.toml").read_text())
    stored["trajectory"]["file"] = f"{SCRIPT}{ONERROR}"
    (out / "scenario.toml").write_text(tomli_w.dumps(stored))
    return out


def _payload_mc(tmp_path: Path) -> Path:
    """An mc folder written by the real writer, whose controllers carry the payload (a hand-made folder: a
    controller's name must be registered to run)."""
    from ddtrack.studies import mc

    def row(seed: int, error: float, gains: list[float] | None) -> dict:
        return {
            "seed": seed,
            "status": "ok",
            "window": [0.0, 2.0],
            "e_tr_mean": error,
            "e_tr_rms": error,
            "e_tr_max": 2 * error,
            "e_tr_final": error,
            "settling_time": 1.0,
            "effort": 3.0,
            "saturation_fraction": 0.0,
            "final_gains": gains,
            "warnings": [{"code": "c", "message": PAYLOAD}],
        }

    rows = {
        "backstepping": [row(s, 0.05, [1.0, 55.0, 15.0]) for s in range(3)],
        PAYLOAD: [row(s, 0.02 + 0.001 * s, [2.0 + s, 50.0, 10.0]) for s in range(3)],
    }
    out = tmp_path / "mc"
    mc.write(out, rows, mc.summarise(rows))
    return out


def _payload_bench(tmp_path: Path) -> Path:
    """A bench folder from the real record, results and leaderboard code, with payloads in the controller, the
    trajectory and the level labels."""
    from ddtrack.studies.suite import leaderboard
    from ddtrack.studies.sweep import write_results

    records = []
    for c, controller in enumerate(("backstepping", PAYLOAD)):
        for seed in range(2):
            labels = {"study": "leaderboard", "trajectory": PAYLOAD, "level": PAYLOAD}
            metrics = {
                "status": "ok",
                "window": [0.0, 2.0],
                "e_tr_mean": 0.05 / (c + 1) + 0.001 * seed,
                "e_tr_rms": 0.05,
                "e_tr_max": 0.1,
                "e_tr_final": 0.05,
                "settling_time": 1.0,
                "effort": 2.0,
                "saturation_fraction": 0.0,
            }
            records.append(
                {
                    "key": f"{c}{seed}",
                    "configuration": {"controller": controller, "labels": labels, "overrides": {"overrides": []}},
                    "seed": seed,
                    "status": "ok",
                    "metrics": metrics,
                    "error": None,
                }
            )
    out = tmp_path / "bench"
    out.mkdir()
    write_results(out, records)
    board = leaderboard({r["key"]: r for r in records}, ["backstepping", PAYLOAD])
    summary = {
        "suite": {"trajectories": [PAYLOAD]},
        "controllers": ["backstepping", PAYLOAD],
        "tuned_gains": None,
        "runs": 4,
        "reused": 0,
        "errors": 0,
        "not_ok": 0,
        "leaderboard": board,
    }
    (out / "leaderboard.json").write_text(json.dumps(summary))
    return out


def test_identification_is_reported_when_the_folder_has_it(tmp_path):
    """A run with the emulator's pre-training (identification.json, as `ddtrack run` writes it) gets a section
    with its loss curve."""
    out = tmp_path / "run"
    assert main(["run", str(SCENARIOS / "paper_line.toml"), *_sets(*SHORT), "--out", str(out)]) == 0
    losses = [1e-3 * 0.7**k for k in range(12)]
    (out / "identification.json").write_text(
        json.dumps(
            {
                "samples": 400,
                "epochs": 12,
                "epoch_loss": losses,
                "nmse": {"forward": 0.01, "lateral": 0.02, "yaw": 0.03},
            }
        )
    )
    html = render(out)
    page = Page(html)
    assert "fig-identification" in page.ids and page.rows("identification-table", html) == 2 + 1 + 3
    assert "fig-gains" not in page.ids  # backstepping's gains stay put: no gains figure
    assert page.rows("gains-table", html) == 3


@pytest.mark.parametrize("kind", list(KINDS))
def test_the_kind_is_read_from_the_files(tmp_path, kind):
    for name in KINDS[kind]:
        (tmp_path / name).write_text("")
    assert detect_kind(tmp_path) == kind


def test_a_folder_of_no_kind_is_refused_with_what_was_expected(tmp_path, cli):
    (tmp_path / "metrics.json").write_text("{}")
    code, out, err = cli("report", tmp_path)
    assert code == 2 and out == "" and "Traceback" not in err
    assert "lacks scenario.toml, timeseries.parquet" in err  # looks like a run folder
    for files in KINDS.values():
        assert ", ".join(files) in err
    code, _, err = cli("report", tmp_path / "missing")
    assert code == 2 and "is not a folder" in err
    for name in KINDS["mc"]:
        (tmp_path / name).write_text("not json")
    with pytest.raises(RunError, match="cannot read"):
        render(tmp_path)
    assert not (tmp_path / "report.html").exists()


def test_report_command_writes_the_page_atomically_where_asked(run_folder, tmp_path, cli):
    target = tmp_path / "out" / "page.html"
    code, out, err = cli("report", run_folder, "--out", target)
    assert code == 0 and out.strip() == f"wrote {target}" and err == ""
    assert target.read_text().startswith("<!DOCTYPE html>")
    assert [p.name for p in target.parent.iterdir()] == ["page.html"]  # no temporary left behind
    code, _, err = cli("report", run_folder, "--out", tmp_path)
    assert code == 2 and "is a folder" in err


def test_decimation_keeps_every_extreme_and_both_ends():
    t = np.linspace(0.0, 40.0, 4001)
    signal = np.sin(t) * np.exp(-t / 20)
    signal[1234], signal[3001] = 5.0, -7.0  # one-sample spikes
    columns = {"t": t, "e": signal, "other": t**2}
    small = decimate(columns, ("e",), max_points=500)
    assert len(small["t"]) <= 500 + 2 and np.all(np.diff(small["t"]) > 0)
    assert small["e"].max() == 5.0 and small["e"].min() == -7.0
    assert small["t"][0] == 0.0 and small["t"][-1] == 40.0
    index = np.searchsorted(t, small["t"])
    assert np.array_equal(small["other"], columns["other"][index])  # rows stay whole
    assert decimate(columns, ("e",), max_points=5000) == columns


def test_chromium_is_installed_only_when_missing_and_as_root(tmp_path):
    calls = []

    def run(command, **options):
        calls.append((command, options["env"]["DEBIAN_FRONTEND"]))
        if command[:2] == ["apt-get", "install"]:
            present.write_text("#!/bin/sh\n")
            present.chmod(0o755)
        return subprocess.CompletedProcess(command, 0, "", "")

    present = tmp_path / "chromium"
    assert browser.ensure_chromium(Path(shutil.which("sh")), root=True, run=run) is None and calls == []
    reason = browser.ensure_chromium(present, root=False, run=run)
    assert "needs root" in reason and calls == []
    assert browser.ensure_chromium(present, root=True, run=run, which=lambda name: None) is not None and calls == []
    assert browser.ensure_chromium(present, root=True, run=run, which=lambda name: "/usr/bin/apt-get") is None
    assert calls == [
        (["apt-get", "update"], "noninteractive"),
        (["apt-get", "install", "-y", "chromium"], "noninteractive"),
    ]
    present.unlink()

    def failing(command, **options):
        return subprocess.CompletedProcess(command, 100, "", "E: Unable to locate package chromium\n")

    reason = browser.ensure_chromium(present, root=True, run=failing, which=lambda name: "/usr/bin/apt-get")
    assert "exited with 100" in reason and "Unable to locate package" in reason
    assert browser.launch_args(root=True)[0] == "--no-sandbox" and "--no-sandbox" not in browser.launch_args(root=False)


def test_page_header_says_what_when_and_which_version(reproduce_folder):
    import datetime as dt

    from ddtrack.report import version

    now = dt.datetime(2030, 1, 2, 3, 4, tzinfo=dt.UTC)
    html = render(reproduce_folder, now=now)
    header = html.split("</header>")[0]
    assert "a reproduce folder" in header and "2030-01-02 03:04 UTC" in header and version() in header
    assert version() != "unknown"  # the installed distribution's version, as `ddtrack --version` prints it


# --- the robots suite (ddtrack bench --suite robots) -------------------------------------------------------------

ROBOT_LAWS = ["backstepping", "kinematic_backstepping"]


@pytest.fixture(scope="module")
def robots_folder(tmp_path_factory):
    """A tiny finished robots suite, the real runner: the paper's robot takes torques only, the Pioneer cmd_vel
    only, so each law is left out on one robot."""
    from distributed import Client

    from ddtrack.cluster import local_cluster
    from ddtrack.studies.robot_suite import RobotSuite, run_robot_suite

    out = tmp_path_factory.mktemp("report_robots")
    suite = RobotSuite(
        robots=("paper", "pioneer_3dx"),
        trajectories=("figure_eight",),
        conditions=("nominal", "latency_50ms"),
        seeds=2,
        overrides=tuple(SHORT[:2]),
    )
    with local_cluster(1) as cluster, Client(cluster) as client:
        run_robot_suite(suite, ROBOT_LAWS, out, client)
    write_report(out)
    return out


def _cell_mean(text: str) -> float:
    return float(text.split()[0])


@pytest.mark.slow
def test_robots_report_in_chromium(robots_folder, chromium, tmp_path):
    html = robots_folder / "report.html"
    summary = json.loads((robots_folder / "leaderboard.json").read_text())
    _assert_self_contained(html.read_text())
    page, graphics = _load(chromium, html, browser.screenshot_path(tmp_path, "report_robots.png"))
    assert {"fig-conditions", "fig-distributions"} <= {g["id"] for g in graphics}
    labels, values = (page.locator(f".card .{part}").all_text_contents() for part in ("label", "value"))
    cards = dict(zip(labels, values, strict=True))
    assert cards["robots"] == "2" and cards["controllers"] == "2" and cards["runs"] == str(summary["runs"])
    assert cards["errors"] == "0" and cards["failures"] == "0"
    for i, (robot, board) in enumerate(summary["boards"].items()):
        assert page.locator(f"section#robot-{i} h2").inner_text() == robot
        head = page.locator(f"table#board-{i} thead th").all_inner_texts()
        assert head == ["rank", "controller", "nominal", "latency_50ms", "all", "failures", "implausible"]
        rows = page.locator(f"table#board-{i} tbody tr").all()
        assert len(rows) == len(board) == 1  # the other law takes no command this robot takes
        for row, entry in zip(rows, board, strict=True):
            texts = row.locator("td").all_inner_texts()
            assert texts[1] == entry["controller"]
            for text, key in zip(texts[2:5], ("nominal", "latency_50ms", "all"), strict=True):
                assert _cell_mean(text) == pytest.approx(entry[key]["mean"], rel=5e-4)
                low, high = re.search(r"\[(\S+), (\S+)\]", text).groups()
                assert float(low) == pytest.approx(entry[key]["ci_low"], rel=5e-4)
                assert float(high) == pytest.approx(entry[key]["ci_high"], rel=5e-4)
            assert texts[5:] == [f"{entry['failures']}/{entry['runs']}", f"{entry['implausible']}/{entry['runs']}"]
    left = [row.locator("td").all_inner_texts() for row in page.locator("table#left-out-table tbody tr").all()]
    assert left == [
        ["paper", "kinematic_backstepping", "nominal, latency_50ms", "takes no velocity commands"],
        ["pioneer_3dx", "backstepping", "nominal, latency_50ms", "takes no torque commands"],
    ]
    assert len(summary["left_out"]) == 4
    # two controllers, one per robot: no ranking to compare and no NN-adaptive law, each said so
    assert "no ranking" in page.locator("section#agreement").inner_text()
    assert "nothing to compare" in page.locator("section#nn-adaptive").inner_text()


def test_a_robots_folder_is_detected_as_such(robots_folder):
    from ddtrack.report.robots_page import KIND_NAME

    assert detect_kind(robots_folder) == "bench"  # `ddtrack bench --suite robots`: the leaderboard says which suite
    html = render(robots_folder)
    page = Page(html)
    assert KIND_NAME in html.split("</header>")[0] and "leaderboard-table" not in page.ids
    assert {"board-0", "board-1", "left-out-table", "suite-table"} <= set(page.ids)
    summary = json.loads((robots_folder / "leaderboard.json").read_text())
    assert page.rows("board-0", html) == len(summary["boards"]["paper"])


def test_a_robots_page_keeps_user_strings_text(robots_folder, tmp_path):
    """The real folder with a robot and a controller renamed to the payload (in leaderboard.json and
    results.parquet): printed as text in the tables and in the SVG matplotlib draws."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    out = tmp_path / "robots"
    shutil.copytree(robots_folder, out)
    quoted = json.dumps(PAYLOAD)[1:-1]
    text = (out / "leaderboard.json").read_text()
    (out / "leaderboard.json").write_text(text.replace("pioneer_3dx", quoted).replace("kinematic_backstepping", quoted))
    rows = pq.read_table(out / "results.parquet").to_pylist()
    for row in rows:
        for key in ("controller", "label.robot"):
            row[key] = PAYLOAD if row[key] in ("pioneer_3dx", "kinematic_backstepping") else row[key]
    pq.write_table(pa.Table.from_pylist(rows), out / "results.parquet")
    html = render(out)
    page = _assert_self_contained(html)
    assert SCRIPT not in html and "<img src=x" not in html
    assert {"td", "h2"} <= {tag for tag, text in page.text if PAYLOAD in text}
    assert any(tag == "text" and text.startswith(SCRIPT) for tag, text in page.text)
