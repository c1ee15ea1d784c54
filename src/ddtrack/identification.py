"""The identification phase of the NN-adaptive controller (model.md §3.7, "N_c = 100 repeat cycle").

Before an experiment, with its own seed: run the fixed-gain backstepping controller on an exciting
reference with a small command dither on the *true* plant (the scenario's plant behind its sensing, under the
controller's inner loop or, for ``inner = "none"``, commanded in velocity), collect the transitions
(z_k = [nu_c(k), nu(k)], body-frame increment of q_k -> q_k+1), and train the emulator for N_c
shuffled epochs of per-sample backpropagation with momentum.
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from ._ordered import total
from ._pytree import FloatVector
from .controllers import Backstepping, Cascade, Dithered, Emulator, NNAdaptiveParameters, VelocityOutput
from .controllers.nn import backprop, forward, momentum_step, sample_loss, zeros_like
from .geometry import body_increment
from .integrators import RK4
from .layout import BODY
from .model import DynamicPlant, MeasurementNoise, Plant, RobotParams, WheelDisturbance
from .parameters import TIMING
from .sim import ClosedLoop, Draws, simulate
from .trajectories import SampledTrajectory, unicycle_reference


class Identification(NamedTuple):
    """The trained emulator and how well it learned."""

    emulator: Emulator
    epoch_loss: Array  #: (epochs,) mean normalised sample loss during each epoch
    nmse: Array  #: (3,) normalised mean squared prediction error per output on the data, after training
    samples: int


#: Peak speed [m/s] and yaw rate [rad/s] of the unscaled exciting reference.
REFERENCE_PEAKS = (0.9, 0.7)
#: Fraction of the command clamps the scaled reference may reach (room for the feedback and the dither).
CLAMP_MARGIN = 0.8


def identification_scale(
    max_velocity: float, max_yaw_rate: float, peaks: tuple[float, float] | None = None
) -> tuple[float, float]:
    """(k_v, k_omega): how much to shrink the exciting reference, the dither and the emulator's scales so that
    the identification stays inside the clamps. Data taken against a clamp says nothing about the command's
    effect, so a robot slower than the paper's would otherwise learn nothing. ``peaks`` overrides the peak
    (speed, yaw rate); by default min(0.9, 0.8 v_max) and min(0.7, 0.8 omega_max), i.e. 1 for the paper's robot."""
    if peaks is None:
        peaks = (
            min(REFERENCE_PEAKS[0], CLAMP_MARGIN * max_velocity),
            min(REFERENCE_PEAKS[1], CLAMP_MARGIN * max_yaw_rate),
        )
    return peaks[0] / REFERENCE_PEAKS[0], peaks[1] / REFERENCE_PEAKS[1]


def exciting_reference(
    duration: float, control_period: float, scale: tuple[float, float] = (1.0, 1.0)
) -> SampledTrajectory:
    """v_r = k_v (0.5 + 0.3 sin 0.3t + 0.1 sin(1.3t + 1)), omega_r = k_omega (0.4 sin 0.5t + 0.3 sin 1.7t)
    (model.md §3.7 at k = 1): speeds in k_v [0.1, 0.9] m/s and yaw rates in k_omega [-0.7, 0.7] rad/s."""
    k_v, k_w = scale
    return unicycle_reference(
        lambda t: k_v * (0.5 + 0.3 * jnp.sin(0.3 * t) + 0.1 * jnp.sin(1.3 * t + 1.0)),
        lambda t: k_w * (0.4 * jnp.sin(0.5 * t) + 0.3 * jnp.sin(1.7 * t)),
        duration=duration,
        step=control_period,
    )


def collect(
    plant: RobotParams | Plant,
    inner: object | None,
    emulator: Emulator,
    key: Array,
    *,
    duration: float,
    control_period: float,
    substeps: int,
    dither: Array,
    gains: Array,
    limits: Array,
    disturbance: WheelDisturbance,
    noise: MeasurementNoise,
    reference_scale: tuple[float, float] = (1.0, 1.0),
) -> tuple[Array, Array]:
    """Run the identification experiment on ``plant`` (a plant, or the parameters of the dynamic plant) under
    ``inner`` (None: the dithered law's command is the plant's velocity input); return inputs z (n, n_in) and
    targets (n, 3) [physical units] of the true state."""
    trajectory = exciting_reference(duration, control_period, reference_scale)
    outer = Dithered(
        Backstepping(kx=gains[0], ky=gains[1], ktheta=gains[2], max_velocity=limits[0], max_yaw_rate=limits[1]),
        std=dither,
    )
    n = round(duration / control_period)
    k_dist, k_noise, k_ctrl = jax.random.split(key, 3)
    draws = Draws(jax.random.normal(k_dist, (n, 2)), jax.random.normal(k_noise, (n, 5)), k_ctrl)
    ref0 = trajectory(0.0)
    x0 = jnp.stack([ref0.x, ref0.y, ref0.theta, 0.0, 0.0])
    loop = ClosedLoop(
        DynamicPlant(plant) if isinstance(plant, RobotParams) else plant,
        VelocityOutput(outer) if inner is None else Cascade(outer, inner),
        trajectory,
        disturbance,
        noise,
        control_period=control_period,
        solver=RK4(substeps),
    )
    result = simulate(loop, x0, draws, n_steps=n)
    nu_c = jnp.stack([result.logs["v_cmd"], result.logs["omega_cmd"]], axis=1)
    posture = BODY.span(result.state, "x", "theta")
    z = jax.vmap(emulator.inputs)(nu_c, BODY.span(result.state, "v", "omega"))[:-1]
    targets = jax.vmap(body_increment)(posture[:-1], posture[1:])
    return z, targets


def train(
    emulator: Emulator,
    z: Array,
    targets: Array,
    key: Array,
    *,
    epochs: int,
    learning_rate: float,
    momentum: float,
    clip_norm: float,
) -> tuple[Emulator, Array]:
    """``epochs`` shuffled passes of per-sample momentum SGD; returns the emulator and the epoch losses."""
    zn, tn = z / emulator.scales.inputs, targets / emulator.scales.outputs

    def sample_step(carry, i):
        mlp, velocity = carry
        loss = sample_loss(mlp, zn[i], tn[i])
        mlp, velocity = momentum_step(
            mlp,
            velocity,
            backprop(mlp, zn[i], tn[i]),
            learning_rate=learning_rate,
            momentum=momentum,
            clip_norm=clip_norm,
        )
        return (mlp, velocity), loss

    def epoch(carry, epoch_key):
        carry, losses = jax.lax.scan(sample_step, carry, jax.random.permutation(epoch_key, zn.shape[0]))
        return carry, total(losses) / losses.shape[0]  # in a fixed order, whatever the batch (_ordered.py)

    (mlp, _), losses = jax.lax.scan(epoch, (emulator.mlp, zeros_like(emulator.mlp)), jax.random.split(key, epochs))
    return emulator.__class__(mlp, emulator.scales, emulator.uses_velocity), losses


def prediction_nmse(emulator: Emulator, z: Array, targets: Array) -> Array:
    """Mean squared error over the variance, per output channel; both means summed in a fixed order, so that a run's
    NMSE is the same bits alone and in any batch (a reduce kernel's order followed the batch: ``_ordered.py``)."""
    predictions = jax.vmap(lambda zi: forward(emulator.mlp, zi / emulator.scales.inputs)[0])(z)
    predictions = predictions * emulator.scales.outputs
    n = targets.shape[0]
    mean = lambda x: jax.vmap(total, in_axes=1)(x) / n  # noqa: E731  # per channel: sum_i x[i, j] / n
    return mean((predictions - targets) ** 2) / mean((targets - mean(targets)) ** 2)


# one compiled program: run op by op, its glue (the exciting reference, the draws, the samples) was some 90 small
# programs, each traced and looked up on its own (0.5 s of a warm NN-adaptive `ddtrack run`, docs/benchmarks.md)
#: the NN-adaptive law's declared defaults: identify's keyword defaults are the scenario's
_NN = {name: field.default for name, field in NNAdaptiveParameters.model_fields.items()}


@partial(jax.jit, static_argnames=("duration", "epochs", "control_period", "substeps", "reference_scale"))
def identify(
    plant: RobotParams | Plant,
    inner: object | None,
    emulator: Emulator,
    key: Array,
    *,
    duration: float = _NN["identification_duration"],
    epochs: int = _NN["epochs"],
    control_period: float = TIMING.control_period,
    substeps: int = TIMING.substeps,
    dither: FloatVector = (0.05, 0.1),
    gains: FloatVector = (1.0, 55.0, 15.0),
    limits: FloatVector = (2.0, 4.0),
    learning_rate: float = _NN["learning_rate"],
    momentum: float = _NN["momentum"],
    clip_norm: float = _NN["gradient_clip"],
    disturbance: WheelDisturbance = WheelDisturbance(),
    noise: MeasurementNoise = MeasurementNoise(),
    reference_scale: tuple[float, float] = (1.0, 1.0),
) -> Identification:
    """Collect identification data on ``plant`` (a plant, or the dynamic plant's parameters) under ``inner``
    (None: velocity commands) and train ``emulator`` on it (model.md §3.7 schedule, step 1); ``reference_scale``
    is :func:`identification_scale`'s (k_v, k_omega). Compiled as one program for each ``duration``, ``epochs``,
    ``control_period``, ``substeps`` and ``reference_scale`` (static); the other arguments may vary without a
    compile."""
    k_data, k_train = jax.random.split(key)
    z, targets = collect(
        plant,
        inner,
        emulator,
        k_data,
        duration=duration,
        control_period=control_period,
        substeps=substeps,
        dither=jnp.asarray(dither, float),
        gains=jnp.asarray(gains, float),
        limits=jnp.asarray(limits, float),
        disturbance=disturbance,
        noise=noise,
        reference_scale=reference_scale,
    )
    trained, losses = _train_jit(
        emulator,
        z,
        targets,
        k_train,
        epochs=epochs,
        learning_rate=learning_rate,
        momentum=momentum,
        clip_norm=clip_norm,
    )
    return Identification(trained, losses, prediction_nmse(trained, z, targets), int(z.shape[0]))


_train_jit = jax.jit(train, static_argnames=("epochs",))
