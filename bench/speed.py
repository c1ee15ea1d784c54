"""Speed benchmark: ddtrack against a plain Python loop on the paper's line case (docs/benchmarks.md).

    python bench/speed.py [--json] [--repeats N] [--python-repeats M] [--cli-repeats K] [--batch B]

In one process, in this order:

1. ``compile_s``: the first ``ddtrack.run`` on scenarios/paper_line.toml (trace + XLA compile + run)
   minus the median steady-state run. JAX's persistent cache is off in this process, so it is a
   real compile; the JAX backend is started before, so its start-up is not counted.
2. The check: the plain Python loop (bench/python_loop.py) and ddtrack must give the same states
   (max |difference| over every recorded state <= 1e-8), or the script stops with exit code 1.
3. ``single_bs_s``: median wall time of ``ddtrack.run(scenario)`` (randomness drawn from the seed,
   then the jitted ``lax.scan``), waited for with ``jax.block_until_ready``; ``simulate_only_s``
   is ``ddtrack.simulate`` alone on the prepared arguments.
4. ``python_loop_bs_s``: median wall time of the same run by the Python loop;
   ``ratio_python_over_ddtrack`` = python_loop_bs_s / single_bs_s (the target is >= 10).
5. ``batch_s``: optional, ``jax.vmap`` of ``ddtrack.simulate`` over B initial poses (--batch 0 skips).
6. ``cold_cli_s`` / ``warm_cli_s``: wall time of a whole ``ddtrack run scenarios/paper_line.toml
   --out <tmp>`` subprocess (interpreter start, imports, compile, run, metrics, writing the run
   folder) with DDTRACK_CACHE_DIR pointing at a fresh empty folder (cold), then at that folder once
   populated (warm). Each cold repeat gets its own fresh folder.

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
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SCENARIO = ROOT / "scenarios" / "paper_line.toml"
TOLERANCE = 1e-8  # max |python - ddtrack| over every recorded state component

sys.path.insert(0, str(Path(__file__).resolve().parent))


class Disagreement(RuntimeError):
    """The Python loop and ddtrack do not simulate the same thing: no timing comparison is honest."""


def timings(fn: Callable[[], object], repeats: int) -> list[float]:
    """Wall times [s] of ``repeats`` calls of ``fn`` (which must wait for its own result)."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return times


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
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
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
        raise Disagreement(f"python loop and ddtrack disagree by {difference:.3g} (> {TOLERANCE:g}), first worst at "
                           f"row {row}: python {a[row].tolist()} vs ddtrack {b[row].tolist()}")
    return difference


def measure_library(repeats: int, python_repeats: int, batch: int) -> dict[str, object]:
    start = time.perf_counter()
    import jax
    import jax.numpy as jnp

    import ddtrack
    from ddtrack.model import DynamicPlant
    from python_loop import params_from_scenario, run_backstepping

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

    single = timings(run_ddtrack, repeats)

    setup, draws = ddtrack.prepare(scenario)
    sim = scenario.simulation
    plant = DynamicPlant(setup.plant_params)
    options = dict(n_steps=sim.n_steps, control_period=sim.control_period, substeps=sim.substeps,
                   disturbance=setup.disturbance, noise=setup.noise, divergence_error=sim.divergence_error)
    x0 = jnp.asarray(setup.x0)

    def simulate_only():
        return jax.block_until_ready(ddtrack.simulate(plant, setup.controller, setup.trajectory, x0, draws, **options))

    simulate_only()
    simulate = timings(simulate_only, repeats)

    python = timings(lambda: run_backstepping(**params), python_repeats)

    # NN-adaptive: the control loop of one run (emulator training and gain law every period); its
    # identification phase is a separate one-off cost, timed apart (compile excluded in both)
    from ddtrack.runner import run_setup

    nn_scenario = ddtrack.load_scenario(SCENARIO, controller="nn_adaptive_backstepping")
    nn_setup, nn_draws = ddtrack.prepare(nn_scenario)
    nn_identify = timings(lambda: jax.block_until_ready(ddtrack.prepare(nn_scenario)[0].identification), 2)
    jax.block_until_ready(run_setup(nn_scenario, nn_setup, nn_draws))
    single_nn = timings(lambda: jax.block_until_ready(run_setup(nn_scenario, nn_setup, nn_draws)), repeats)

    figures: dict[str, object] = {
        "scenario": str(SCENARIO.relative_to(ROOT)),
        "n_steps": sim.n_steps,
        "substeps": sim.substeps,
        "max_abs_state_difference": difference,
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
        "repeats": repeats,
        "python_repeats": python_repeats,
    }
    if batch > 0:
        figures.update(measure_batch(jax, jnp, ddtrack, plant, setup, draws, options, x0, batch, max(3, repeats // 4)))
    return figures


def measure_batch(jax, jnp, ddtrack, plant, setup, draws, options, x0, size, repeats) -> dict[str, object]:
    """``size`` robots starting 0..5 m further from the line, in one ``vmap`` over the initial state."""
    starts = x0 + jnp.linspace(0.0, 5.0, size)[:, None] * jnp.array([0.0, 1.0, 0.0, 0.0, 0.0])
    batched = jax.jit(jax.vmap(lambda z: ddtrack.simulate(plant, setup.controller, setup.trajectory, z, draws,
                                                          **options)))

    def run_batch():
        return jax.block_until_ready(batched(starts))

    start = time.perf_counter()
    run_batch()
    first_s = time.perf_counter() - start
    times = timings(run_batch, repeats)
    return {"batch_size": size, "batch_compile_s": first_s - statistics.median(times),
            "batch_s": statistics.median(times), "batch_per_robot_s": statistics.median(times) / size}


def ddtrack_command() -> list[str]:
    """The installed ``ddtrack`` script next to this interpreter, else ``python -m ddtrack``."""
    script = Path(sys.executable).parent / "ddtrack"
    if script.exists():
        return [str(script)]
    found = shutil.which("ddtrack")
    return [found] if found else [sys.executable, "-m", "ddtrack"]


def measure_cli(repeats: int) -> dict[str, object]:
    command = ddtrack_command()
    env = {k: v for k, v in os.environ.items() if not k.startswith(("JAX_", "XLA_"))}
    cold, warm, entries = [], [], []
    with tempfile.TemporaryDirectory(prefix="ddtrack-bench-") as scratch:
        scratch = Path(scratch)

        def run_cli(cache: Path, out: Path) -> float:
            start = time.perf_counter()
            done = subprocess.run([*command, "run", str(SCENARIO), "--out", str(out)], cwd=ROOT,
                                  env={**env, "DDTRACK_CACHE_DIR": str(cache)}, capture_output=True, text=True)
            elapsed = time.perf_counter() - start
            if done.returncode != 0:
                raise RuntimeError(f"`ddtrack run` exited {done.returncode}:\n{done.stdout}{done.stderr}")
            return elapsed

        for i in range(repeats):
            cache = scratch / f"cache{i}"
            cache.mkdir()
            cold.append(run_cli(cache, scratch / f"cold{i}"))
            entries.append(sum(1 for p in cache.rglob("*") if p.is_file()))
        for i in range(repeats):
            warm.append(run_cli(scratch / "cache0", scratch / f"warm{i}"))
    return {"cold_cli_s": statistics.median(cold), "cold_cli_min_s": min(cold), "warm_cli_s": statistics.median(warm),
            "warm_cli_min_s": min(warm), "cli_repeats": repeats, "cli_cache_files": entries[0],
            "cli_command": " ".join([Path(command[0]).name, *command[1:], "run", "scenarios/paper_line.toml",
                                     "--out", "<tmp>"])}


ROWS = [
    ("compile_s", "compile (first ddtrack.run minus steady)"),
    ("single_bs_s", "ddtrack.run, one line-case run"),
    ("simulate_only_s", "  of which ddtrack.simulate"),
    ("single_nn_s", "NN-adaptive run (identification apart)"),
    ("nn_identification_s", "NN identification phase"),
    ("python_loop_bs_s", "plain Python loop, same run"),
    ("ratio_python_over_ddtrack", "speed-up python / ddtrack (target >= 10)"),
    ("batch_s", "vmap batch"),
    ("batch_per_robot_s", "  per robot"),
    ("cold_cli_s", "`ddtrack run`, empty compile cache"),
    ("warm_cli_s", "`ddtrack run`, populated cache"),
]


def table(result: dict[str, object]) -> str:
    lines = [f"ddtrack speed benchmark: {result['scenario']}, {result['n_steps']} control periods x "
             f"{result['substeps']} RK4 substeps",
             f"{result['cpu']} ({result['cores']} cores), python {result['python']}, jax {result['jax']}, "
             f"numpy {result['numpy']}, {result['date']}",
             f"states agree to {result['max_abs_state_difference']:.1e}", ""]
    for key, label in ROWS:
        if key not in result:
            continue
        value = result[key]
        if key == "batch_s":
            label = f"vmap batch of {result['batch_size']} robots, all of it"
        if key.startswith("ratio"):
            lines.append(f"  {label:<44} {value:10.1f} x   (min/min {result[key + '_min']:.1f} x)")
            continue
        minimum = key[:-2] + "_min_s"
        extra = f"   (min {result[minimum] * 1e3:.1f} ms)" if minimum in result else ""
        lines.append(f"  {label:<44} {value * 1e3:10.1f} ms{extra}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    parser.add_argument("--repeats", type=int, default=20, help="timed ddtrack runs (median reported)")
    parser.add_argument("--python-repeats", type=int, default=None,
                        help="timed Python-loop runs [default: min(repeats, 5)]")
    parser.add_argument("--cli-repeats", type=int, default=3, help="cold and warm CLI runs each [default 3]")
    parser.add_argument("--batch", type=int, default=100, help="robots in the vmap batch; 0 skips it")
    args = parser.parse_args(argv)
    if args.repeats < 1 or args.cli_repeats < 0 or args.batch < 0:
        parser.error("--repeats must be >= 1, --cli-repeats and --batch >= 0")
    python_repeats = args.python_repeats if args.python_repeats is not None else min(args.repeats, 5)

    load_start = load_average()
    try:
        figures = measure_library(args.repeats, max(1, python_repeats), args.batch)  # imports jax: first
        if args.cli_repeats:
            figures.update(measure_cli(args.cli_repeats))
    except Disagreement as exc:
        print(f"bench/speed.py: FAILED the agreement check: {exc}", file=sys.stderr)
        return 1
    result = {**machine_info(), "load_average_start": load_start, "load_average_end": load_average(), **figures}
    print(json.dumps(result, indent=2) if args.json else table(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
