"""NN-adaptive backstepping: Kanayama gains tuned online by gradient descent through the Jacobian of
an emulator network that learns the robot (the paper's contribution; model.md §3, pseudo-code 3.8).

One control period (model.md §3.8)::

    e        = posture_error(y_k, ref_k)
    emulator <- one momentum-SGD step on the last transition (z_{k-1}, body_increment(q_{k-1}, q_k))
    if gate (|e_xy| < e_gate, no saturation at k-1, t >= freeze_time):
        g     = (Gamma e) D_b J_b^n Phi                      eqs. 22-25, 34 corrected
        dA    = clip(-T_c Lambda g + beta_K dA_prev - T_c sigma (A - A_0), +-dA_max)
        A     = clip(A + dA, A_min, A_max)
    nu_c     = clamp(kanayama(e, ref, A)),  nu_c_dot analytic   eq. 12, model.md §2.5
    z_k      = [nu_c, nu_k]                                  the emulator's next training input
"""

from __future__ import annotations

from typing import Annotated, Any, Literal, NamedTuple

import jax
import jax.numpy as jnp
from jax import Array
from pydantic import Field

from .._pytree import FloatVector, pytree_dataclass, static_field
from ..geometry import body_increment, posture_error, rotation
from ..layout import pose, pose_vector, velocity
from ..parameters import NonNegative, Parameters, Positive, PositiveTriple, Structure, declared
from ..trajectories import Reference
from .backstepping import StrictTerm, VelocityClamps, kanayama_command, velocity_command
from .base import Logs, VelocityCommand
from .nn import MLP, Scales, backprop, input_jacobian, momentum_step, sample_loss, zeros_like

JACOBIANS = ("network", "analytic", "quasi_static", "model", "model_sensitivity")
ERROR_JACOBIANS = ("exact", "paper")
Fraction = Annotated[float, Field(ge=0.0, lt=1.0)]


class NNAdaptiveParameters(Parameters):
    """The NN-adaptive law's own parameters (model.md §3): the gain law, the emulator, and its identification."""

    rates: tuple[NonNegative, NonNegative, NonNegative] = Field(
        (200.0, 200.0, 200.0),
        description=("Lambda: gain adaptation rates [1/s] with the normalised Jacobian; 0 gives backstepping."),
    )
    gain_momentum: Fraction = Field(0.0, description="beta_K, momentum of the gains.")
    max_step: PositiveTriple = Field((0.05, 5.0, 0.5), description="Largest gain change per control period.")
    gain_min: PositiveTriple = Field((0.1, 1.0, 0.1), description="Lower gain bounds (Kx, Ky, Ktheta).")
    gain_max: PositiveTriple = Field((10.0, 600.0, 60.0), description="Upper gain bounds (Kx, Ky, Ktheta).")
    gate_error: Positive = Field(0.5, description="Gains adapt only while e_tr is below this [m].")
    leakage: NonNegative = Field(0.0, description="sigma: pull of the gains back to their initial values [1/s].")
    gamma: tuple[NonNegative, NonNegative, NonNegative] = Field(
        (1.0, 50.0, 1.0), description=("Gamma of the cost eq. 22, weights of (e_x, e_y, e_theta).")
    )
    jacobian: Structure[Literal["network", "analytic", "quasi_static", "model", "model_sensitivity"]] = Field(
        "network",
        description=(
            "Plant Jacobian of the gain law: the emulator's (eq. 34), analytic per-sample, "
            "quasi-static, the nominal model's by autodiff, or that in the multi-step sensitivity."
        ),
    )
    error_jacobian: Structure[Literal["exact", "paper"]] = Field(
        "exact", description=("d e_p / d q: exact (model.md §3.3) or the paper's approximation -T_e.")
    )
    emulator: Structure[Literal["E1", "E0"]] = Field(
        "E1", description=("E1: input (v_c, omega_c, v, omega); E0: the paper's (v_c, omega_c).")
    )
    hidden_units: Structure[int] = Field(20, ge=1, le=1000, description="Hidden tanh units N_h.")
    learning_rate: Positive = Field(0.2, description="Emulator backpropagation rate eta.")
    momentum: Fraction = Field(0.3, description="Emulator momentum beta.")
    gradient_clip: Positive = Field(5.0, description="Emulator gradient-norm clip.")
    online_learning: Structure[bool] = Field(True, description="Train the emulator on every new sample.")
    learn_saturated: bool = Field(
        False,
        description=("Also train the emulator online on transitions during which a clamp or the torque limit acted."),
    )
    structured_jacobian: bool = Field(False, description="Keep only the two direct, positive Jacobian entries.")
    identification: Structure[bool] = Field(True, description="Pre-train the emulator on an identification run.")
    identification_duration: Structure[Positive] = Field(
        60.0, le=3600.0, description="Length of the identification run [s]."
    )
    epochs: Structure[int] = Field(
        100, ge=1, le=10_000, description="N_c: pre-training epochs over the identification data."
    )
    identification_speed: tuple[Positive, Positive] | None = Field(
        None,
        description=(
            "Peak (speed [m/s], yaw rate [rad/s]) of the identification reference; default "
            "(min(0.9, 0.8 max_velocity), min(0.7, 0.8 max_yaw_rate)), inside the clamps."
        ),
    )
    dither: tuple[NonNegative, NonNegative] | None = Field(
        None,
        description=(
            "Command dither (sigma_v [m/s], sigma_omega [rad/s]) of the identification run; default "
            "(0.05, 0.1) scaled like the identification reference."
        ),
    )
    freeze_time: NonNegative | None = Field(
        None, description=("No gain change before this time [s]; default 0 with identification, 2 without.")
    )


@pytree_dataclass
class Emulator:
    """The network and its fixed scales. E1 (``uses_velocity``): input [v_c, omega_c, v, omega];
    E0: input [v_c, omega_c]. Output: the body-frame one-step pose increment (model.md §3.7)."""

    mlp: MLP
    scales: Scales
    uses_velocity: bool = static_field(default=True, why="the network's input size: E1 reads the velocity, E0 not")

    def inputs(self, nu_c: Array, nu: Array) -> Array:
        return jnp.concatenate([nu_c, nu]) if self.uses_velocity else nu_c


def emulator_scales(
    control_period: float, *, uses_velocity: bool, max_velocity: float = 1.0, max_yaw_rate: float = 2.0
) -> Scales:
    """s_z = [v_max, w_max(, v_max, w_max)], s_y = [T_c v_max, 0.05 T_c v_max, T_c w_max] (model.md §3.7)."""
    inputs = [max_velocity, max_yaw_rate] * (2 if uses_velocity else 1)
    tv = control_period * max_velocity
    return Scales(
        inputs=jnp.asarray(inputs, float), outputs=jnp.asarray([tv, 0.05 * tv, control_period * max_yaw_rate], float)
    )


def one_step_coefficient(bandwidth: Array, control_period: float) -> Array:
    """c = T_c - (1 - exp(-k T_c)) / k: displacement per sample per unit command for an inner loop of
    bandwidth k [1/s] (model.md §3.4 (a), the consistent reading of the paper's eqs. 27-31)."""
    return control_period - (1.0 - jnp.exp(-bandwidth * control_period)) / bandwidth


def error_jacobian_body(error: Array, exact: bool) -> Array:
    """D_b = D R_3(theta) = [[-1, 0, e_y], [0, -1, -e_x], [0, 0, -1]] (model.md §3.3); the paper's
    D ~ -T_e gives -I."""
    if not exact:
        return -jnp.eye(3)
    return jnp.array([[-1.0, 0.0, error[1]], [0.0, -1.0, -error[0]], [0.0, 0.0, -1.0]])


def gain_sensitivity(error: Array, ref: Reference) -> Array:
    """Phi = d nu_c / d(Kx, Ky, Ktheta) = [[e_x, 0, 0], [0, v_r e_y, v_r sin e_th]] (eq. 24 corrected)."""
    zero = jnp.zeros_like(error[0])
    return jnp.array([[error[0], zero, zero], [zero, ref.v * error[1], ref.v * jnp.sin(error[2])]])


def cost_gradient(error: Array, ref: Reference, gamma: Array, plant_jacobian_body: Array, exact: bool) -> Array:
    """dJ/dalpha = e^T Gamma D_b J_b Phi for J = e^T Gamma e / 2 (eqs. 22-23, model.md §3.1, 3.5 generic form)."""
    return (gamma * error) @ error_jacobian_body(error, exact) @ plant_jacobian_body @ gain_sensitivity(error, ref)


def sensitivity_step(
    sensitivity: Array,
    y: Array,
    ref: Reference,
    gains: Array,
    plant_jacobian_body: Array,
    scale: Array,
    control_period: float,
) -> Array:
    """Sigma(k+1) = [I + T_c d(S nu)/dq + J d nu_c/dq] Sigma(k) + J^n Phi(k), with J = R_3(theta) J_b^n c_bar
    (model.md §3.6 Mode B): the transition takes the real J, the input the normalised J^n = J / c_bar (``scale``), so
    Sigma = (d q / d alpha) / c_bar, in the units of Mode A's J^n Phi. The clamps are ignored, as in Phi."""
    theta, v = pose(y)[2], velocity(y)[0]
    world_jacobian = rotation(theta) @ plant_jacobian_body
    command_of_pose = lambda q: kanayama_command(posture_error(q[0], q[1], q[2], ref.x, ref.y, ref.theta), ref, gains)  # noqa: E731
    pose_rate_jacobian = jnp.array([[0.0, 0.0, -v * jnp.sin(theta)], [0.0, 0.0, v * jnp.cos(theta)], [0.0, 0.0, 0.0]])
    transition = (
        jnp.eye(3)
        + control_period * pose_rate_jacobian
        + scale * world_jacobian @ jax.jacfwd(command_of_pose)(pose_vector(y))
    )
    error = posture_error(*pose(y), ref.x, ref.y, ref.theta)
    return transition @ sensitivity + world_jacobian @ gain_sensitivity(error, ref)


def sensitivity_gradient(error: Array, y: Array, gamma: Array, sensitivity: Array, exact: bool) -> Array:
    """dJ/dalpha = e^T Gamma D Sigma, with D = D_b R_3(theta)^T the world-frame d e_p / d q (model.md §3.3)."""
    return (gamma * error) @ error_jacobian_body(error, exact) @ rotation(pose(y)[2]).T @ sensitivity


class AdaptiveMemory(NamedTuple):
    """Everything the NN-adaptive law evolves, carried between control periods (docs/architecture.md): the gains, the
    emulator and its momentum, and the previous sample it learns from (model.md §3.6 to 3.8)."""

    gains: Array  #: current (Kx, Ky, Ktheta)
    last_step: Array  #: previous gain change, for the gain momentum
    mlp: MLP  #: emulator weights
    mlp_velocity: MLP  #: their momentum
    previous_pose: Array  #: measured pose at k-1
    previous_input: Array  #: emulator input z_{k-1}
    previous_saturated: Array  #: 1.0 if a clamp or the torque limit acted at k-1
    started: Array  #: 1.0 once a transition exists to learn from
    sensitivity: Array | None = None  #: Sigma = d q / d (Kx, Ky, Ktheta) (3x3), for jacobian "model_sensitivity"


@pytree_dataclass
class NNAdaptiveBackstepping:
    """Kanayama law whose gains adapt online through the emulator's Jacobian (model.md §3).

    In: measured state y and reference. Out: nu_c = (v_c [m/s], omega_c [rad/s]), clamped, with its
    analytic derivative; composed with an inner loop in a :class:`~ddtrack.controllers.Cascade`.
    With ``rates`` = 0 it is the backstepping controller exactly. Logs: ``kx, ky, ktheta``,
    ``emulator_loss`` (normalised sample loss of the online step), ``jacobian_v`` and ``jacobian_omega``
    (normalised J_b[0, 0] and J_b[2, 1] used by the gain law) and ``gate`` (1.0 when the gains moved).

    ``jacobian`` picks J (model.md §3.4): ``network`` (the emulator, eq. 34), ``analytic`` (a), ``quasi_static`` (b),
    ``model`` (the exact one-step sensitivity of the nominal model under the inner loop, by automatic
    differentiation: ``nominal_period``), or ``model_sensitivity``: that J in the multi-step forward sensitivity
    recursion of model.md §3.6's Mode B, Sigma(k+1) = [I + T_c d(S nu)/dq + J d nu_c/dq] Sigma(k) + J Phi(k), with the
    gradient e^T Gamma D Sigma / c_bar. Sigma restarts from 0 whenever the gate is closed, so it covers the
    trajectory since adaptation last resumed.
    """

    gains: FloatVector  #: initial (Kx, Ky, Ktheta)
    emulator: Emulator
    control_period: float
    analytic_coefficients: Array  #: (c_v, c_omega) of model.md §3.4 (a) for the nominal inner loop
    freeze_time: float  #: [s] no gain change before (the scenario's default depends on the identification)
    rates: FloatVector = declared(NNAdaptiveParameters)  #: Lambda [1/s], with the normalised Jacobian
    gain_momentum: float = declared(NNAdaptiveParameters)  #: beta_K
    max_step: FloatVector = declared(NNAdaptiveParameters)  #: per-sample clip of the gain change
    gain_min: FloatVector = declared(NNAdaptiveParameters)
    gain_max: FloatVector = declared(NNAdaptiveParameters)
    gate_error: float = declared(NNAdaptiveParameters)  #: [m]
    leakage: float = declared(NNAdaptiveParameters)  #: sigma [1/s], pull towards the initial gains
    gamma: FloatVector = declared(NNAdaptiveParameters)  #: Gamma of eq. 22
    learning_rate: float = declared(NNAdaptiveParameters)  #: emulator eta
    momentum: float = declared(NNAdaptiveParameters)  #: emulator beta
    gradient_clip: float = declared(NNAdaptiveParameters)  #: emulator gradient-norm clip
    max_velocity: float = declared(VelocityClamps)
    max_yaw_rate: float = declared(VelocityClamps)
    jacobian: str = declared(NNAdaptiveParameters)
    error_jacobian: str = declared(NNAdaptiveParameters)
    online_learning: bool = declared(NNAdaptiveParameters)
    learn_saturated: Array | bool = declared(NNAdaptiveParameters)
    structured_jacobian: Array | bool = declared(NNAdaptiveParameters)
    strict: Array | bool = declared(StrictTerm)
    nominal_period: Any = None  #: ddtrack.sim.NominalPeriod, for the "model" Jacobians

    def init(self, x0: Array, ref0: Reference, key: Array) -> AdaptiveMemory:
        x0 = jnp.asarray(x0, float)
        gains = jnp.asarray(self.gains, float)
        n_in = self.emulator.scales.inputs.shape[0]
        sensitivity = jnp.zeros((3, 3)) if self.jacobian == "model_sensitivity" else None
        return AdaptiveMemory(
            gains,
            jnp.zeros(3),
            self.emulator.mlp,
            zeros_like(self.emulator.mlp),
            pose_vector(x0),
            jnp.zeros(n_in),
            jnp.asarray(0.0),
            jnp.asarray(0.0),
            sensitivity,
        )

    def _plant_jacobian(self, mlp: MLP, nu_c: Array, nu: Array) -> Array:
        """Body-frame J_b^n (3x2) of the configured source, normalised by c_bar (model.md §3.4)."""
        c_v, c_w = jnp.asarray(self.analytic_coefficients)[0], jnp.asarray(self.analytic_coefficients)[1]
        if self.jacobian == "quasi_static":
            return jnp.array([[1.0, 0.0], [0.0, 0.0], [0.0, 1.0]])  # T_c S / T_c
        if self.jacobian == "analytic":
            return jnp.array([[1.0, 0.0], [0.0, 0.0], [0.0, c_w / c_v]])
        if self.jacobian in ("model", "model_sensitivity"):
            held = lambda c: VelocityCommand(c, jnp.zeros(2), jnp.zeros(2), jnp.asarray(0.0))  # noqa: E731
            return self.nominal_period.jacobian(nu, nu_c, held) / c_v
        emulator = Emulator(mlp, self.emulator.scales, self.emulator.uses_velocity)
        jb = input_jacobian(mlp, emulator.scales, emulator.inputs(nu_c, nu))[:, :2] / c_v
        # structured: keep the two direct channels, positive (model.md §3.7 safeguards)
        structured = jnp.array([[jnp.maximum(jb[0, 0], 0.0), 0.0], [0.0, 0.0], [0.0, jnp.maximum(jb[2, 1], 0.0)]])
        return jnp.where(self.structured_jacobian, structured, jb)

    def command(
        self, t: Array, y: Array, ref: Reference, memory: AdaptiveMemory
    ) -> tuple[VelocityCommand, AdaptiveMemory, Logs]:
        error = posture_error(*pose(y), ref.x, ref.y, ref.theta)
        nu = velocity(y)
        scales, started = self.emulator.scales, memory.started > 0.5
        # a saturated transition says nothing about the command's effect (the actuators ignored it)
        learn = started & jnp.logical_or(self.learn_saturated, memory.previous_saturated < 0.5)

        # learn the last transition
        z_prev = memory.previous_input / scales.inputs
        target = body_increment(memory.previous_pose, pose_vector(y)) / scales.outputs
        loss = jnp.where(started, sample_loss(memory.mlp, z_prev, target), 0.0)
        mlp, mlp_velocity = memory.mlp, memory.mlp_velocity
        if self.online_learning:
            trained, momentum = momentum_step(
                mlp,
                mlp_velocity,
                backprop(mlp, z_prev, target),
                learning_rate=self.learning_rate,
                momentum=self.momentum,
                clip_norm=self.gradient_clip,
            )
            keep = lambda new, old: jnp.where(learn, new, old)  # noqa: E731
            mlp, mlp_velocity = (
                jax.tree_util.tree_map(keep, trained, mlp),
                jax.tree_util.tree_map(keep, momentum, mlp_velocity),
            )

        # adapt the gains (eqs. 22-26)
        limits = jnp.stack([jnp.asarray(self.max_velocity, float), jnp.asarray(self.max_yaw_rate, float)])
        gains = memory.gains
        nu_c_now = jnp.clip(kanayama_command(error, ref, gains), -limits, limits)
        jb = self._plant_jacobian(mlp, nu_c_now, nu)
        gate = (
            started
            & (jnp.hypot(error[0], error[1]) < self.gate_error)
            & (memory.previous_saturated < 0.5)
            & (t >= self.freeze_time)
        )
        sensitivity, c_v = memory.sensitivity, jnp.asarray(self.analytic_coefficients)[0]
        if self.jacobian == "model_sensitivity":
            assert sensitivity is not None, "init() gives model_sensitivity a sensitivity"
            gradient = sensitivity_gradient(
                error, y, jnp.asarray(self.gamma), sensitivity, self.error_jacobian == "exact"
            )
            advanced = sensitivity_step(sensitivity, y, ref, gains, jb, c_v, self.control_period)
            sensitivity = jnp.where(gate, advanced, 0.0)
        else:
            gradient = cost_gradient(error, ref, jnp.asarray(self.gamma), jb, self.error_jacobian == "exact")
        initial = jnp.asarray(self.gains, float)
        step = (
            -self.control_period * jnp.asarray(self.rates) * gradient
            + self.gain_momentum * memory.last_step
            - self.control_period * self.leakage * (gains - initial)
        )
        step = jnp.where(gate, jnp.clip(step, -jnp.asarray(self.max_step), jnp.asarray(self.max_step)), 0.0)
        gains = jnp.clip(gains + step, jnp.asarray(self.gain_min), jnp.asarray(self.gain_max))

        # the Kanayama command with the new gains: the backstepping law's own code (so rates = 0 is it, bit for bit)
        command = velocity_command(error, nu, ref, gains, limits, self.strict)
        memory = AdaptiveMemory(
            gains,
            step,
            mlp,
            mlp_velocity,
            pose_vector(y),
            self.emulator.inputs(command.nu_c, nu),
            command.saturated,
            jnp.asarray(1.0),
            sensitivity,
        )
        logs = {
            "kx": gains[0],
            "ky": gains[1],
            "ktheta": gains[2],
            "emulator_loss": loss,
            "jacobian_v": jb[0, 0],
            "jacobian_omega": jb[2, 1],
            "gate": gate.astype(float),
        }
        return command, memory, logs

    def observe(self, memory: AdaptiveMemory, saturated: Array) -> AdaptiveMemory:
        """Record whether the inner loop saturated this period, for the next period's gate."""
        return memory._replace(previous_saturated=jnp.maximum(memory.previous_saturated, saturated))
