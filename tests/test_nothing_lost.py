"""Nothing lost: a write that fails midway (a full disk) leaves no partial file and ends in one clean line;
an output folder that cannot be written fails before anything is simulated.

The driver killed at random moments and resumed is `bench/kill_resume.py` (and, in the suite,
tests/test_sweep.py::test_resume_after_sigkill); a run folder under a regular file is
tests/test_cli.py::test_unwritable_output_fails_before_simulating.
"""

from __future__ import annotations

import errno
import os
import shutil
import subprocess
import uuid
from pathlib import Path

import pytest
from conftest import SCENARIOS

import ddtrack.runner
import ddtrack.studies.mc
from ddtrack import outdir
from ddtrack.errors import RunError
from ddtrack.studies import sweep

SHORT = ("--set", "simulation.duration=1.0", "--set", "simulation.metric_window=[0.0, 1.0]")


class FullDisk:
    """A file object whose writes raise ENOSPC once ``room`` bytes have gone through, after writing what
    fits (as a real full disk does): the temporary file is left really partial."""

    def __init__(self, file, room: int) -> None:
        self._file, self._room = file, room

    def write(self, data) -> int:
        data = bytes(data)
        if len(data) > self._room:
            self._file.write(data[: self._room])
            self._file.flush()
            self._room = 0
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self._room -= len(data)
        return self._file.write(data)

    def __getattr__(self, name):
        return getattr(self._file, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self._file.close()


def fill_disk(monkeypatch, *, victim: str, room: int = 100) -> None:
    """Make ``outdir.atomic_write`` see a full disk while writing a file named ``victim``."""

    class Os:  # outdir's view of ``os``; the real module is left alone
        def __getattr__(self, name):
            return getattr(os, name)

        @staticmethod
        def fdopen(fd, mode):
            name = Path(os.readlink(f"/proc/self/fd/{fd}")).name  # the temporary: .<name>.<random>.tmp
            file = os.fdopen(fd, mode)
            return FullDisk(file, room) if name.startswith(f".{victim}.") else file

    monkeypatch.setattr(outdir, "os", Os())


def listing(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def assert_clean_error(code: int, stderr: str, name: str, cause: str = "No space left on device") -> None:
    assert code == 2, stderr
    lines = [line for line in stderr.strip().splitlines() if "simulation program" not in line]  # a study's first
    assert 1 <= len(lines) <= 2 and "Traceback" not in stderr, stderr
    assert name in lines[0] and cause in lines[0], stderr


def test_atomic_write_failing_midway_leaves_the_old_file_and_no_temporary(tmp_path, monkeypatch):
    path = tmp_path / "data.bin"
    path.write_bytes(b"old and whole")
    fill_disk(monkeypatch, victim="data.bin", room=1000)
    with pytest.raises(RunError, match=r"data\.bin.*No space left on device") as caught:
        outdir.atomic_write(path, lambda f: f.write(b"x" * 5000))
    assert caught.value.__cause__.errno == errno.ENOSPC  # the cause stays reachable from Python
    assert listing(tmp_path) == ["data.bin"] and path.read_bytes() == b"old and whole"


@pytest.mark.parametrize("victim", ["scenario.toml", "timeseries.parquet", "metrics.json"])
def test_run_on_a_full_disk_exits_2_and_leaves_no_part_of_the_run(tmp_path, cli, monkeypatch, victim):
    fill_disk(monkeypatch, victim=victim)
    out = tmp_path / "run"
    code, _, stderr = cli("run", SCENARIOS / "paper_line.toml", *SHORT, "--out", out)
    assert_clean_error(code, stderr, victim)
    assert str(out / victim) in stderr  # the user's folder is named, not the hidden staging one
    assert listing(tmp_path) == []  # the run is written whole or not at all; no staging folder left


@pytest.mark.parametrize("victim", ["timeseries.parquet", "metrics.json"])
def test_a_failed_rerun_leaves_the_earlier_run_whole(tmp_path, cli, monkeypatch, victim):
    out = tmp_path / "run"
    assert cli("run", SCENARIOS / "paper_line.toml", *SHORT, "--out", out)[0] == 0
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    fill_disk(monkeypatch, victim=victim)
    code, _, stderr = cli("run", SCENARIOS / "paper_line.toml", *SHORT, "--seed", "1", "--out", out)
    assert_clean_error(code, stderr, victim)
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before
    assert listing(tmp_path) == ["run", *(f"run/{name}" for name in listing(out))]


@pytest.mark.slow  # compiles the Monte Carlo batch (about 5 s)
@pytest.mark.parametrize("victim", ["runs.parquet", "summary.json"])
def test_mc_on_a_full_disk_exits_2_and_leaves_nothing(tmp_path, cli, monkeypatch, victim):
    fill_disk(monkeypatch, victim=victim)
    out = tmp_path / "mc"
    code, _, stderr = cli("mc", SCENARIOS / "paper_line.toml", "-n", "2", *SHORT, "--out", out)
    assert_clean_error(code, stderr, victim)
    assert listing(tmp_path) == []


def test_sweep_store_on_a_full_disk_keeps_only_whole_records(tmp_path, monkeypatch):
    record = sweep.error_record("k" * 64, {"controller": "backstepping", "overrides": {}}, 0, "boom")
    sweep.write_record(tmp_path, record | {"key": "a" * 64})
    fill_disk(monkeypatch, victim="b" * 64 + ".json", room=10)
    with pytest.raises(RunError, match="No space left on device"):
        sweep.write_record(tmp_path, record | {"key": "b" * 64})
    fill_disk(monkeypatch, victim="results.parquet", room=10)
    with pytest.raises(RunError, match=r"results\.parquet.*No space left on device"):
        sweep.write_results(tmp_path, list(sweep.read_records(tmp_path).values()))
    assert listing(tmp_path) == ["records", f"records/{'a' * 64}.json"]
    assert list(sweep.read_records(tmp_path)) == ["a" * 64]


def test_animation_on_a_full_disk_leaves_no_partial_file(tmp_path):
    from ddtrack.animation import _write_atomically  # the writer for files that need a name (ffmpeg, Pillow)

    def render(path: Path) -> None:
        path.write_bytes(b"GIF89a half a frame")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    with pytest.raises(RunError, match=r"run\.gif.*No space left on device"):
        _write_atomically(tmp_path / "run.gif", render)
    assert listing(tmp_path) == []


# --- a real file system: tmpfs mounts (we may be root; skipped where mounting is not permitted) ----------


@pytest.fixture
def mount(tmp_path):
    """``mount(size, read_only=False) -> folder``: a tmpfs of ``size`` mounted on a fresh folder, unmounted
    after the test."""
    mounted: list[Path] = []

    def make(size: str, *, read_only: bool = False) -> Path:
        folder = tmp_path / f"mnt-{uuid.uuid4().hex[:8]}"
        folder.mkdir()
        options = f"size={size}" + (",ro" if read_only else "")
        if shutil.which("mount") is None:
            pytest.skip("no mount command")
        done = subprocess.run(
            ["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(folder)], capture_output=True, text=True
        )
        if done.returncode != 0:
            pytest.skip(f"cannot mount a tmpfs here ({done.stderr.strip() or done.returncode})")
        mounted.append(folder)
        return folder

    yield make
    for folder in mounted:
        subprocess.run(["umount", str(folder)], check=False)


def test_run_into_a_real_full_disk(mount, cli):
    disk = mount("64k")  # scenario.toml fits; the 40 s run's 4000-row timeseries.parquet does not
    out = disk / "run"
    code, _, stderr = cli("run", SCENARIOS / "paper_line.toml", "--out", out)
    assert_clean_error(code, stderr, "timeseries.parquet")
    assert listing(disk) == []  # no part of the run, no staging folder
    # and no space is held by a hidden or deleted-but-open temporary
    stat = os.statvfs(disk)
    assert (stat.f_blocks - stat.f_bfree) * stat.f_frsize <= 4096


def refuse_to_simulate(*args, **kwargs):
    raise AssertionError("simulated although the output folder cannot be written")


@pytest.mark.parametrize(
    "command", [("run", SCENARIOS / "paper_line.toml"), ("mc", SCENARIOS / "paper_line.toml", "-n", "2")]
)
def test_read_only_output_fails_before_simulating(mount, cli, monkeypatch, command):
    monkeypatch.setattr(ddtrack.runner, "run_setup", refuse_to_simulate)
    monkeypatch.setattr(ddtrack.studies.mc, "run_specs", refuse_to_simulate)
    disk = mount("64k", read_only=True)  # read-only even for root
    code, _, stderr = cli(*command, "--out", disk / "out")
    assert_clean_error(code, stderr, "cannot be written", cause="Read-only file system")
    assert listing(disk) == []


def test_output_under_a_file_fails_before_simulating_mc(tmp_path, cli, monkeypatch):
    monkeypatch.setattr(ddtrack.studies.mc, "run_specs", refuse_to_simulate)
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    code, _, stderr = cli("mc", SCENARIOS / "paper_line.toml", "-n", "2", "--out", blocker / "mc")
    assert_clean_error(code, stderr, "cannot be written", cause="Not a directory")
    assert blocker.read_text() == "not a folder"
