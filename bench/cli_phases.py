"""Where the time of one ``ddtrack run`` goes, phase by phase (docs/benchmarks.md, "One interactive run").

    python bench/cli_phases.py [SCENARIO] [--out DIR] [--json] [--cache DIR]

Runs, in this fresh process, the steps ``ddtrack run SCENARIO --out DIR`` takes, timing each: import (the
command line and the scenario module, which brings JAX), load (parse and validate the scenario), jax (switch on
the persistent compilation cache), prepare (start JAX's backend; the run's randomness and objects), simulate
(trace, look up or compile, run the jitted simulation), metrics, write (the run folder: scenario.toml,
timeseries.parquet, metrics.json, the figures; the imports of Matplotlib and pyarrow) less figures (the PNGs,
timed by drawing them a second time, into memory, after ``total_s``). ``total_s`` is this process's time from its
first line to the run folder written (interpreter start-up excluded; ``ddtrack`` exits at once after that).
``compiles`` counts the XLA programs the run needed and ``cache_hits`` how many of them the persistent
compilation cache answered (run twice with the same ``--cache``: the second run is warm).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import tempfile
import time
from pathlib import Path

START = time.perf_counter()
ROOT = Path(__file__).resolve().parent.parent


class CompileCounter(logging.Handler):
    """Counts JAX's log lines about compiling a program and about hitting the persistent cache."""

    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.compiles = 0
        self.cache_hits = 0

    def emit(self, record: logging.LogRecord) -> None:
        message = record.getMessage()
        self.compiles += message.startswith("Compiling ")
        self.cache_hits += message.startswith("Persistent compilation cache hit")


def phases(scenario: Path, out: Path) -> dict[str, float | int]:
    times: dict[str, float | int] = {}
    mark = START

    def lap(name: str) -> None:
        nonlocal mark
        now = time.perf_counter()
        times[name] = now - mark
        mark = now

    from ddtrack import cli  # what `ddtrack` imports before it knows the command
    from ddtrack._after_import import after_import

    cli.collect_garbage_rarely()  # as the command
    after_import("jax", cli.one_device_per_core)  # as the command: its compile-cache entries are this run's
    after_import("jax", lambda jax: jax.config.update("jax_enable_x64", True))  # as the command: float64
    from ddtrack.scenario import load_scenario

    lap("import_s")
    spec = load_scenario(scenario)
    lap("load_s")
    import jax

    counter = CompileCounter()
    for name in ("jax._src.dispatch", "jax._src.compiler", "jax._src.compilation_cache", "jax._src.interpreters.pxla"):
        logging.getLogger(name).addHandler(counter)
    jax.config.update("jax_log_compiles", True)
    logging.getLogger("jax").setLevel(logging.DEBUG)
    logging.getLogger("jax").propagate = False  # counted, not printed
    from ddtrack.runner import enable_compilation_cache, prepare, run_setup

    enable_compilation_cache()
    lap("jax_s")
    setup, draws = prepare(spec)
    jax.block_until_ready(draws)
    lap("prepare_s")
    result = jax.block_until_ready(run_setup(spec, setup, draws))
    lap("simulate_s")
    from ddtrack.metrics import summarize
    from ddtrack.sim import timeseries

    columns = timeseries(result)
    sim = spec.simulation
    metrics = summarize(
        columns,
        status=result.status_name,
        window=sim.window,
        control_period=sim.control_period,
        settling_threshold=sim.settling_threshold,
        failure_time=result.failure_time,
    )
    lap("metrics_s")
    from ddtrack.rundir import write_run

    written = write_run(out, spec, columns, metrics)
    lap("write_s")
    times["total_s"] = time.perf_counter() - START
    times["figures_s"] = figures_time(spec, columns, metrics)  # drawn again, into memory: the figures' share
    times["write_s"] -= times["figures_s"]
    times["compiles"], times["cache_hits"] = counter.compiles, counter.cache_hits
    times["files"] = len(written)
    return times


def figures_time(spec, columns, metrics) -> float:
    """The figures of a run folder drawn again, into memory: the figure part of the write phase."""
    import io

    import matplotlib.pyplot as plt

    from ddtrack import plotting

    start = time.perf_counter()
    window = tuple(metrics["window"])
    for fig in (
        plotting.plot_path(columns, title=spec.name),
        plotting.plot_states(columns),
        plotting.plot_errors(columns, window=window),
        plotting.plot_torques(columns, max_torque=spec.plant_params().max_torque),
    ):
        fig.savefig(io.BytesIO(), format="png", dpi=110)
        plt.close(fig)
    return time.perf_counter() - start


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenario", nargs="?", type=Path, default=ROOT / "scenarios" / "paper_line.toml")
    parser.add_argument("--out", type=Path, help="run folder [default: a temporary one]")
    parser.add_argument("--cache", help="DDTRACK_CACHE_DIR for this run [default: the environment's]")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    if args.cache:
        os.environ["DDTRACK_CACHE_DIR"] = args.cache
    with tempfile.TemporaryDirectory(prefix="ddtrack-phases-") as scratch:
        times = phases(args.scenario, args.out or Path(scratch) / "run")
    if args.json:
        print(json.dumps(times, indent=2))
    else:
        for name, value in times.items():
            print(f"  {name:<22} {value * 1e3:8.0f} ms" if name.endswith("_s") else f"  {name:<22} {value:8d}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
