"""Logs from known plants (a lag model, a torque-driven body, a voltage-driven robot), to check identification
against the truth (docs/identification.md).

The base follows ``theta`` under the plan's commands, each acting ``delay`` s after it was sent; what it logs is
either its speeds plus white noise, or, with ``encoder_counts``, the speeds that odometry derives from quantised
wheel angles over each sample interval (so the log is also a little late and coarse, as a real one is).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise
from typing import Any

import jax.numpy as jnp
import numpy as np
from jax import Array

from ..model import dynamics
from ..model.motors import DCMotor, voltage_driver
from ..model.params import RobotParams
from ..model.sensing import body_increments
from ..model.traction import wheel_speeds
from .excitation import Plan
from .fit import SpeedLog, SpeedModel, simulate
from .lag import simulate_speeds
from .motor import MotorLog

FINE = 10  #: simulation points per sample interval


def _applied_finely(t: np.ndarray, inputs: np.ndarray, delay: float) -> tuple[np.ndarray, np.ndarray]:
    """A fine time grid (``FINE`` points per sample, one sample past the last) and the input in force at each of its
    points: the last one sent ``delay`` [s] or more before, zero before the first arrives."""
    step = float(np.median(np.diff(t)))
    fine_t = np.arange(len(t) * FINE + 1) * (step / FINE)
    acting = np.searchsorted(t, fine_t - delay + 1e-12, side="right") - 1
    return fine_t, np.where((acting >= 0)[:, None], inputs[np.clip(acting, 0, None)], 0.0)


def _encoder_speeds(
    angles: np.ndarray, steps: np.ndarray, encoder_counts: int, wheel_radius: float, half_axle: float
) -> np.ndarray:
    """(v, omega) as odometry gives them: the wheels' ``angles`` (n + 1, 2) [rad] (right, left), quantised to
    ``encoder_counts`` per turn, differenced over the ``steps`` (n,) [s] between them: each a mean over its interval."""
    tick = 2 * np.pi / encoder_counts
    rates = np.diff(np.floor(angles / tick) * tick, axis=0) / steps[:, None]
    return np.column_stack(body_increments(rates.T, wheel_radius, half_axle))


def lag_log(
    theta: np.ndarray,
    plan: Plan,
    *,
    noise: tuple[float, float] = (0.0, 0.0),
    delay: float = 0.0,
    encoder_counts: int | None = None,
    wheel_radius: float = 0.0975,
    half_axle: float = 0.1655,
    odometry_rate: float | None = None,
    seed: int = 0,
) -> SpeedLog:
    """The log of a base with lag model ``theta`` driven by ``plan``: the commands as sent, the speeds as measured
    (``noise`` = std of v [m/s] and omega [rad/s]; ``encoder_counts`` per wheel revolution, with the wheel radius
    [m] and half axle [m]); ``delay`` [s] between a command and its effect. With ``odometry_rate`` [Hz] the speeds
    are logged on their own clock at that rate, the commands on the plan's (:func:`timed_lag_log`)."""
    if odometry_rate is not None:
        return timed_lag_log(
            theta, plan, odometry_rate, noise=noise, delay=delay, encoder_counts=encoder_counts,
            wheel_radius=wheel_radius, half_axle=half_axle, seed=seed,
        )  # fmt: skip
    step = float(np.median(np.diff(plan.t)))
    sent = np.column_stack([plan.v, plan.omega])
    fine_t, command = _applied_finely(plan.t, sent, delay)
    truth = simulate_speeds(np.asarray(theta, dtype=float), fine_t, command, np.zeros(2))
    rng = np.random.default_rng(seed)
    if encoder_counts is None:
        measured = truth[::FINE][: len(plan.t)] + rng.normal(size=(len(plan.t), 2)) * np.asarray(noise)
        return SpeedLog(t=plan.t, command=sent, speed=measured, source="synthetic lag log")
    wheel_rates = np.column_stack(
        wheel_speeds(truth[:, 0], truth[:, 1], wheel_radius=wheel_radius, half_axle=half_axle)
    )
    angles = np.concatenate(
        [np.zeros((1, 2)), np.cumsum(0.5 * (wheel_rates[1:] + wheel_rates[:-1]) * (step / FINE), axis=0)]
    )
    counted = angles[::FINE][: len(plan.t) + 1]
    speeds = _encoder_speeds(counted, np.full(len(plan.t), step), encoder_counts, wheel_radius, half_axle)
    measured = speeds + rng.normal(size=(len(plan.t), 2)) * np.asarray(noise)
    t = plan.t + step  # a rate is known at the end of its interval, when the next command has just been sent
    in_force = sent[np.minimum(np.arange(len(plan.t)) + 1, len(plan.t) - 1)]
    return SpeedLog(t=t, command=in_force, speed=measured, source="synthetic lag log with encoders")


def _lag_rates(theta: np.ndarray, state: np.ndarray, command: np.ndarray) -> list[float]:
    """d/dt of (v, omega, the distance, the heading) under the lag model (model.md §1.8), written out here in NumPy
    so that :func:`timed_lag_log`'s truth shares no code with the fit's simulation."""
    t1, t2, t3, t4, t5, t6 = theta
    v, omega = state[0], state[1]
    return [(command[0] + t3 * omega**2 - t4 * v) / t1, (command[1] - t5 * v * omega - t6 * omega) / t2, v, omega]


def timed_lag_log(
    theta: np.ndarray,
    plan: Plan,
    odometry_rate: float,
    *,
    noise: tuple[float, float] = (0.0, 0.0),
    delay: float = 0.0,
    encoder_counts: int | None = None,
    wheel_radius: float = 0.0975,
    half_axle: float = 0.1655,
    seed: int = 0,
) -> SpeedLog:
    """The log of a base with lag model ``theta`` as a robot's two streams record it: each command of ``plan`` on
    its own stamp, acting ``delay`` [s] later until the next one does (zero before the first arrives), and the
    speeds on the odometry's clock at ``odometry_rate`` [Hz], from t = 0: instants plus white ``noise``, or with
    ``encoder_counts`` the means over each odometry interval from quantised wheel angles (stamped at its end).
    The truth is integrated exactly between every switch and stamp (SciPy's DOP853, rtol 1e-10), apart from the
    fit's own simulation."""
    from scipy.integrate import solve_ivp

    theta = np.asarray(theta, dtype=float)
    sent = np.column_stack([plan.v, plan.omega])
    stamps = np.arange(0.0, float(plan.t[-1]), 1.0 / odometry_rate)
    acting = plan.t + delay
    bounds = np.unique(np.concatenate([[0.0], acting[acting < stamps[-1]], stamps]))
    states = np.zeros((bounds.size, 4))  # (v, omega, distance, heading) at each bound
    for i, (a, b) in enumerate(pairwise(bounds)):
        k = np.searchsorted(acting, a, side="right") - 1  # the command acting over [a, b)
        command = sent[k] if k >= 0 else np.zeros(2)
        states[i + 1] = solve_ivp(
            lambda _, x, u=command: _lag_rates(theta, x, u), (a, b), states[i], method="DOP853", rtol=1e-10,
            atol=1e-12,
        ).y[:, -1]  # fmt: skip
    at = states[np.searchsorted(bounds, stamps)]
    rng = np.random.default_rng(seed)
    sent_t = np.asarray(plan.t, dtype=float)
    if encoder_counts is None:
        measured = at[:, :2] + rng.normal(size=(stamps.size, 2)) * np.asarray(noise)
        t, source = stamps, f"synthetic lag log, odometry at {odometry_rate:g} Hz"
    else:
        angles = np.column_stack([at[:, 2] + half_axle * at[:, 3], at[:, 2] - half_axle * at[:, 3]]) / wheel_radius
        speeds = _encoder_speeds(angles, np.diff(stamps), encoder_counts, wheel_radius, half_axle)
        measured = speeds + rng.normal(size=(stamps.size - 1, 2)) * np.asarray(noise)
        t, source = stamps[1:], f"synthetic lag log with encoders, odometry at {odometry_rate:g} Hz"
    command = sent[np.clip(np.searchsorted(sent_t, t, side="right") - 1, 0, None)]
    return SpeedLog(t=t, command=command, speed=measured, source=source, sent_t=sent_t, sent=sent)


def reversing_steps(
    *, amplitude: float, duration: float = 30.0, rate: float = 50.0, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """Times [s] and a two-channel input (n, 2) (wheel torques [N m], or voltages [V]) that excite a robot without
    running away: held steps of common and differential input within +-``amplitude``, each followed by its
    opposite, so the speeds wander about zero."""
    rng = np.random.default_rng(seed)
    t = np.arange(round(duration * rate)) / rate
    steps = np.zeros((t.size, 2))
    begin = 0.5
    while begin < duration - 0.5:
        hold = rng.uniform(0.3, 1.0)
        push = amplitude * np.array([rng.uniform(-1, 1), rng.uniform(-1, 1)])
        for sign, start in ((1.0, begin), (-1.0, begin + hold)):
            span = (t >= start) & (t < start + hold)
            steps[span] = sign * np.array([push[0] + push[1], push[0] - push[1]]) / 2
        begin += 2 * hold
    return t, steps


def torque_plan(
    *, max_torque: float, duration: float = 30.0, rate: float = 50.0, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`reversing_steps` of wheel torques [N m] within +-``max_torque``."""
    return reversing_steps(amplitude=max_torque, duration=duration, rate=rate, seed=seed)


def body_log(
    truth: np.ndarray,
    t: np.ndarray,
    torque: np.ndarray,
    *,
    wheel_radius: float,
    half_axle: float,
    noise: tuple[float, float] = (0.0, 0.0),
    delay: float = 0.0,
    seed: int = 0,
) -> SpeedLog:
    """The log of a torque-driven robot whose body model is ``truth`` = (M_v, m d, M_w, b_w, tau_c): the torques as
    commanded, the speeds plus white ``noise`` (std of v [m/s], omega [rad/s]); ``delay`` [s] from command to
    wheel."""
    from .body import body_model

    model = body_model(wheel_radius=wheel_radius, half_axle=half_axle)
    fine_t, applied = _applied_finely(t, torque, delay)
    speeds = simulate(model, np.asarray(truth, dtype=float), fine_t, applied, np.zeros(2), False)
    rng = np.random.default_rng(seed)
    measured = speeds[::FINE][: len(t)] + rng.normal(size=(len(t), 2)) * np.asarray(noise)
    return SpeedLog(t=t, command=torque, speed=measured, source="synthetic body log")


@dataclass(frozen=True)
class _VoltageDriven:
    """(v_dot, omega_dot) of a robot whose motors a PWM board drives (model.md §1.7, :func:`voltage_driver`, its
    clips included), with ``p`` = (m, I_C, d, b_w, tau_c, J_w, R_a, eta k_t, k_e): the truth of a synthetic log,
    written apart from the fitted model (hashable, so one compiled simulation serves it)."""

    wheel_radius: float
    half_axle: float
    supply_voltage: float
    current_limit: float

    def robot(self, p: Any) -> tuple[RobotParams, DCMotor]:
        params = RobotParams(
            mass=p[0],
            inertia=p[1],
            com_offset=p[2],
            wheel_radius=self.wheel_radius,
            half_axle=self.half_axle,
            viscous_friction=p[3],
            coulomb_friction=p[4],
            wheel_inertia=p[5],
        )
        motor = DCMotor(p[6], p[7], p[8], 1.0, self.supply_voltage, self.current_limit)
        return params, motor

    def __call__(self, p: Array, speed: Array, voltage: Array) -> Array:
        params, motor = self.robot(p)
        torque, _ = voltage_driver(motor, voltage, dynamics.wheel_speeds(params, speed))
        return dynamics.body_acceleration(params, speed, torque, jnp.zeros(2))


def motor_log(
    robot: RobotParams,
    motor: DCMotor,
    t: np.ndarray,
    voltage: np.ndarray,
    *,
    noise: tuple[float, float] = (0.0, 0.0),
    current_noise: float = 0.0,
    delay: float = 0.0,
    seed: int = 0,
) -> MotorLog:
    """The log of ``robot`` whose wheels ``motor`` turns (efficiency folded into its torque constant), driven by
    the armature ``voltage`` (n, 2) [V] sent at the times ``t`` [s] and acting ``delay`` [s] later: the voltages
    as sent, the speeds plus white ``noise`` (std of v [m/s], omega [rad/s]) and the currents drawn plus white
    ``current_noise`` [A]."""
    rate = _VoltageDriven(robot.wheel_radius, robot.half_axle, float(motor.supply_voltage), float(motor.current_limit))
    truth = np.array(
        [
            robot.mass,
            robot.inertia,
            robot.com_offset,
            robot.viscous_friction,
            robot.coulomb_friction,
            robot.wheel_inertia,
            motor.resistance,
            motor.efficiency * motor.torque_constant,
            motor.back_emf,
        ],
        dtype=float,
    )
    model = SpeedModel("truth", (), (), (), rate, lambda *_: (np.zeros(0), np.zeros(0)), (), (), ("u_r", "u_l"))
    fine_t, applied = _applied_finely(t, voltage, delay)
    speeds = simulate(model, truth, fine_t, applied, np.zeros(2), False)[::FINE][: len(t)]
    _, true_motor = rate.robot(jnp.asarray(truth))
    wheels = np.column_stack(
        wheel_speeds(speeds[:, 0], speeds[:, 1], wheel_radius=robot.wheel_radius, half_axle=robot.half_axle)
    )
    _, current = voltage_driver(true_motor, jnp.asarray(applied[::FINE][: len(t)]), jnp.asarray(wheels))
    rng = np.random.default_rng(seed)
    measured = speeds + rng.normal(size=(len(t), 2)) * np.asarray(noise)
    drawn = np.asarray(current) + rng.normal(size=(len(t), 2)) * current_noise
    return MotorLog(SpeedLog(t=t, command=voltage, speed=measured, source="synthetic motor log"), drawn)
