"""``ddtrack/DiffDriveTracking-v0``: trajectory tracking of a differential-drive robot as a Gymnasium environment.

A thin shell over the simulator (docs/architecture.md): each ``step`` is one control period of
:func:`ddtrack.sim.simulate`, through the same functions (:func:`~ddtrack.sim.plant_period`,
:func:`~ddtrack.sim.period_status`), on the plant, disturbance and measurement noise that
:func:`ddtrack.runner.prepare` draws from the seed, as ``ddtrack run`` does.

Action modes
------------
``"torque"``
    a in [-1, 1]^2 (float32); the wheel torques (tau_R, tau_L) = a * ``robot.max_torque`` [N m] (the nominal
    limit) are held over the period, after the true plant's saturation. The scenario's controller is unused.
``"gains"``
    a in [-1, 1]^3 (float32) sets (Kx, Ky, Ktheta) of the scenario's Kanayama backstepping law (paper eq. 12)
    for this period, over its own inner loop (the paper's idea with a learned policy in place of the
    gradient law). a = 0 gives the scenario's gains K0 exactly; a = +1 gives ``gain_max`` and a = -1
    ``gain_min``, log-linearly in between (the gains span two decades):
    K = K0 (gain_max / K0)^a for a >= 0, K0 (K0 / gain_min)^a for a < 0.
    The bounds are the NN-adaptive defaults (0.1, 1, 0.1) .. (10, 600, 60) (``NNAdaptiveConfig``), or an
    ``nn_adaptive_backstepping`` scenario's own ``gain_min``/``gain_max``, widened to contain K0.
    Allowed controllers: those registered with Kanayama gains (:func:`gains_controllers`): ``backstepping``,
    ``sliding_mode_backstepping``, ``adaptive_backstepping``, ``kinematic_backstepping``, a plugin's that declares
    them, and ``nn_adaptive_backstepping``, which is run as plain ``backstepping`` with its gains and inner loop
    (the policy replaces its gain law).

Actions outside [-1, 1] are clipped (``Box`` actions are normalised, as Gymnasium recommends).

Observation (float32, physical units, each clipped to its bound)
------------------------------------------------------------------
What the controller sees, y = x + noise (``noise.measure``, the scenario's ``[noise]``), against the reference
at the same instant::

    0 e_x [m]   1 e_y [m]        posture error in the robot frame (model.md §2.2), bound +-simulation.divergence_error
    2 sin e_theta   3 cos e_theta                                              bound +-1
    4 v [m/s]   5 omega [rad/s]  the robot's measured velocities,              bound +-50 (the divergence speed)
    6 v_r [m/s] 7 omega_r [rad/s] the reference's feed-forward velocities,    bound +-50
    8 Kx  9 Ky  10 Ktheta        gains mode only: the gains in force,          bound [gain_min, gain_max]

A running episode stays inside the error and speed bounds (past them it is terminated), so clipping acts only
on the observation that ends a diverging episode. The observation after the last period reuses the last
period's noise draw (a run draws one per period).

Reward
------
r_k = -T_c (J(k+1) + effort_weight |tau_k|^2), with J = 1/2 e_p^T Gamma e_p, Gamma = diag(1, 50, 1) (paper eq. 22,
model.md §3.1) of the *true* state x_{k+1} against the reference at t_{k+1}, and tau_k the wheel torques held
[N m] (zero effort for a kinematic plant). The factor T_c makes the return the time integral of the cost,
-int (J + w |tau|^2) dt [m^2 s], whatever the control period. Scale on ``paper_line`` (40 s; the robot starts
10 m from the reference point, 7.07 m off the line): the scenario's own gains score -895, of which -893 in
the first 5 s of transient and -0.02 in the last 20 s (tracking to a few mm); a random gains agent about -970.
Tracking to within 1 cm costs 0.5 * 50 * 1e-4 = 2.5e-3 per second. The default ``effort_weight`` = 1e-3 /(N m)^2
adds 0.02 to that run and charges the 10 N m torque limit on both wheels 0.2 per second: small beside the
tracking cost, enough to break ties in favour of gentle torques.

When a period diverges or goes non-finite (``period_status``: |(e_x, e_y)| > divergence_error, |v| or |omega|
> 50, or NaN) the episode is ``terminated``, the state is frozen as in the simulator, and the reward charges
that period and every remaining one at the cost bound 1/2 (50 D^2 + pi^2) + effort_weight * 2 tau_max^2
(D = divergence_error, tau_max the plant's torque limit), so ending an episode early never pays.
``truncated`` is set after the scenario's last period.

``info``: ``t`` [s] (of the observation), ``status`` (``"ok"``, ``"diverged"``, ``"non_finite"``), ``e_tr`` [m]
(|(e_x, e_y)| of the true state), ``state`` (the true [x, y, theta, v, omega]), ``seed`` (of the episode),
``control`` (the held input, wheel torques [N m]; ``step`` only) and, in gains mode, ``gains``.
"""

from __future__ import annotations

import dataclasses
import math
from functools import partial
from os import PathLike
from typing import Any, NamedTuple

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
from gymnasium import spaces
from jax import Array

from ..controllers import NNAdaptiveParameters
from ..errors import ConfigError, RunError, did_you_mean
from ..geometry import posture_error
from ..integrators import RK4
from ..layout import BODY, Layout, pose, velocity
from ..precision import enable_float64
from ..runner import prepare
from ..scenario import (
    BacksteppingConfig,
    NNAdaptiveConfig,
    Scenario,
    Setup,
    kanayama_gains,
    kanayama_kinds,
    load_scenario,
)
from ..shipped import scenario_path
from ..sim import DIVERGENCE_SPEED, STATUS_NAMES, ClosedLoop, Draws, HeldInput, measured

ACTION_MODES = ("torque", "gains")
DEFAULT_SCENARIO = "training"  #: scenarios/training.toml: plant, disturbance and noise drawn per seed
DEFAULT_EFFORT_WEIGHT = 1e-3  #: w of the effort term [1/(N m)^2]
#: Gamma of the cost eq. 22, weights of (e_x, e_y, e_theta) (model.md §3.1): the NN-adaptive law's default
GAMMA: tuple[float, float, float] = NNAdaptiveParameters.model_fields["gamma"].default
RESET_OPTIONS = ("initial_pose",)


class _Episode(NamedTuple):
    """What one episode's jitted steps read and never change (a pytree: new values never recompile)."""

    loop: ClosedLoop  #: the run's loop; its controller the Kanayama-based one (gains mode), else None
    xi_disturbance: Array  #: (N, 2) the run's disturbance draws
    xi_noise: Array  #: (N, 5) the run's noise draws
    n_steps: Array  #: N
    torque_scale: Array  #: action 1 -> this torque [N m]
    effort_weight: Array  #: [1/(N m)^2]
    cost_bound: Array  #: cost per second charged for the rest of a terminated episode
    gain_anchor: Array  #: (3,) K0, the gains of action 0
    gain_log_up: Array  #: (3,) log(gain_max / K0)
    gain_log_down: Array  #: (3,) log(K0 / gain_min)
    obs_low: Array  #: (n_obs,) bounds of the observation, float64 copies of the float32 ones
    obs_high: Array


def _gains(episode: _Episode, action: Array) -> Array:
    """Gains (Kx, Ky, Ktheta) of an action in [-1, 1]^3: K0 exactly at 0, log-linear to the bounds at +-1."""
    return episode.gain_anchor * jnp.exp(action * jnp.where(action >= 0, episode.gain_log_up, episode.gain_log_down))


#: what :func:`_step` packs after the observation: the plant's input u (N m or m/s), the BODY of x_{k+1}, the gains
PACKED = Layout(("reward", "status", "e_tr", "u_0", "u_1", *BODY.names, "kx", "ky", "ktheta"),
                ("", "", "m", "", "", *BODY.units, "1/s", "1/m^2", "1/m"))  # fmt: skip


def _observe(episode: _Episode, x: Array, k: Array, gains: Array | None) -> tuple[Array, Array, Array]:
    """Observation at period k of state x (measured with draw k), and the true error's cost J and e_tr."""
    loop = episode.loop
    ref = loop.trajectory(k * loop.control_period)
    body = loop.plant.observe(x)
    y = loop.noise.measure(measured(loop.plant, x), episode.xi_noise[jnp.minimum(k, episode.n_steps - 1)])
    e = posture_error(*pose(y), ref.x, ref.y, ref.theta)
    parts = [e[0], e[1], jnp.sin(e[2]), jnp.cos(e[2]), *velocity(y), ref.v, ref.omega]
    observation = jnp.stack(parts if gains is None else [*parts, *gains])
    observation = jnp.clip(observation, episode.obs_low, episode.obs_high)
    true = posture_error(*pose(body), ref.x, ref.y, ref.theta)
    cost = 0.5 * (GAMMA[0] * true[0] ** 2 + GAMMA[1] * true[1] ** 2 + GAMMA[2] * true[2] ** 2)
    return observation, cost, jnp.hypot(true[0], true[1])


@partial(jax.jit, static_argnames=("gains_mode",))
def _start(episode: _Episode, body0: Array, key: Array, *, gains_mode: bool) -> tuple[Array, Any, Array]:
    """The plant's initial state and the controller's memory (as ``simulate`` initialises them) from the BODY state
    ``body0``, and the packed first observation."""
    loop = episode.loop
    x0 = loop.plant.init(jnp.asarray(body0, dtype=float))
    memory = loop.controller.init(measured(loop.plant, x0), loop.trajectory(0.0), key) if gains_mode else ()
    observation, _, e_tr = _observe(episode, x0, jnp.asarray(0), episode.gain_anchor if gains_mode else None)
    return x0, memory, jnp.concatenate([observation, jnp.stack([e_tr])])


@partial(jax.jit, static_argnames=("gains_mode",))
def _step(
    episode: _Episode, x: Array, memory: Any, k: Array, action: Array, *, gains_mode: bool
) -> tuple[Array, Any, Array]:
    """Period k of :func:`ddtrack.sim.simulate`'s loop with the action in place of (or inside) the controller.

    Returns x_{k+1}, the controller's memory and the packed host data [observation, reward, status, e_tr,
    u_k (2,), BODY of x_{k+1} (5,), gains (3,; gains mode)]. The period is :class:`~ddtrack.sim.ClosedLoop`'s, which
    ``simulate`` steps too: a failed period freezes state and memory.
    """
    if gains_mode:
        gains = _gains(episode, action)
        controller = episode.loop.controller
        if not hasattr(controller, "outer"):  # kinematic backstepping: the law alone is the controller
            controller = dataclasses.replace(controller, kx=gains[0], ky=gains[1], ktheta=gains[2])
        else:  # a Cascade, or a VelocityOutput (inner = "none")
            outer = dataclasses.replace(controller.outer, kx=gains[0], ky=gains[1], ktheta=gains[2])
            controller = dataclasses.replace(controller, outer=outer)
    else:
        gains = None
        controller = HeldInput(action * episode.torque_scale, output_kind="torque")  # torque mode: the action
    loop = dataclasses.replace(episode.loop, controller=controller)
    x_next, next_memory, status, (_, _, _, u, _) = loop.period(
        x, memory, jnp.asarray(0), k, episode.xi_disturbance[k], episode.xi_noise[k]
    )
    keep = status == 0
    observation, cost, e_tr = _observe(episode, x_next, k + 1, gains)
    effort = jnp.sum(u**2) if loop.plant.input_kind == "torque" else jnp.asarray(0.0)
    remaining = episode.n_steps - k  # this period and the ones after it
    cost = jnp.where(keep, cost + episode.effort_weight * effort, remaining * episode.cost_bound)
    reward = -loop.control_period * cost
    parts = [observation, jnp.stack([reward, status.astype(float), e_tr]), u, loop.plant.observe(x_next)]
    return x_next, next_memory, jnp.concatenate(parts if gains is None else [*parts, gains])


class DiffDriveTrackingEnv(gymnasium.Env):
    """Track a scenario's reference with a differential-drive robot, one control period per step.

    See the module docstring for the action modes, observation, reward and termination. Creating it switches JAX
    to float64 for the process (:func:`ddtrack.enable_float64`), so that ``gymnasium.make`` works as it is.

    Parameters
    ----------
    scenario
        a scenario file path or a :class:`ddtrack.Scenario`
    action_mode
        ``"torque"`` (wheel torques) or ``"gains"`` (Kx, Ky, Ktheta of the backstepping law)
    effort_weight
        w of the reward's effort term [1/(N m)^2], default :data:`DEFAULT_EFFORT_WEIGHT`
    render_mode
        only ``None`` (no rendering)
    plant_model
        builds the true robot's plant from its drawn parameters (``Setup.plant_model``, e.g. a plant with more states
        than BODY); None: the scenario's

    Raises
    ------
    ConfigError
        naming the argument: an unknown ``action_mode``, a scenario that cannot be read, a controller that
        gains mode cannot drive, a negative ``effort_weight``, a ``render_mode``.
    """

    metadata: dict[str, Any] = {"render_modes": []}  # noqa: RUF012 (an instance attribute in gymnasium.Env)

    def __init__(
        self,
        scenario: str | PathLike | Scenario | None = None,
        *,
        action_mode: str = "torque",
        effort_weight: float = DEFAULT_EFFORT_WEIGHT,
        render_mode: str | None = None,
        plant_model: Any = None,
    ) -> None:
        enable_float64()  # documented above: an environment made by gymnasium.make has no other place to ask
        if action_mode not in ACTION_MODES:
            raise ConfigError(
                "action_mode", f"unknown action mode {action_mode!r}", did_you_mean(str(action_mode), ACTION_MODES)
            )
        if render_mode is not None:
            raise ConfigError(
                "render_mode",
                f"{render_mode!r} is not supported",
                "leave render_mode=None; plot a finished run with `ddtrack run` instead",
            )
        if (
            isinstance(effort_weight, bool)
            or not isinstance(effort_weight, (int, float))
            or not math.isfinite(effort_weight)
            or effort_weight < 0
        ):
            raise ConfigError("effort_weight", f"must be a finite number >= 0 (got {effort_weight!r})")
        given = _load(scenario)
        self.scenario = _scenario_for(given, action_mode)
        self.action_mode = action_mode
        self.effort_weight = float(effort_weight)
        self.render_mode = None
        self.plant_model = plant_model  # None: the scenario's
        sim, config = self.scenario.simulation, self.scenario.controller
        self._gains_mode = action_mode == "gains"
        if self._gains_mode:
            anchor = np.asarray(kanayama_gains(config), dtype=float)
            bounds = scenario_gain_bounds(given)
            self.gain_min = np.minimum(np.asarray(bounds[0], float), anchor)
            self.gain_max = np.maximum(np.asarray(bounds[1], float), anchor)
            self.gain_anchor = anchor
        distance, speed = self.scenario.divergence_distance(), DIVERGENCE_SPEED
        low = [-distance, -distance, -1.0, -1.0, -speed, -speed, -speed, -speed]
        high = [distance, distance, 1.0, 1.0, speed, speed, speed, speed]
        if self._gains_mode:
            low, high = [*low, *self.gain_min], [*high, *self.gain_max]
        # clipped to the float64 copies of these float32 bounds, an observation stays inside them after the cast
        low32, high32 = np.asarray(low, np.float32), np.asarray(high, np.float32)
        self.observation_space = spaces.Box(low32, high32, dtype=np.float32)
        self._n_actions = n_actions = 3 if self._gains_mode else 2  # three gains or two wheel torques
        self.action_space = spaces.Box(
            -np.ones(n_actions, np.float32), np.ones(n_actions, np.float32), dtype=np.float32
        )
        self._n_obs = len(low)
        self._constants: dict[str, Any] = {
            "control_period": sim.control_period,
            "n_steps": sim.n_steps,
            "divergence_error": distance,
            "torque_scale": self.scenario.robot.max_torque,
            "effort_weight": self.effort_weight,
            "obs_low": low32.astype(float),
            "obs_high": high32.astype(float),
        }
        # the current episode's run objects (``ddtrack.runner.prepare``; x0 with the reset's options); torque mode
        # simulates the true robot (setup.plant_model) whatever the scenario's controller
        self.setup: Setup | None = None
        self.draws: Draws | None = None  #: and its random draws
        self._episode: _Episode | None = None
        self._x: Array | None = None
        self._memory: Any = None
        self._k = 0
        self._done = True
        self._seed: int | None = None

    # --- the Gymnasium API ------------------------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        """Start an episode: draw the plant, disturbance and noise from ``seed`` as ``ddtrack run --seed`` does
        (:func:`ddtrack.runner.prepare`; without an emulator's identification, which no gain law here uses).

        ``seed`` None draws one from the environment's generator (so a seeded first reset fixes the
        sequence of episodes). ``options``: ``{"initial_pose": [x, y, theta]}`` [m, m, rad] replaces the
        scenario's initial pose (the velocity stays the scenario's).
        """
        super().reset(seed=seed)
        if seed is None:
            seed = int(self.np_random.integers(0, 2**31 - 1))
        pose = _initial_pose(options)
        setup, draws = prepare(self.scenario, seed=seed, identify=False)  # no gain law here needs an emulator
        if self.plant_model is not None:
            setup = dataclasses.replace(setup, plant_model=self.plant_model)
        plant = setup.plant if self._gains_mode else setup.sensed(setup.plant_model(setup.plant_params))
        x0 = jnp.asarray(setup.x0, dtype=float)
        if pose is not None:
            x0 = x0.at[:3].set(jnp.asarray(pose, dtype=float))
        c = self._constants
        torque_max = float(setup.plant_params.max_torque) if plant.input_kind == "torque" else 0.0
        cost_bound = (
            0.5 * (max(GAMMA[:2]) * c["divergence_error"] ** 2 + GAMMA[2] * math.pi**2)
            + self.effort_weight * 2 * torque_max**2
        )
        if self._gains_mode:
            anchor = self.gain_anchor
            log_up, log_down = np.log(self.gain_max / anchor), np.log(anchor / self.gain_min)
        else:
            anchor = log_up = log_down = np.ones(3)
        self._episode = _Episode(
            loop=ClosedLoop(
                plant,
                setup.controller if self._gains_mode else None,
                setup.trajectory,
                setup.disturbance,
                setup.noise,
                control_period=jnp.asarray(c["control_period"]),
                divergence_error=jnp.asarray(c["divergence_error"]),
                solver=RK4(self.scenario.simulation.substeps),
            ),
            xi_disturbance=draws.disturbance,
            xi_noise=draws.noise,
            n_steps=jnp.asarray(c["n_steps"]),
            torque_scale=jnp.asarray(c["torque_scale"]),
            effort_weight=jnp.asarray(c["effort_weight"]),
            cost_bound=jnp.asarray(cost_bound),
            gain_anchor=jnp.asarray(anchor),
            gain_log_up=jnp.asarray(log_up),
            gain_log_down=jnp.asarray(log_down),
            obs_low=jnp.asarray(c["obs_low"]),
            obs_high=jnp.asarray(c["obs_high"]),
        )
        self._x, self._memory, packed = _start(self._episode, x0, draws.controller_key, gains_mode=self._gains_mode)
        self._k, self._done, self._seed = 0, False, seed
        self.setup, self.draws = dataclasses.replace(setup, x0=x0), draws
        host = np.asarray(packed)
        observation = host[: self._n_obs].astype(np.float32)
        info = {"t": 0.0, "status": "ok", "e_tr": float(host[self._n_obs]), "state": np.array(x0), "seed": seed}
        if self._gains_mode:
            info["gains"] = self.gain_anchor.copy()
        return observation, info

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        """One control period under ``action`` (clipped to [-1, 1]); see the module docstring."""
        if self._done:
            raise RunError("the episode has ended or not begun: call reset() before step()")
        n_actions = self._n_actions
        action = np.asarray(action, dtype=float)
        if action.shape != (n_actions,):
            raise ConfigError("action", f"expected shape ({n_actions},) in {self.action_mode} mode, got {action.shape}")
        action = np.clip(action, -1.0, 1.0)  # NaN passes, and ends the episode as non_finite
        self._x, self._memory, packed = _step(
            self._episode,
            self._x,
            self._memory,
            self._k,
            action,
            gains_mode=self._gains_mode,
        )
        self._k += 1
        host = np.asarray(packed)
        observation, tail = host[: self._n_obs].astype(np.float32), host[self._n_obs :]
        reward, e_tr = float(PACKED.read(tail, "reward")), float(PACKED.read(tail, "e_tr"))
        status = STATUS_NAMES[int(PACKED.read(tail, "status"))]
        terminated = status != "ok"
        truncated = not terminated and self._k >= self.scenario.simulation.n_steps
        self._done = terminated or truncated
        info = {
            "t": self._k * self.scenario.simulation.control_period,
            "status": status,
            "e_tr": e_tr,
            "state": PACKED.span(tail, "x", "omega").copy(),
            "seed": self._seed,
            "control": PACKED.span(tail, "u_0", "u_1").copy(),
        }
        if self._gains_mode:
            info["gains"] = PACKED.span(tail, "kx", "ktheta").copy()
        return observation, reward, terminated, truncated, info

    # --- helpers --------------------------------------------------------------------------------

    def gains_to_action(self, gains: Any) -> np.ndarray:
        """The action (float64) that sets ``gains`` = (Kx, Ky, Ktheta) in gains mode: the inverse of the map in
        the module docstring, clipped to [-1, 1]; the scenario's own gains give exactly 0."""
        if not self._gains_mode:
            raise ConfigError("action_mode", "gains_to_action needs action_mode='gains'")
        ratio = np.log(np.asarray(gains, dtype=float) / self.gain_anchor)
        scale = np.where(ratio >= 0, np.log(self.gain_max / self.gain_anchor), np.log(self.gain_anchor / self.gain_min))
        with np.errstate(divide="ignore", invalid="ignore"):
            action = np.where(scale > 0, ratio / np.where(scale > 0, scale, 1.0), 0.0)
        return np.clip(action, -1.0, 1.0)


def gains_controllers() -> tuple[str, ...]:
    """The kinds gains mode accepts: those registered with Kanayama gains (:func:`ddtrack.register_controller`)."""
    return tuple(kanayama_kinds())


def scenario_gain_bounds(scenario: Scenario) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """(gain_min, gain_max) of gains mode: an NN-adaptive scenario's own, else the NN-adaptive defaults."""
    if isinstance(scenario.controller, NNAdaptiveConfig):
        return scenario.controller.gain_min, scenario.controller.gain_max
    fields = NNAdaptiveConfig.model_fields
    return fields["gain_min"].default, fields["gain_max"].default


def _load(scenario: Any) -> Scenario:
    if isinstance(scenario, Scenario):
        return scenario
    if scenario is None:  # Gymnasium's convention: make(ENV_ID) with no arguments works
        return load_scenario(scenario_path(DEFAULT_SCENARIO))
    if not isinstance(scenario, (str, PathLike)):
        raise ConfigError("scenario", f"expected a path or a ddtrack.Scenario, got {type(scenario).__name__}")
    return load_scenario(scenario)


def _scenario_for(scenario: Scenario, action_mode: str) -> Scenario:
    """The scenario the environment runs: gains mode needs a Kanayama outer law; NN-adaptive becomes backstepping."""
    if action_mode != "gains":
        return scenario
    config, allowed = scenario.controller, gains_controllers()
    if config.kind not in allowed:
        raise ConfigError(
            "action_mode",
            f"'gains' sets the gains of Kanayama backstepping, and this scenario's controller.kind is {config.kind!r}",
            f"use action_mode='torque', or one of {', '.join(allowed)}",
        )
    if isinstance(config, NNAdaptiveConfig):  # the policy replaces the gradient law; gains and inner loop stay
        shared = {name: getattr(config, name) for name in BacksteppingConfig.model_fields if name != "kind"}
        return scenario.model_copy(update={"controller": BacksteppingConfig(kind="backstepping", **shared)})
    return scenario


def _initial_pose(options: dict[str, Any] | None) -> np.ndarray | None:
    if options is None:
        return None
    if not isinstance(options, dict):
        raise ConfigError("options", f"expected a dict, got {type(options).__name__}")
    for key in options:
        if key not in RESET_OPTIONS:
            raise ConfigError(f"options.{key}", "unknown reset option", did_you_mean(str(key), RESET_OPTIONS))
    if "initial_pose" not in options:
        return None
    try:
        pose = np.asarray(options["initial_pose"], dtype=float)
    except (TypeError, ValueError):
        pose = np.full(0, np.nan)
    if pose.shape != (3,) or not np.all(np.isfinite(pose)):
        raise ConfigError(
            "options.initial_pose", f"expected 3 finite numbers [x, y, theta], got {options['initial_pose']!r:.60}"
        )
    return pose
