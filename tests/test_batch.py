"""The batch engine and Monte Carlo (`ddtrack mc`): row i of a batch is the single run, on common random numbers."""

from __future__ import annotations

import json
import os
import pty
import subprocess
import sys

import numpy as np
import pyarrow.parquet as pq
import pytest
from conftest import SCENARIOS

import ddtrack
from ddtrack.runner import prepare
from ddtrack.studies.batches import monte_carlo
from ddtrack.studies.mc import load_specs, run_specs, summarise

SHORT = ["simulation.duration=4", "simulation.metric_window=[0, 4]"]
# Gaussian wheel disturbance, pose noise and a random plant mass: every random stream is exercised
RANDOM = [*SHORT, 'randomize.mass={distribution="uniform", relative=0.2}']


# A batch row equals its single run, to the bit, for every controller: tests/test_determinism.py.


def test_common_random_numbers_across_controllers():
    bs, nn = (
        ddtrack.load_scenario(SCENARIOS / "figure_eight.toml", overrides=RANDOM, controller=kind)
        for kind in ("backstepping", "nn_adaptive_backstepping")
    )
    (setup_bs, draws_bs) = prepare(bs, seed=9)
    (setup_nn, draws_nn) = prepare(nn, seed=9, identify=False)
    assert setup_bs.plant_params == setup_nn.plant_params  # the same drawn plant
    assert np.array_equal(draws_bs.disturbance, draws_nn.disturbance)
    assert np.array_equal(draws_bs.noise, draws_nn.noise)


# mc's rows equal the single runs' metrics, a diverged run included: tests/test_determinism.py.


def test_chunking_does_not_change_the_runs():
    scenario = ddtrack.load_scenario(SCENARIOS / "figure_eight.toml", overrides=RANDOM)
    whole = monte_carlo(scenario, list(range(5)), chunk_size=5)
    chunked = monte_carlo(scenario, list(range(5)), chunk_size=2)  # 2 + 2 + 1 padded to 2
    assert [r["seed"] for r in chunked] == list(range(5))
    for a, b in zip(whole, chunked, strict=True):
        assert a == b  # every metric, to the bit
        assert 9.6 <= a["plant_mass"] <= 14.4  # 12 kg +-20 %
    assert len({r["plant_mass"] for r in whole}) == 5


def test_summary_pairs_runs_by_seed():
    nn_only = ["controller.epochs=2", "controller.identification_duration=5"]  # keys backstepping does not have
    specs = load_specs(SCENARIOS / "figure_eight.toml", controllers=["backstepping"], overrides=RANDOM)
    specs |= load_specs(
        SCENARIOS / "figure_eight.toml", controllers=["nn_adaptive_backstepping"], overrides=[*RANDOM, *nn_only]
    )
    rows = run_specs(specs, n=3, seed=2, chunk_size=3)
    summary = summarise(rows)
    paired = [
        100 * (b["e_tr_mean"] - n["e_tr_mean"]) / b["e_tr_mean"]
        for b, n in zip(rows["backstepping"], rows["nn_adaptive_backstepping"], strict=True)
    ]
    gain = summary["improvement"]["nn_adaptive_backstepping"]
    assert gain["mean"] == pytest.approx(np.mean(paired)) and gain["paired_runs"] == 3
    assert gain["ci_low"] < gain["mean"] < gain["ci_high"]
    assert [r["seed"] for r in rows["backstepping"]] == [2, 3, 4]


def test_mc_command_writes_its_tables(tmp_path, cli):
    out = tmp_path / "mc"
    code, stdout, stderr = cli(
        "mc",
        SCENARIOS / "figure_eight.toml",
        "-n",
        "4",
        "--controllers",
        "backstepping",
        "--vary",
        "mass=uniform:0.2",
        *[a for s in SHORT for a in ("--set", s)],
        "--chunk",
        "3",
        "--out",
        out,
    )
    assert code == 0 and "4 runs per controller" in stdout and "e_tr_mean" in stdout
    # the programs it needs, and no progress bar when stderr is not a terminal
    assert stderr == "1 simulation program to run (one per structure); 0 already compiled in the cache\n"
    table = pq.read_table(out / "runs.parquet")
    assert table.num_rows == 4 and table.column("seed").to_pylist() == [0, 1, 2, 3]
    assert {"controller", "plant_mass", "e_tr_mean", "status", "effort"} <= set(table.column_names)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["controllers"]["backstepping"]["failures"] == 0
    assert (out / "runs.csv").read_text().startswith('"controller","seed"')


@pytest.mark.parametrize(
    ("args", "field"),
    [
        (["--vary", "mass=uniform"], "--vary"),
        (["--vary", "mas=uniform:0.2"], "randomize.mas"),
        (["--controllers", "backstepping,backstepping"], "--controllers"),
        (["--controllers", "nn"], "controller.kind"),
        (["--seed", str(2**63 - 1)], "--seed"),  # seeds past jax's int64 key: found by the fuzzer
    ],
)
def test_mc_bad_input_exits_2_and_writes_nothing(tmp_path, cli, args, field):
    code, _, stderr = cli("mc", SCENARIOS / "paper_line.toml", "-n", "2", *args, "--out", tmp_path / "mc")
    assert code == 2 and stderr.startswith(f"error: {field}")
    assert not (tmp_path / "mc").exists()


def test_mc_shows_a_progress_bar_on_a_terminal(tmp_path):
    """On a (pseudo-)terminal stderr, ``mc`` draws rich's bar from 0 to the last run."""
    leader, follower = pty.openpty()
    args = [
        sys.executable,
        "-m",
        "ddtrack",
        "mc",
        str(SCENARIOS / "figure_eight.toml"),
        "-n",
        "4",
        "--chunk",
        "2",
        *[a for s in SHORT for a in ("--set", s)],
        "--out",
        str(tmp_path / "mc"),
    ]
    with subprocess.Popen(
        args,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=follower,
        env={**os.environ, "COLUMNS": "100", "TERM": "xterm"},
    ) as process:
        os.close(follower)
        screen = b""
        while True:
            try:
                chunk = os.read(leader, 4096)
            except OSError:  # EIO: the child closed the terminal
                break
            if not chunk:
                break
            screen += chunk
        stdout = process.stdout.read().decode()
    os.close(leader)
    assert process.returncode == 0, screen.decode(errors="replace")
    text = screen.decode(errors="replace")
    assert "0/4" in text and "4/4" in text and "backstepping" in text and "━" in text
    assert "4/4" not in stdout and "runs per controller" in stdout  # the bar stays off the results


def test_runs_split_over_two_cpu_devices_are_the_same_runs():
    """``in_shares`` splits a chunk into a share per JAX CPU device (``ddtrack`` asks for one per core), each share
    a thread's, all on the first device (one compiled program for every share): a subprocess
    with two devices must give the rows this one-device process gives, for backstepping and for the NN-adaptive
    law, whose emulators one program partitioned over the two devices trained differently in the last
    bits (with a 5 s, 5-epoch identification as with the paper's 60 s and 100; not with 2 epochs). Both the
    identification and the simulation are split. The first batch runs in a ``with jax.enable_x64(True):`` block
    instead of ``ddtrack.enable_float64()``: the threads that compute the shares take the caller's float64 (they
    ran in float32, and ``simulate`` refused them, before ``in_shares`` passed the setting on)."""
    nn = [
        "controller.kind=nn_adaptive_backstepping",
        "simulation.duration=3",
        "simulation.metric_window=[0, 3]",
        "controller.identification_duration=5",
        "controller.epochs=5",
    ]
    script = (
        "import jax, json, sys; jax.config.update('jax_num_cpu_devices', 2)\n"
        "import ddtrack\nfrom ddtrack.sim.batch import in_shares\nfrom ddtrack.studies.batches import monte_carlo\n"
        "seen = []\nin_shares(lambda x: seen.append((x.shape, *x.devices())) or x, jax.numpy.zeros(4))\n"
        "assert len(jax.devices()) == 2 and seen == [((2,), jax.devices()[0])] * 2, seen\n"  # two shares, one device
        "with jax.enable_x64(True):\n"  # float64 in this thread only
        f"    scenario = ddtrack.load_scenario({str(SCENARIOS / 'figure_eight.toml')!r}, overrides={RANDOM!r})\n"
        "    print(json.dumps(monte_carlo(scenario, [0, 1, 2, 3], chunk_size=4)))\n"
        "ddtrack.enable_float64()\n"
        "print(json.dumps(monte_carlo(scenario, [0, 1], chunk_size=2)))\n"  # one run per share: left unsplit
        f"nn = ddtrack.load_scenario({str(SCENARIOS / 'paper_line.toml')!r}, overrides={nn!r})\n"
        "import ddtrack.runner as runner, ddtrack.studies.batches as batches\nsplit, split_runs = [], in_shares\n"
        "record = lambda f, *a: split.append(getattr(f, 'func', f).__name__) or split_runs(f, *a)\n"
        "runner.in_shares = batches.in_shares = record\n"
        "print(json.dumps(monte_carlo(nn, [0, 1, 2, 3], chunk_size=4)))\n"
        "assert split == ['batched', 'share_series'], split\n"  # the identification (vmap_runs), the simulation
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    sharded, pair, sharded_nn = (json.loads(line) for line in done.stdout.splitlines()[-3:])
    here = monte_carlo(
        ddtrack.load_scenario(SCENARIOS / "figure_eight.toml", overrides=RANDOM), [0, 1, 2, 3], chunk_size=4
    )
    assert pair == here[:2]
    for a, b in zip(here, sharded, strict=True):
        assert a == b  # every metric, to the bit: each share simulates its two runs as a batch of two
    here_nn = monte_carlo(
        ddtrack.load_scenario(SCENARIOS / "paper_line.toml", overrides=nn), [0, 1, 2, 3], chunk_size=4
    )
    assert here_nn == sharded_nn  # the identification NMSE among the metrics: the emulators too


def test_ctrl_c_returns_without_waiting_for_the_shares_still_computing():
    """A Ctrl-C while the threads compute their shares reaches the caller at once: ``ddtrack mc`` said "aborted"
    only once every share had finished (4.8 and 11 s after it, in a 50-run NN identification). Each share here
    waits for the caller to release it; it must see the release, which the old code only gave once the shares had
    given up."""
    script = (
        "import jax, signal, threading, time; jax.config.update('jax_num_cpu_devices', 2)\n"
        "from ddtrack.sim.batch import in_shares\n"
        "signal.signal(signal.SIGINT, signal.default_int_handler)\n"  # as in a terminal; a background job ignores it
        "main, started = threading.main_thread().ident, threading.Barrier(2)\n"
        "release, released = threading.Event(), []\n"
        "def share(x):\n"
        "    if started.wait() == 0:\n"  # both shares are computing: Ctrl-C, to the waiting caller
        "        signal.pthread_kill(main, signal.SIGINT)\n"
        "    released.append(release.wait(10))\n"
        "    return x\n"
        "try:\n"
        "    in_shares(share, jax.numpy.zeros(4))\n"
        "except KeyboardInterrupt:\n"
        "    release.set()\n"
        "while len(released) < 2:\n"
        "    time.sleep(0.05)\n"
        "print(released)\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[True, True]"  # released by the caller, not timed out


def test_mc_of_one_run_prints_its_mean_without_an_interval(tmp_path, cli):
    # found by the fuzzer: one run has no confidence interval, and the summary line used to crash on it
    code, stdout, stderr = cli(
        "mc",
        SCENARIOS / "paper_line.toml",
        "-n",
        "1",
        "--controllers",
        "backstepping",
        "--set",
        "simulation.duration=2",
        "--set",
        "simulation.metric_window=[0, 2]",
        "--set",
        "simulation.lost_path_error=100",  # 2 s do not reach the line 7 m away: judged on, not off, its path
        "--out",
        tmp_path / "mc",
    )
    assert code == 0, stderr
    assert "(one run: no interval)" in stdout and (tmp_path / "mc" / "summary.json").is_file()
