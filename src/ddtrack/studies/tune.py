"""``ddtrack tune``: a controller's constant gains tuned offline by gradient descent through whole rollouts.

The loss is the paper's cost (eq. 22, J_k = e_k^T Gamma e_k / 2) summed over the control periods of each
training run, times T_c, so a time integral [m^2 s], averaged over the training scenarios and seeds, plus an
optional effort term ``effort_weight * integral (tau_R^2 + tau_L^2) dt``. The sum runs over the scenario's
metric window by default (what the metrics and Table 1 score: on the paper's cases the whole run is dominated
by the initial transient, during which the velocity clamps act and the gains hardly matter), or over the whole
run (``whole_run``). Its gradient is ``jax.grad`` through
the simulator's ``lax.scan`` (reverse mode through the RK4 substeps, the controller and its clamps). The gains are
optimised in log space with Adam, so they stay positive, and clipped to ``[gain_min, gain_max]``.

This gives the paper's online gain law (model.md §3) a fair opponent: backstepping whose constant gains were chosen
as well as the same cost allows on the same training runs, instead of by hand.
"""

from __future__ import annotations

import dataclasses
import json
import math
import operator
from collections.abc import Callable, Sequence
from functools import reduce
from pathlib import Path
from typing import IO, Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import tomli_w

from ..errors import ConfigError
from ..integrators import RK4
from ..metrics import window_mask
from ..outdir import atomic_write
from ..runner import prepare_batch
from ..scenario import Scenario, Setup, controller_output, tunable_kinds
from ..sim import ClosedLoop, Draws, repeated, simulate_batch

#: the fields of the outer law that the tuned gains replace, in the scenario's ``gains`` order; the kinds whose
#: gains can be tuned are the registry's (:func:`ddtrack.scenario.tunable_kinds`: differentiable, Kanayama, torque)
GAIN_FIELDS = ("kx", "ky", "ktheta")
#: Gamma of eq. 22 by default: (1, 1, 0) makes J_k = e_tr^2 / 2, the tracking error the metrics and Table 1 score.
#: The NN gain law's own (1, 50, 1) weighs the lateral error 50 times: tuned on it, backstepping trades a longer
#: along-track lag for a smaller lateral error and ends with a larger e_tr (docs/tuning.md).
DEFAULT_GAMMA = (1.0, 1.0, 0.0)


class Problem(NamedTuple):
    """One training scenario: its prepared batch of seeds and how to simulate it."""

    scenario: Scenario
    setup: Setup  #: a batch: every array with a leading axis over the seeds
    draws: Draws
    divergence_error: float  #: [m], :meth:`Scenario.divergence_distance`, found before any tracing


class TuneResult(NamedTuple):
    """The outcome of :func:`tune`: the best gains seen, the descent's history, and its first and best loss
    (:func:`total_loss`, the paper's cost eq. 22 integrated over each run's window; m^2 s with the default
    weights)."""

    gains: tuple[float, ...]  #: the tuned gains
    history: list[dict]  #: per iteration: loss, gains, gradient
    initial_loss: float
    final_loss: float


UNTUNABLE_PLANTS = ("slip", "slip_velocity")  #: plants whose substep loop runs a traced count (a while loop)


def problems(scenarios: Sequence[Scenario], seeds: Sequence[int]) -> list[Problem]:
    """Each training scenario prepared once for all the seeds (one vmapped batch each)."""
    tunable = tunable_kinds()
    for scenario in scenarios:
        if scenario.controller.kind not in tunable:
            raise ConfigError(
                "--controller",
                f"'{scenario.controller.kind}' has no tunable gains here",
                f"tune one of: {', '.join(tunable)}",
            )
        if scenario.plant.model in UNTUNABLE_PLANTS:
            raise ConfigError(
                "plant.model",
                f"'{scenario.plant.model}' cannot be tuned through: its integration adapts its steps to the robot "
                "(a loop whose length is a number), which reverse-mode gradients cannot pass",
                'tune on the robot\'s identified lag model (plant.model = "lag") or the unicycle, then compare the '
                "gains on this plant with ddtrack bench --scenario",
            )
    return [
        Problem(scenario, *prepare_batch(scenario, list(seeds)), scenario.divergence_distance())
        for scenario in scenarios
    ]


def rollout_loss(
    problem: Problem, gains: jax.Array, gamma: jax.Array, effort_weight: float, whole_run: bool = False
) -> jax.Array:
    """Mean over the batch's runs of sum_k (J_k (eq. 22) + effort_weight |tau_k|^2) T_c, over the metric window
    (or the whole run)."""
    sim = problem.scenario.simulation
    fields = GAIN_FIELDS
    controller = problem.setup.controller
    runs = len(problem.setup.x0)
    outer = dataclasses.replace(
        controller.outer, **{f: jnp.broadcast_to(gains[i], (runs,)) for i, f in enumerate(fields)}
    )
    setup = problem.setup
    loop = ClosedLoop(
        setup.plant,
        dataclasses.replace(controller, outer=outer),
        setup.trajectory,
        setup.disturbance,
        setup.noise,
        control_period=sim.control_period,
        divergence_error=problem.divergence_error,
        solver=RK4(sim.substeps),
    )
    result = simulate_batch(repeated(loop, runs), setup.x0, problem.draws, n_steps=sim.n_steps)
    t = np.arange(sim.n_steps) * sim.control_period
    counted = np.ones(sim.n_steps) if whole_run else window_mask(t, sim.window).astype(float)
    per_period = 0.5 * jnp.sum(gamma * result.error**2, axis=-1) + effort_weight * jnp.sum(result.control**2, axis=-1)
    return jnp.mean(jnp.sum(per_period * counted, axis=1)) * sim.control_period


def total_loss(
    training: Sequence[Problem], log_gains: jax.Array, gamma: jax.Array, effort_weight: float, whole_run: bool = False
) -> jax.Array:
    """The mean of :func:`rollout_loss` over the training scenarios, as a function of log(gains)."""
    gains = jnp.exp(log_gains)
    losses = [rollout_loss(p, gains, gamma, effort_weight, whole_run) for p in training]
    return reduce(operator.add, losses) / len(training)  # summed in order, as sum() would


def tune(
    training: Sequence[Problem],
    initial: Sequence[float],
    *,
    steps: int = 40,
    learning_rate: float = 0.1,
    gamma: Sequence[float] = DEFAULT_GAMMA,
    effort_weight: float = 0.0,
    whole_run: bool = False,
    gain_min: Sequence[float] = (0.05, 0.5, 0.05),
    gain_max: Sequence[float] = (20.0, 2000.0, 200.0),
    on_step: Callable[[dict], None] = lambda record: None,
) -> TuneResult:
    """Adam on log(gains) for ``steps`` iterations; keeps the best gains seen (the loss is not convex).

    A step whose loss or gradient is not finite (a run that blew up) is undone and the step size halved.
    """
    if effort_weight > 0 and any(controller_output(p.scenario.controller) != "torque" for p in training):
        raise ConfigError(
            "--effort-weight",
            'the effort term integrates wheel torques, and a controller over cmd_vel (inner = "none") commands none',
            "drop --effort-weight, or tune over an inner loop",
        )
    gamma_array = jnp.asarray(gamma, float)
    loss_and_grad = jax.jit(
        jax.value_and_grad(lambda lg: total_loss(training, lg, gamma_array, effort_weight, whole_run))
    )
    low, high = np.log(np.asarray(gain_min, float)), np.log(np.asarray(gain_max, float))
    log_gains = np.clip(np.log(np.asarray(initial, float)), low, high)
    first, second = np.zeros_like(log_gains), np.zeros_like(log_gains)
    rate, history = learning_rate, list[dict[str, Any]]()
    best = (math.inf, log_gains)
    for step in range(steps + 1):  # the last evaluation only scores the final gains
        loss, grad = (np.asarray(v, float) for v in loss_and_grad(jnp.asarray(log_gains)))
        finite = bool(np.isfinite(loss) and np.all(np.isfinite(grad)))
        record = {
            "step": step,
            "loss": float(loss) if finite else None,
            "gains": [float(g) for g in np.exp(log_gains)],
            "learning_rate": rate,
        }
        history.append(record)
        on_step(record)
        if finite and loss < best[0]:
            best = (float(loss), log_gains)
        if step == steps:
            break
        if not finite:  # back to the best point, smaller steps
            log_gains, rate = best[1], rate / 2
            continue
        first = 0.9 * first + 0.1 * grad
        second = 0.999 * second + 0.001 * grad**2
        update = (first / (1 - 0.9 ** (step + 1))) / (np.sqrt(second / (1 - 0.999 ** (step + 1))) + 1e-8)
        log_gains = np.clip(log_gains - rate * update, low, high)
    if history[0]["loss"] is None:
        raise ConfigError(
            "controller.gains",
            "the initial gains already give non-finite runs",
            "start from gains that track, e.g. the scenario's own",
        )
    return TuneResult(tuple(float(g) for g in np.exp(best[1])), history, history[0]["loss"], best[0])


def write(out: Path, result: TuneResult, kind: str, settings: dict) -> None:
    """``tuned.toml`` (a scenario fragment: ``[controller]`` with the tuned gains), ``loss.csv``, ``tune.json``
    and ``loss.png``, each written atomically."""
    fragment = {"controller": {"kind": kind, "gains": list(result.gains)}}
    header = "# ddtrack tune: paste into a scenario, or pass as --set controller.gains=[...]\n"
    atomic_write(out / "tuned.toml", lambda f: f.write((header + tomli_w.dumps(fragment)).encode()))
    lines = ["step,loss,kx,ky,ktheta,learning_rate"] + [
        ",".join(
            [
                str(r["step"]),
                "" if r["loss"] is None else repr(r["loss"]),
                *map(repr, r["gains"]),
                repr(r["learning_rate"]),
            ]
        )
        for r in result.history
    ]
    atomic_write(out / "loss.csv", lambda f: f.write(("\n".join(lines) + "\n").encode()))
    summary = {
        "kind": kind,
        "gains": list(result.gains),
        "initial_loss": result.initial_loss,
        "final_loss": result.final_loss,
        "settings": settings,
        "history": result.history,
    }
    atomic_write(out / "tune.json", lambda f: f.write((json.dumps(summary, indent=2) + "\n").encode()))
    atomic_write(out / "loss.png", lambda f: _loss_figure(result, f))


def _loss_figure(result: TuneResult, file: IO[bytes]) -> None:
    import matplotlib.pyplot as plt

    steps = [r["step"] for r in result.history if r["loss"] is not None]
    losses = [r["loss"] for r in result.history if r["loss"] is not None]
    fig, ax = plt.subplots(figsize=(6, 3.5), layout="constrained")
    ax.semilogy(steps, losses, marker="o", markersize=3)
    ax.set(xlabel="iteration", ylabel="loss: sum of J_k T_c (eq. 22)", title="ddtrack tune")
    ax.grid(True, which="both", alpha=0.3)
    fig.savefig(file, format="png", dpi=120)
    plt.close(fig)
