"""`ddtrack sweep`: run keys, the Dask cluster (embedded and real), the resumable record store."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pyarrow.parquet as pq
import pytest
from conftest import SCENARIOS

from ddtrack.scenario import load_scenario
from ddtrack.studies.batches import monte_carlo
from ddtrack.studies.sweep import plan_sweep, read_records, read_sweep

PYTHON = sys.executable
DASK = str(Path(sys.executable).with_name("dask"))
SHORT = {"simulation.duration": 2.0, "simulation.metric_window": [0.0, 2.0]}
METRICS = ("e_tr_mean", "e_tr_rms", "e_tr_max", "e_tr_final", "effort", "saturation_fraction")


def write_sweep(folder: Path, *, masses=(9.0, 11.0), seeds: int = 3, chunk: int = 2, extra: str = "") -> Path:
    """A tiny grid sweep over figure_eight (Gaussian disturbance and noise: every seed differs)."""
    shutil.copy(SCENARIOS / "figure_eight.toml", folder / "figure_eight.toml")
    path = folder / "sweep.toml"
    path.write_text(
        f'scenario = "figure_eight.toml"\ncontrollers = ["backstepping"]\nseeds = {seeds}\n'
        f'chunk = {chunk}\n{extra}\n[set]\n"simulation.duration" = 2.0\n'
        f'"simulation.metric_window" = [0.0, 2.0]\n[grid]\n"robot.mass" = {list(masses)}\n'
    )
    return path


def direct(masses, seeds) -> dict[tuple[float, int], dict]:
    """The same runs through studies.batches.monte_carlo, by (mass, seed)."""
    rows = {}
    for mass in masses:
        overrides = [f"{k}={json.dumps(v)}" for k, v in {**SHORT, "robot.mass": mass}.items()]
        scenario = load_scenario(SCENARIOS / "figure_eight.toml", overrides=overrides, controller="backstepping")
        for row in monte_carlo(scenario, list(range(seeds)), chunk_size=seeds):
            rows[(mass, row["seed"])] = row
    return rows


def assert_records_match(records: dict[str, dict], masses, seeds: int) -> None:
    expected = direct(masses, seeds)
    assert len(records) == len(expected) == len(masses) * seeds
    seen = set()
    for key, record in records.items():
        assert record["key"] == key and record["status"] == "ok" and record["error"] is None
        mass = record["configuration"]["overrides"]["robot.mass"]
        seen.add((mass, record["seed"]))
        for name in METRICS:
            # the same float64 code in another batch shape: reassociation only (test_batch measures ~5e-15)
            assert record["metrics"][name] == pytest.approx(expected[(mass, record["seed"])][name], rel=0, abs=1e-12)
    assert seen == set(expected)


def children(pid: int) -> list[psutil.Process]:
    try:
        return psutil.Process(pid).children(recursive=True)
    except psutil.NoSuchProcess:
        return []


def workers(pid: int) -> list[psutil.Process]:
    """The worker processes a sweep's embedded cluster spawned (multiprocessing's spawn_main)."""
    found = []
    for child in children(pid):
        try:
            if any("spawn_main" in part for part in child.cmdline()):
                found.append(child)
        except psutil.NoSuchProcess:
            pass
    return found


def kill_all(processes) -> None:
    """SIGKILL each process (and, first, its descendants) by pid."""
    for proc in processes:
        pid = proc.pid
        for child in children(pid):
            try:
                child.kill()
            except psutil.NoSuchProcess:
                pass
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        if isinstance(proc, subprocess.Popen):
            proc.wait(timeout=30)


def wait_for(condition, timeout: float, what: str):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}")


def record_files(out: Path) -> list[Path]:
    folder = out / "records"
    return sorted(folder.glob("*.json")) if folder.is_dir() else []


# --- the sweep file ---------------------------------------------------------------------------------


def test_plan_keys_every_run_once(tmp_path):
    path = write_sweep(tmp_path, masses=(9.0, 11.0, 9.0), seeds=4)  # a repeated value resolves to the same runs
    plan = plan_sweep(read_sweep(path), path.parent)
    assert len(plan.configurations) == 3 and len(plan.runs) == 8
    assert all(len(key) == 64 for key in plan.runs)
    again = plan_sweep(read_sweep(path), path.parent)
    assert list(again.runs) == list(plan.runs)  # keys depend on the resolved scenario and seed only


def test_random_design_is_seeded(tmp_path):
    shutil.copy(SCENARIOS / "figure_eight.toml", tmp_path / "figure_eight.toml")
    path = tmp_path / "random.toml"
    path.write_text(
        'scenario = "figure_eight.toml"\nseeds = {start = 5, count = 2}\n'
        '[random]\nn = 3\nseed = 7\n"robot.mass" = {low = 9.0, high = 11.0}\n'
    )
    plan = plan_sweep(read_sweep(path), tmp_path)
    masses = [c.overrides["robot.mass"] for c in plan.configurations]
    assert len(set(masses)) == 3 and all(9.0 <= m < 11.0 for m in masses)
    assert masses == [c.overrides["robot.mass"] for c in plan_sweep(read_sweep(path), tmp_path).configurations]
    assert sorted({seed for _, seed in plan.runs.values()}) == [5, 6] and len(plan.runs) == 6


@pytest.mark.parametrize(
    ("text", "field"),
    [
        ('scenario = "figure_eight.toml"\nseeds = 2\nsedes = 3\n[grid]\n"robot.mass" = [9.0]\n', "sedes: unknown key"),
        ('seeds = 2\n[grid]\n"robot.mass" = [9.0]\n', "scenario: is required"),
        ('scenario = "missing.toml"\nseeds = 2\n[grid]\n"robot.mass" = [9.0]\n', "scenario: "),
        ('scenario = "figure_eight.toml"\nseeds = 2\n[grid]\n', "grid: is empty"),
        ('scenario = "figure_eight.toml"\nseeds = 2\n[grid]\n"robot.mass" = []\n', "grid.robot.mass: has no values"),
        ('scenario = "figure_eight.toml"\nseeds = 2\n[grid]\n"robot.mas" = [9.0]\n', "robot.mas: unknown key"),
        (
            'scenario = "figure_eight.toml"\nseeds = {start = 0, cout = 2}\n[grid]\n"robot.mass" = [9.0]\n',
            "seeds.cout: unknown key",
        ),
    ],
)
def test_bad_sweep_files_exit_2_naming_the_field(tmp_path, cli, text, field):
    shutil.copy(SCENARIOS / "figure_eight.toml", tmp_path / "figure_eight.toml")
    (tmp_path / "bad.toml").write_text(text)
    out = tmp_path / "out"
    code, _stdout, stderr = cli("sweep", tmp_path / "bad.toml", "--out", out)
    assert code == 2 and field in stderr, stderr
    assert len(stderr.strip().splitlines()) <= 2 and "Traceback" not in stderr
    assert not out.exists()  # nothing written


def test_a_failing_task_is_recorded_and_retried_on_resume(tmp_path, monkeypatch):
    import jax
    from distributed import Client, LocalCluster

    import ddtrack.studies.sweep as sweep
    import ddtrack.studies.tasks as tasks

    path = write_sweep(tmp_path, masses=(10.0,), seeds=2)
    plan = plan_sweep(read_sweep(path), tmp_path)
    out = tmp_path / "out"

    def broken(*args, **kwargs):
        raise FloatingPointError("injected failure")

    # threads in this process, so the patch reaches the task (no listening socket: in-process transport)
    with (
        LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster,
        Client(cluster) as client,
    ):
        monkeypatch.setattr(tasks, "cells_rows", broken)  # the task's batched simulation
        cache_before = jax.config.jax_compilation_cache_dir
        failed = sweep.run_sweep(plan, out, client)
        # a worker in this very process keeps its caller's settings: the driver turns no process-wide switch
        assert cache_before is None and jax.config.jax_compilation_cache_dir is None
        records = read_records(out)
        assert failed.errors == 2 and len(records) == 2
        assert all(
            r["status"] == "error" and r["error"] == "FloatingPointError: injected failure" for r in records.values()
        )
        assert pq.read_table(out / "results.parquet").column("status").to_pylist() == ["error", "error"]
        monkeypatch.undo()
        again = sweep.run_sweep(plan, out, client)  # error records are retried
    assert again.reused == 0 and again.errors == 0
    assert_records_match(read_records(out), (10.0,), 2)


# --- the embedded cluster ---------------------------------------------------------------------------


def test_local_cluster_listens_on_loopback_only():
    from distributed import Client

    from ddtrack.cluster import local_cluster

    with local_cluster(2) as cluster, Client(cluster) as client:
        addresses = [cluster.scheduler_address, *client.scheduler_info()["workers"]]
        assert len(addresses) == 3
        for address in addresses:
            assert address.startswith("tcp://127.0.0.1:"), address
        # every listening socket of the scheduler's process (this one) and of the workers is on loopback;
        # with dashboard_address=None the scheduler still serves /health and /metrics, on 127.0.0.1 as well
        pids = [os.getpid(), *client.run(os.getpid).values()]
        listening = [
            c
            for pid in pids
            for c in psutil.Process(pid).net_connections(kind="inet")
            if c.status == psutil.CONN_LISTEN
        ]
        assert len(listening) >= 3
        assert {c.laddr.ip for c in listening} <= {"127.0.0.1", "::1"}, listening


@pytest.mark.slow
def test_grid_sweep_equals_direct_monte_carlo(tmp_path, cli):
    path = write_sweep(tmp_path)
    out = tmp_path / "out"
    code, stdout, stderr = cli("sweep", path, "--out", out, "--workers", "2")
    assert code == 0, stderr
    assert "6 runs (2 configurations x 3 seeds)" in stdout
    records = read_records(out)
    assert len(record_files(out)) == 6 and len(set(records)) == 6
    assert_records_match(records, (9.0, 11.0), 3)
    table = pq.read_table(out / "results.parquet")
    assert table.column("key").to_pylist() == sorted(records)  # sorted by key
    assert table.column("set.robot.mass").to_pylist() == [
        records[k]["configuration"]["overrides"]["robot.mass"] for k in sorted(records)
    ]
    assert table.column("e_tr_mean").to_pylist() == [records[k]["metrics"]["e_tr_mean"] for k in sorted(records)]
    assert (out / "results.csv").read_text().count("\n") == 7
    before = (out / "results.parquet").read_bytes()
    code, stdout, _ = cli("sweep", path, "--out", out, "--workers", "1")  # everything is there: nothing runs
    assert code == 0 and "6 found" in stdout and "0 run;" in stdout
    assert (out / "results.parquet").read_bytes() == before  # deterministic


@pytest.mark.slow
def test_resume_after_sigkill(tmp_path):
    masses, seeds = (9.0, 10.0, 11.0), 4
    path = write_sweep(tmp_path, masses=masses, seeds=seeds, chunk=1)  # 12 tasks: records land one by one
    out = tmp_path / "out"
    command = [PYTHON, "-m", "ddtrack", "sweep", str(path), "--out", str(out), "--workers", "2"]
    started: list[subprocess.Popen] = []
    spawned: list[psutil.Process] = []  # the sweeps' worker processes, killed by pid if any outlived its sweep
    try:
        # kill while the workers start (no record yet), after the first record, then part-way
        for target in (0, 1, 5):
            proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
            started.append(proc)
            # both workers spawned before the kill, so the snapshot below holds every process to check
            wait_for(lambda: len(workers(proc.pid)) >= 2, 120, "the worker processes")  # noqa: B023
            wait_for(lambda t=target: len(record_files(out)) >= t, 120, f"{target} records")
            family = children(proc.pid)
            spawned.extend(family)
            assert len(workers(proc.pid)) == 2
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(timeout=30)
            # the workers notice their parent's death and exit (distributed's parent-alive pipe)
            _, alive = psutil.wait_procs(family, timeout=20)
            assert not alive, f"orphan workers: {[p.pid for p in alive]}"
            assert len(record_files(out)) < len(masses) * seeds and not (out / "results.parquet").exists()
            for file in record_files(out):
                json.loads(file.read_text())  # every record is whole
        (out / "records" / ".leftover.json.abc.tmp").write_text('{"key": ')  # as a kill during a write leaves
        final = subprocess.run(command, capture_output=True, text=True, timeout=300)
        assert final.returncode == 0, final.stderr
        reused = int(re.search(r": (\d+) found in", final.stdout).group(1))
        assert 5 <= reused < len(masses) * seeds  # it resumed: only the missing runs ran
        assert sorted(p.name for p in (out / "records").iterdir()) == [p.name for p in record_files(out)]  # no temps
        records = read_records(out)
        assert_records_match(records, masses, seeds)
        assert pq.read_table(out / "results.parquet").column("key").to_pylist() == sorted(records)  # no duplicate
    finally:
        kill_all(started)
        kill_all(p for p in spawned if p.is_running())


# --- a real cluster ---------------------------------------------------------------------------------


class Cluster:
    """``dask scheduler`` and ``dask worker`` processes on 127.0.0.1, started by their own CLI."""

    def __init__(self, folder: Path, workers: int) -> None:
        self.file = folder / "scheduler.json"
        self.procs: list[subprocess.Popen] = []
        log = open(folder / "dask.log", "wb")
        self.procs.append(
            subprocess.Popen(
                [
                    DASK,
                    "scheduler",
                    "--host",
                    "127.0.0.1",
                    "--port",
                    "0",
                    "--scheduler-file",
                    str(self.file),
                    "--no-dashboard",
                ],
                stdout=log,
                stderr=log,
            )
        )
        wait_for(self.file.exists, 60, "the scheduler file")
        for _ in range(workers):
            self.procs.append(
                subprocess.Popen(
                    [
                        DASK,
                        "worker",
                        "--scheduler-file",
                        str(self.file),
                        "--nthreads",
                        "1",
                        "--no-dashboard",
                        "--host",
                        "127.0.0.1",
                    ],
                    stdout=log,
                    stderr=log,
                )
            )

    def client(self):
        from distributed import Client

        return Client(scheduler_file=str(self.file), timeout="30s")

    def close(self) -> None:
        kill_all(self.procs)


@pytest.mark.slow
def test_sweep_on_a_real_cluster_survives_a_killed_worker(tmp_path):
    masses, seeds = (9.0, 11.0), 4
    path = write_sweep(tmp_path, masses=masses, seeds=seeds, chunk=1)
    out = tmp_path / "out"
    cluster = Cluster(tmp_path, workers=2)
    sweep = None
    try:
        with cluster.client() as client:
            client.wait_for_workers(2, timeout=60)
            info = client.scheduler_info()
            assert info["address"].startswith("tcp://127.0.0.1:")
            assert all(a.startswith("tcp://127.0.0.1:") for a in info["workers"])
            pids = client.run(os.getpid)  # worker address -> pid
            sweep = subprocess.Popen(
                [PYTHON, "-m", "ddtrack", "sweep", str(path), "--out", str(out), "--scheduler-file", str(cluster.file)],
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
            # kill a worker while it holds a task (the first tasks compile for seconds: a wide window)
            busy = wait_for(lambda: [w for w, tasks in client.processing().items() if tasks], 120, "a busy worker")
            victim = pids[busy[0]]
            done_before = len(record_files(out))
            os.kill(victim, signal.SIGKILL)
            stdout, stderr = sweep.communicate(timeout=300)
        assert done_before < len(masses) * seeds
        assert not psutil.pid_exists(victim) or psutil.Process(victim).status() == psutil.STATUS_ZOMBIE  # it died
        assert sweep.returncode == 0, stderr
        assert "8 runs" in stdout and "0 errors" in stdout
        records = read_records(out)
        assert_records_match(records, masses, seeds)  # no run lost
        assert pq.read_table(out / "results.parquet").num_rows == len(masses) * seeds
    finally:
        if sweep is not None:
            kill_all([sweep])
        cluster.close()


@pytest.mark.slow
def test_random_sweep_on_a_real_cluster_by_address(tmp_path):
    shutil.copy(SCENARIOS / "figure_eight.toml", tmp_path / "figure_eight.toml")
    path = tmp_path / "random.toml"
    path.write_text(
        'scenario = "figure_eight.toml"\nseeds = {start = 3, count = 2}\nchunk = 2\n'
        "[set]\nsimulation = {duration = 2.0, metric_window = [0.0, 2.0]}\n"
        '[random]\nn = 2\nseed = 1\n"plant.mass" = {low = 9.0, high = 13.0}\n'
    )
    plan = plan_sweep(read_sweep(path), tmp_path)
    out = tmp_path / "out"
    cluster = Cluster(tmp_path, workers=1)
    try:
        address = json.loads(cluster.file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        with cluster.client() as client:
            client.wait_for_workers(1, timeout=60)
        result = subprocess.run(
            [PYTHON, "-m", "ddtrack", "sweep", str(path), "--out", str(out), "--scheduler", address],
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert result.returncode == 0, result.stderr
        with cluster.client() as client:  # the driver set the compile cache on the workers, as a plugin, not a task
            caches = client.run(lambda: __import__("jax").config.jax_compilation_cache_dir)
            assert caches and all(str(path).endswith("jax") for path in caches.values()), caches
            assert "ddtrack-compilation-cache" in client.run_on_scheduler(
                lambda dask_scheduler: list(dask_scheduler.worker_plugins)
            )
    finally:
        cluster.close()
    records = read_records(out)
    assert set(records) == set(plan.runs) and len(records) == 4
    for configuration in plan.configurations:
        for row in monte_carlo(configuration.scenario, [3, 4], chunk_size=2):
            key = next(
                k
                for k, (i, seed) in plan.runs.items()
                if plan.configurations[i] is configuration and seed == row["seed"]
            )
            assert records[key]["configuration"]["overrides"] == configuration.overrides
            for name in METRICS:
                assert records[key]["metrics"][name] == pytest.approx(row[name], rel=0, abs=1e-12)


def test_unreachable_scheduler_exits_2_and_leaves_no_folder(tmp_path, cli, monkeypatch):
    monkeypatch.setattr("ddtrack.cluster.CONNECT_TIMEOUT_S", 2)  # the default 20 s, shortened for the suite
    sweep_file = write_sweep(tmp_path)
    with socket.socket() as closed:  # a loopback port that nothing listens on
        closed.bind(("127.0.0.1", 0))
        port = closed.getsockname()[1]
    code, _, stderr = cli(
        "sweep", sweep_file, "--out", tmp_path / "out" / "sweep", "--scheduler", f"tcp://127.0.0.1:{port}"
    )
    assert code == 2 and "cannot reach the Dask scheduler" in stderr
    assert not (tmp_path / "out").exists()
