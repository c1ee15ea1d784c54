"""Speed benchmark: ddtrack against a plain Python loop on the paper's line case (docs/benchmarks.md).

    python bench/speed.py [--json] [--repeats N] [--python-repeats M] [--python-nn-repeats P] [--cli-repeats K]
                          [--control-repeats C] [--batch-sizes 256,1024]

In one process, in this order:

1. ``compile_s``: the first ``ddtrack.run`` on scenarios/paper_line.toml (trace + XLA compile + run)
   minus the median steady-state run. JAX's persistent cache is off in this process, so it is a
   real compile; the JAX backend is started before, so its start-up is not counted.
2. The check: the plain Python loop (bench/python_loop.py) and ddtrack must give the same states
   (max |difference| over every recorded state <= 1e-8), or the script stops with exit code 1; the
   same for the NN-adaptive controller without identification (the emulator starts from the weights
   ddtrack draws from the seed, which the Python loop takes from ``ddtrack.prepare``).
3. ``single_bs_s``: median wall time of ``ddtrack.run(scenario)`` (randomness drawn from the seed,
   then the jitted ``lax.scan``), waited for with ``jax.block_until_ready``; ``simulate_only_s``
   is the unbatched ``ddtrack.simulate`` alone on the prepared arguments (``ddtrack.run`` simulates the run
   as a batch's row, docs/benchmarks.md).
4. ``python_loop_bs_s``: median wall time of the same run by the Python loop;
   ``ratio_python_over_ddtrack`` = python_loop_bs_s / single_bs_s (the target is >= 10).
5. ``single_nn_s``: median wall time of one NN-adaptive run (identification apart, timed as
   ``nn_identification_s``); ``python_loop_nn_s``: the plain Python NN loop on the same scenario without
   identification (the same per-period work); ``ratio_python_nn_over_ddtrack`` = python_loop_nn_s / single_nn_s.
6. ``control_bs_s``: python-control's ``input_output_response`` on the same closed loop at matching
   accuracy (bench/control_loop.py; needs ``pip install -e '.[bench]'``); ``ratio_control_over_ddtrack``.
7. ``batch_bs_robot_steps_per_s`` / ``batch_nn_robot_steps_per_s``: robot control steps per second of
   ``studies.batches.batch_metrics`` (the path of ``ddtrack mc``) at the best of the tried batch sizes (bench/batch.py),
   on one JAX CPU device per core, as the ``ddtrack`` command sets up.
8. ``cold_cli_s`` / ``warm_cli_s``: wall time of a whole ``ddtrack run scenarios/paper_line.toml
   --out <tmp>`` subprocess (interpreter start, imports, compile, run, metrics, writing the run
   folder and its figures) with DDTRACK_CACHE_DIR pointing at a fresh empty folder (cold), then at that
   folder once populated (warm); each repeat gets its own fresh folder. ``python_process_s``: the whole
   process ``python bench/python_loop.py scenarios/paper_line.toml --out <tmp>.csv`` (read the TOML,
   simulate in plain Python, write the states), run just before each cold/warm pair so that the three share
   the machine's load; ``ratio_cold`` / ``ratio_warm`` = cold_cli_s / warm_cli_s over python_process_s
   (targets: <= 6 and <= 3). ``--cli-only`` measures only this.
9. ``floor_process_s``: the whole process that only imports what ``ddtrack run`` imports (the command line, the
   scenario models, JAX, SciPy's LAPACK, which JAX loads to call an exported program, Matplotlib's pyplot,
   pyarrow's Parquet writer), starts JAX's float64 CPU backend and exits
   as ``ddtrack`` does (without the interpreter's teardown): what any ``ddtrack run`` costs before it reads its
   scenario. Interleaved with the three above; ``ratio_floor`` = floor_process_s / python_process_s, the lowest
   ``ratio_warm`` this command could reach with these libraries.

Medians resist the noise of a shared machine; the minimum of each series is reported beside it.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SCENARIO = ROOT / "scenarios" / "paper_line.toml"
TOLERANCE = 1e-8  # max |python - ddtrack| over every recorded state component

sys.path.insert(0, str(Path(__file__).resolve().parent))

from control_loop import timings  # noqa: E402  (python-control itself is imported only when measured)


class Disagreement(RuntimeError):
    """The Python loop and ddtrack do not simulate the same thing: no timing comparison is honest."""


def machine_info() -> dict[str, object]:
    import jax
    import jaxlib
    import numpy

    cpu = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "cores_usable": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
        "platform": platform.platform(),
        "python": platform.python_version(),
        "jax": jax.__version__,
        "jaxlib": jaxlib.__version__,
        "numpy": numpy.__version__,
        "jax_backend": jax.default_backend(),
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
    }


def load_average() -> list[float]:
    try:
        return [float(x) for x in Path("/proc/loadavg").read_text().split()[:3]]
    except OSError:
        return []


def check_agreement(ddtrack_states, python_states) -> float:
    """Max |difference| between the two runs' states; raises :class:`Disagreement` above TOLERANCE."""
    import numpy as np

    a, b = np.asarray(python_states, dtype=float), np.asarray(ddtrack_states, dtype=float)
    if a.shape != b.shape:
        raise Disagreement(f"state shapes differ: python {a.shape}, ddtrack {b.shape}")
    difference = float(np.max(np.abs(a - b)))
    if not difference <= TOLERANCE:  # also catches NaN
        row = int(np.argmax(np.max(np.abs(a - b), axis=1)))
        raise Disagreement(
            f"python loop and ddtrack disagree by {difference:.3g} (> {TOLERANCE:g}), first worst at "
            f"row {row}: python {a[row].tolist()} vs ddtrack {b[row].tolist()}"
        )
    return difference


def measure_library(
    repeats: int, python_repeats: int, python_nn_repeats: int, control_repeats: int, batch_sizes: list[int]
) -> dict[str, object]:
    start = time.perf_counter()
    import jax
    import jax.numpy as jnp
    import numpy as np

    jax.config.update(
        "jax_num_cpu_devices", len(os.sched_getaffinity(0))
    )  # as the ddtrack command: batches use every core

    from python_loop import params_from_nn_setup, params_from_scenario, run_backstepping, run_nn_adaptive

    import ddtrack

    ddtrack.enable_float64()
    from ddtrack.runner import closed_loop, run_setup

    import_s = time.perf_counter() - start
    jax.config.update("jax_enable_compilation_cache", False)  # a real compile, whatever the environment says
    jnp.zeros(1).block_until_ready()  # start the backend outside the compile figure

    scenario = ddtrack.load_scenario(SCENARIO)

    def run_ddtrack():
        return jax.block_until_ready(ddtrack.run(scenario))

    start = time.perf_counter()
    result = run_ddtrack()
    first_s = time.perf_counter() - start

    params = params_from_scenario(scenario)
    difference = check_agreement(result.state, run_backstepping(**params))
    # the NN loop starts from ddtrack's initial emulator weights: no identification to redo by hand
    nn_free = ddtrack.load_scenario(
        SCENARIO, controller="nn_adaptive_backstepping", overrides=["controller.identification=false"]
    )
    nn_free_setup, nn_free_draws = ddtrack.prepare(nn_free)
    nn_params = params_from_nn_setup(nn_free, nn_free_setup)
    nn_difference = check_agreement(
        run_setup(nn_free, nn_free_setup, nn_free_draws).state, run_nn_adaptive(**nn_params)
    )

    single = timings(run_ddtrack, repeats)

    setup, draws = ddtrack.prepare(scenario)
    sim = scenario.simulation
    loop, x0 = closed_loop(scenario, setup), jnp.asarray(setup.x0)

    def simulate_only():
        return jax.block_until_ready(ddtrack.simulate(loop, x0, draws, n_steps=sim.n_steps))

    simulate_only()
    simulate = timings(simulate_only, repeats)

    python = timings(lambda: run_backstepping(**params), python_repeats)

    # NN-adaptive: the control loop of one run (emulator training and gain law every period); its
    # identification phase is a separate one-off cost, timed apart (compile excluded in both)
    nn_scenario = ddtrack.load_scenario(SCENARIO, controller="nn_adaptive_backstepping")
    nn_setup, nn_draws = ddtrack.prepare(nn_scenario)
    nn_identify = timings(lambda: jax.block_until_ready(ddtrack.prepare(nn_scenario)[0].identification), 2)
    jax.block_until_ready(run_setup(nn_scenario, nn_setup, nn_draws))
    single_nn = timings(lambda: jax.block_until_ready(run_setup(nn_scenario, nn_setup, nn_draws)), repeats)
    python_nn = timings(lambda: run_nn_adaptive(**nn_params), python_nn_repeats)

    figures: dict[str, object] = {
        "scenario": str(SCENARIO.relative_to(ROOT)),
        "n_steps": sim.n_steps,
        "substeps": sim.substeps,
        "max_abs_state_difference": difference,
        "max_abs_state_difference_nn": nn_difference,
        "import_s": import_s,
        "first_call_s": first_s,
        "compile_s": first_s - statistics.median(single),
        "single_bs_s": statistics.median(single),
        "single_bs_min_s": min(single),
        "simulate_only_s": statistics.median(simulate),
        "simulate_only_min_s": min(simulate),
        "single_nn_s": statistics.median(single_nn),
        "single_nn_min_s": min(single_nn),
        "nn_identification_s": statistics.median(nn_identify),
        "python_loop_bs_s": statistics.median(python),
        "python_loop_bs_min_s": min(python),
        "ratio_python_over_ddtrack": statistics.median(python) / statistics.median(single),
        "ratio_python_over_ddtrack_min": min(python) / min(single),
        "python_loop_nn_s": statistics.median(python_nn),
        "python_loop_nn_min_s": min(python_nn),
        "ratio_python_nn_over_ddtrack": statistics.median(python_nn) / statistics.median(single_nn),
        "ratio_python_nn_over_ddtrack_min": min(python_nn) / min(single_nn),
        "repeats": repeats,
        "python_repeats": python_repeats,
        "python_nn_repeats": python_nn_repeats,
    }
    if control_repeats:
        from control_loop import time_control

        figures.update(time_control(control_repeats, ddtrack_result=np.asarray(result.state)))
        figures["ratio_control_over_ddtrack"] = figures["control_bs_s"] / figures["single_bs_s"]
        figures["ratio_control_over_ddtrack_min"] = figures["control_bs_min_s"] / figures["single_bs_min_s"]
    if batch_sizes:
        from batch import best_throughput

        throughput = best_throughput(batch_sizes, repeats=2)
        for kind, key in (("backstepping", "batch_bs"), ("nn_adaptive_backstepping", "batch_nn")):
            best = throughput["best"][kind]
            figures |= {f"{key}_robot_steps_per_s": best["robot_steps_per_s"], f"{key}_best_size": best["batch"]}
        figures["batch_devices"] = len(jax.devices())
    return figures


def ddtrack_command() -> list[str]:
    """The installed ``ddtrack`` script next to this interpreter, else ``python -m ddtrack``."""
    script = Path(sys.executable).parent / "ddtrack"
    if script.exists():
        return [str(script)]
    found = shutil.which("ddtrack")
    return [found] if found else [sys.executable, "-m", "ddtrack"]


#: what the ``ddtrack`` process sets, imports and starts before it reads a scenario (ddtrack.cli.entry_point), then
#: its exit (ddtrack.cli.exit_now)
FLOOR_CODE = (
    "import ddtrack.cli; ddtrack.cli.collect_garbage_rarely(); import ddtrack.scenario, ddtrack.runner, jax; "
    "ddtrack.cli.one_device_per_core(jax); ddtrack.enable_float64(); ddtrack.runner.enable_compilation_cache(); "
    "jax.numpy.zeros(1).block_until_ready(); import scipy.linalg, matplotlib.pyplot, pyarrow.parquet; "
    "ddtrack.cli.exit_now(0)"
)


def measure_cli(repeats: int) -> dict[str, object]:
    """Whole processes, interleaved so that they share the machine's load: ``python bench/python_loop.py`` (the
    case as a plain script), ``ddtrack run`` cold (an empty compile cache) and warm (that cache populated), and the
    floor: a process that only imports and starts what ``ddtrack run`` needs (FLOOR_CODE)."""
    command = ddtrack_command()
    env = {k: v for k, v in os.environ.items() if not k.startswith(("JAX_", "XLA_"))}
    cold, warm, plain, floor, entries = [], [], [], [], []
    with tempfile.TemporaryDirectory(prefix="ddtrack-bench-") as scratch:
        scratch = Path(scratch)

        def timed(args: list[str], cache: Path) -> float:
            start = time.perf_counter()
            done = subprocess.run(
                args, cwd=ROOT, env={**env, "DDTRACK_CACHE_DIR": str(cache)}, capture_output=True, text=True
            )
            elapsed = time.perf_counter() - start
            if done.returncode != 0:
                raise RuntimeError(f"`{' '.join(args)}` exited {done.returncode}:\n{done.stdout}{done.stderr}")
            return elapsed

        plain_script = [sys.executable, str(ROOT / "bench" / "python_loop.py"), str(SCENARIO)]
        for i in range(repeats):
            cache = scratch / f"cache{i}"
            cache.mkdir()
            plain.append(timed([*plain_script, "--out", str(scratch / f"states{i}.csv")], cache))
            cold.append(timed([*command, "run", str(SCENARIO), "--out", str(scratch / f"cold{i}")], cache))
            entries.append(sum(1 for p in cache.rglob("*") if p.is_file()))
            warm.append(timed([*command, "run", str(SCENARIO), "--out", str(scratch / f"warm{i}")], cache))
            floor.append(timed([sys.executable, "-c", FLOOR_CODE], cache))
        phases = json.loads(
            subprocess.run(
                [
                    sys.executable,
                    str(ROOT / "bench" / "cli_phases.py"),
                    str(SCENARIO),
                    "--json",
                    "--cache",
                    str(scratch / "cache0"),
                ],
                cwd=ROOT,
                env=env,
                capture_output=True,
                text=True,
                check=True,
            ).stdout
        )
    python_s = statistics.median(plain)
    return {
        "python_process_s": python_s,
        "python_process_min_s": min(plain),
        "cold_cli_s": statistics.median(cold),
        "cold_cli_min_s": min(cold),
        "warm_cli_s": statistics.median(warm),
        "warm_cli_min_s": min(warm),
        "ratio_cold": statistics.median(cold) / python_s,
        "ratio_cold_min": min(cold) / min(plain),
        "ratio_warm": statistics.median(warm) / python_s,
        "ratio_warm_min": min(warm) / min(plain),
        "floor_process_s": statistics.median(floor),
        "floor_process_min_s": min(floor),
        "ratio_floor": statistics.median(floor) / python_s,
        "ratio_floor_min": min(floor) / min(plain),
        "cli_repeats": repeats,
        "cli_cache_files": entries[0],
        **{f"phase_{name}": value for name, value in phases.items()},
        "cli_command": " ".join(
            [Path(command[0]).name, *command[1:], "run", "scenarios/paper_line.toml", "--out", "<tmp>"]
        ),
    }


ROWS = [
    ("compile_s", "compile (first ddtrack.run minus steady)"),
    ("single_bs_s", "ddtrack.run, one line-case run"),
    ("simulate_only_s", "  unbatched ddtrack.simulate"),
    ("single_nn_s", "NN-adaptive run (identification apart)"),
    ("nn_identification_s", "NN identification phase"),
    ("python_loop_bs_s", "plain Python loop, same run"),
    ("ratio_python_over_ddtrack", "speed-up python / ddtrack (target >= 10)"),
    ("python_loop_nn_s", "plain Python NN loop (no identification)"),
    ("ratio_python_nn_over_ddtrack", "speed-up python NN / ddtrack NN"),
    ("control_bs_s", "python-control input_output_response"),
    ("ratio_control_over_ddtrack", "speed-up python-control / ddtrack (>= 10)"),
    ("batch_bs_robot_steps_per_s", "batch backstepping (target 5 M)"),
    ("batch_nn_robot_steps_per_s", "batch NN-adaptive (target 1 M)"),
    ("python_process_s", "`python bench/python_loop.py`, whole process"),
    ("cold_cli_s", "`ddtrack run`, empty compile cache"),
    ("warm_cli_s", "`ddtrack run`, populated cache"),
    ("ratio_cold", "cold `ddtrack run` / python process (<= 6)"),
    ("ratio_warm", "warm `ddtrack run` / python process (<= 3)"),
    ("floor_process_s", "imports and JAX start of `ddtrack run` alone"),
    ("ratio_floor", "that floor / python process"),
    ("phase_total_s", "warm run in process (bench/cli_phases.py)"),
    ("phase_import_s", "  import (click, scenario, JAX)"),
    ("phase_load_s", "  load and validate the scenario"),
    ("phase_jax_s", "  switch on the compilation cache"),
    ("phase_prepare_s", "  prepare (backend start, draws)"),
    ("phase_simulate_s", "  simulate (trace, cache hit, run)"),
    ("phase_metrics_s", "  metrics"),
    ("phase_write_s", "  write the folder (figures apart)"),
    ("phase_figures_s", "  figures (four PNGs)"),
]


def table(result: dict[str, object]) -> str:
    lines = [
        f"ddtrack speed benchmark: {SCENARIO.relative_to(ROOT)}",
        f"{result['cpu']} ({result['cores']} cores), python {result['python']}, jax {result['jax']}, "
        f"numpy {result['numpy']}, {result['date']}, load average {result['load_average_start']}",
    ]
    if "n_steps" in result:
        lines += [
            f"{result['n_steps']} control periods x {result['substeps']} RK4 substeps; states agree to "
            f"{result['max_abs_state_difference']:.1e} (backstepping), "
            f"{result['max_abs_state_difference_nn']:.1e} (NN-adaptive)"
        ]
    lines.append("")
    for key, label in ROWS:
        if key not in result:
            continue
        value = result[key]
        if key.startswith("batch_"):
            size = result[key.replace("robot_steps_per_s", "best_size")]
            lines.append(f"  {label:<44} {value / 1e6:10.2f} M robot control steps/s (batch {size})")
            continue
        if key.startswith("ratio"):
            lines.append(f"  {label:<44} {value:10.1f} x   (min/min {result[key + '_min']:.1f} x)")
            continue
        if key.startswith("phase_"):
            lines.append(f"  {label:<44} {value * 1e3:10.1f} ms")
            continue
        minimum = key[:-2] + "_min_s"
        extra = f"   (min {result[minimum] * 1e3:.1f} ms)" if minimum in result else ""
        lines.append(f"  {label:<44} {value * 1e3:10.1f} ms{extra}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    parser.add_argument("--repeats", type=int, default=20, help="timed ddtrack runs (median reported)")
    parser.add_argument(
        "--python-repeats", type=int, default=None, help="timed Python-loop runs [default: min(repeats, 5)]"
    )
    parser.add_argument(
        "--python-nn-repeats", type=int, default=3, help="timed Python NN-loop runs, under a second each [default 3]"
    )
    parser.add_argument("--cli-repeats", type=int, default=3, help="cold and warm CLI runs each [default 3]")
    parser.add_argument(
        "--control-repeats",
        type=int,
        default=3,
        help="timed python-control runs (pip install -e '.[bench]'), about 1.2 s each; 0 skips them",
    )
    parser.add_argument(
        "--cli-only",
        action="store_true",
        help="only the whole-process figures: ddtrack run cold and warm against the plain Python script",
    )
    parser.add_argument(
        "--batch-sizes",
        default="256,1024",
        help="batch sizes tried for the batch throughput (comma-separated); '' skips it",
    )
    args = parser.parse_args(argv)
    if args.repeats < 1 or args.cli_repeats < 0 or args.control_repeats < 0:
        parser.error("--repeats must be >= 1, --cli-repeats and --control-repeats >= 0")
    batch_sizes = [int(size) for size in args.batch_sizes.split(",") if size.strip()]
    python_repeats = args.python_repeats if args.python_repeats is not None else min(args.repeats, 5)

    load_start = load_average()
    try:
        figures = (
            {}
            if args.cli_only
            else measure_library(
                args.repeats, max(1, python_repeats), max(1, args.python_nn_repeats), args.control_repeats, batch_sizes
            )
        )  # imports jax: first
        if args.cli_repeats or args.cli_only:
            figures.update(measure_cli(max(1, args.cli_repeats)))
    except Disagreement as exc:
        print(f"bench/speed.py: FAILED the agreement check: {exc}", file=sys.stderr)
        return 1
    result = {**machine_info(), "load_average_start": load_start, "load_average_end": load_average(), **figures}
    print(json.dumps(result, indent=2) if args.json else table(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
