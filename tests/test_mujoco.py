"""MuJoCo as an independent physics check of the plant (docs/reliability.md, "Independent physics check: MuJoCo").

``tests/mujoco_model.py`` builds a MuJoCo robot (free chassis, hinged sphere wheels, frictionless caster, floor with
friction mu) from the same :class:`~ddtrack.model.RobotParams`. Three checks:

* within grip, the same torques (held per control period) move both to the same place over 10 s, and the gap
  shrinks in proportion to MuJoCo's contact time constant (its soft contacts lag the no-slip constraint);
* in a tightening turn, MuJoCo's wheels start to slip where ``traction.required_friction`` of ddtrack's run
  reaches mu;
* beyond grip, MuJoCo's robot accelerates at mu g (1 - d / l_c), the traction limit of docs/model.md, and so does
  ddtrack's own slip plant (model.md §1.10) on the same robot and floor, its wheels sliding as fast as MuJoCo's on
  average. Where the two contact models part: MuJoCo's soft contacts chatter while sliding, so its normal loads,
  its acceleration (within 6 %) and the split of the slip between its wheels move; the slip plant's loads are static.

mujoco is a test dependency: without it this module fails to import, it is not skipped.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from mujoco_model import GRAVITY, MujocoRobot, compared_params

from ddtrack.integrators import RK4
from ddtrack.model import DynamicPlant, RobotParams, slip_plant, traction
from ddtrack.robots import preset

PERIOD = 0.01  # [s] the control period: torques are held this long in both simulators
FLOOR = 1.0  # the floor's friction coefficient mu
#: the paper's robot has massless wheels and no caster position: MuJoCo's wheels are 0.1 kg discs (J_w = m R^2 / 2,
#: modelled by ddtrack too) and its caster sits 0.3 m ahead of the axle
PAPER_WHEEL_INERTIA = 0.5 * 0.1 * 0.05**2
PAPER_CASTER = 0.3


def robot(name: str) -> tuple[RobotParams, float]:
    """The compared parameters of preset ``name`` and its caster position l_c [m]."""
    chosen = preset(name)
    if name == "paper":
        return compared_params(chosen.robot_params(), wheel_inertia=PAPER_WHEEL_INERTIA), PAPER_CASTER
    assert chosen.caster_position is not None
    return compared_params(chosen.robot_params()), chosen.caster_position


def wheel_load(params: RobotParams, caster: float) -> float:
    """Static normal load on each drive wheel, m g (1 - d / l_c) / 2 [N]."""
    return float(params.mass) * GRAVITY * (1.0 - float(params.com_offset) / caster) / 2.0


def ddtrack_run(params: RobotParams, torques: np.ndarray) -> np.ndarray:
    """BODY states [x, y, theta, v, omega] of DynamicPlant at t = 0, T_c, ..., N T_c under held ``torques`` (N, 2)."""
    plant = DynamicPlant(params)

    def period(x: jax.Array, u: jax.Array) -> tuple[jax.Array, jax.Array]:
        return plant.advance(x, u, jnp.zeros(2), PERIOD, RK4(10)), x

    last, states = jax.lax.scan(period, jnp.zeros(5), jnp.asarray(torques))
    return np.vstack([np.asarray(states), np.asarray(last)[None]])


def mujoco_run(
    params: RobotParams, caster: float, torques: np.ndarray, timestep: float
) -> tuple[np.ndarray, np.ndarray, MujocoRobot]:
    """MuJoCo's BODY states (heading unwrapped) as :func:`ddtrack_run`'s, its wheels' slip speeds after each period
    (N, 2) [m/s], and the robot at the end."""
    mj = MujocoRobot(params, friction=FLOOR, caster_position=caster, timestep=timestep)
    mj.settle()
    states, slips = [mj.body()], []
    for u in torques:
        mj.advance(u, PERIOD)
        states.append(mj.body())
        slips.append(mj.slip_speeds())
    out = np.array(states)
    out[:, 2] = np.unwrap(out[:, 2])
    return out, np.array(slips), mj


def needed_friction(params: RobotParams, caster: float, states: np.ndarray) -> np.ndarray:
    """``traction.required_friction`` of a ddtrack run, rescaled from its load m g / 2 per wheel to the wheel load
    with the caster carrying its share."""
    t = PERIOD * np.arange(len(states))
    mu = traction.required_friction(
        t,
        states[:, 3],
        states[:, 4],
        mass=float(params.mass),
        inertia_axle=float(params.inertia_axle),
        com_offset=float(params.com_offset),
        half_axle=float(params.half_axle),
    )
    return mu * (float(params.mass) * GRAVITY / 2.0) / wheel_load(params, caster)


def replay_torques(scale: float, duration: float = 10.0) -> np.ndarray:
    """Open-loop torques (N, 2) [N m] up to about ``scale``: a forward-backward drive (cosines, so the speed swings
    about zero) and a slower weaving turn."""
    t = PERIOD * np.arange(round(duration / PERIOD))
    common = 0.6 * np.cos(2 * np.pi * t / 1.5) + 0.25 * np.cos(2 * np.pi * t / 0.7)
    turn = 0.25 * np.sin(2 * np.pi * t / 1.7 + 0.5)
    return scale * np.stack([common + turn, common - turn], axis=1)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "scale", "viscous"), [("paper", 1.5, 0.0), ("paper", 1.5, 0.01), ("turtlebot3_burger", 0.35, 0.0)]
)
def test_replayed_torques_agree_within_grip(name: str, scale: float, viscous: float) -> None:
    """Within grip, ddtrack and MuJoCo agree to millimetres over 10 s of the same torques, and the gap is MuJoCo's:
    it halves with MuJoCo's contact time constant (2 time steps), so the extrapolated gap is far smaller still."""
    params, caster = robot(name)
    params = dataclasses.replace(params, viscous_friction=viscous)  # b_w [N m s/rad]: MuJoCo's hinge damping
    torques = replay_torques(scale)
    ours = ddtrack_run(params, torques)
    # the premise: the floor carries the motion (required friction well under mu = 1, the caster's load counted)
    needed = needed_friction(params, caster, ours)
    print(f"{name}: needs mu = {needed.max():.3f}")
    assert 0.5 < needed.max() < 0.9 * FLOOR, needed.max()
    gaps, places = {}, {}
    for timestep in (2e-4, 1e-4):
        theirs, slips, _ = mujoco_run(params, caster, torques, timestep)
        places[timestep] = theirs[:, :2]
        gaps[timestep] = np.hypot(*(ours[:, :2] - theirs[:, :2]).T)
        assert slips.max() < 0.02, f"{name}: MuJoCo's wheels slipped ({slips.max():.3g} m/s) within grip"
    coarse, fine = gaps[2e-4].max(), gaps[1e-4].max()
    # measured: paper 4.24 mm at 0.2 ms, 2.12 mm at 0.1 ms, extrapolated 0.002 mm; with b_w = 0.01 (slower, less
    # creep) 0.79 mm, 0.40 mm, 0.005 mm; TurtleBot3 Burger (0.35 N m) 1.95 mm, 0.97 mm, 0.002 mm
    assert fine < 3e-3, f"{name}: {fine * 1e3:.3f} mm apart after 10 s"
    assert 1.8 < coarse / fine < 2.2, f"{name}: gap {coarse * 1e3:.3f} mm -> {fine * 1e3:.3f} mm, not first order"
    limit = 2.0 * places[1e-4] - places[2e-4]  # MuJoCo's path at time constant 0, extrapolated to first order
    extrapolated = np.hypot(*(ours[:, :2] - limit).T).max()
    print(f"{name} b_w {viscous}: {coarse * 1e3:.3f} mm, {fine * 1e3:.3f} mm, extrapolated {extrapolated * 1e3:.4f} mm")
    assert extrapolated < 0.02e-3, f"{name}: {extrapolated * 1e3:.3f} mm apart in the limit"


def friction_used(mj: MujocoRobot) -> float:
    """The larger of the two wheels' tangential over normal contact force in MuJoCo: mu when a wheel slides."""
    forces = mj.contact_forces()
    return max(forces[tyre][1] / forces[tyre][0] for tyre in ("tyre_right", "tyre_left"))


@pytest.mark.parametrize(
    ("name", "rate", "turn"), [("paper", 1.5, 0.0), ("paper", 1.5, 0.3), ("turtlebot3_burger", 0.2, 0.3)]
)
def test_slip_starts_where_required_friction_reaches_mu(name: str, rate: float, turn: float) -> None:
    """From rest, torques ramping at ``rate`` [N m/s], the right wheel's ``turn`` more and the left's less (a turn
    that tightens as it speeds up): MuJoCo's wheels start to slide (friction force at mu times the normal force)
    in the control period where ddtrack's required friction of the same torques reaches mu, and until then use
    the friction ddtrack says they need."""
    params, caster = robot(name)
    t = PERIOD * np.arange(200)
    torques = rate * t[:, None] * np.array([1.0 + turn, 1.0 - turn])
    needed = needed_friction(params, caster, ddtrack_run(params, torques))  # [k]: over period k
    mj = MujocoRobot(params, friction=FLOOR, caster_position=caster, timestep=2e-4)
    mj.settle()
    used, slips = [], []
    for u in torques:
        mj.advance(u, PERIOD)
        used.append(friction_used(mj))  # [k]: at the end of period k
        slips.append(mj.slip_speeds().max())
        if used[-1] > 0.999 * FLOOR:
            break
    onset, reached = len(used) - 1, int(np.argmax(needed >= FLOOR))
    assert used[-1] > 0.999 * FLOOR, f"{name}: no slip within {t[-1]:.1f} s"
    # measured: paper straight 1.38 s as ddtrack, turning 0.86 s (ddtrack 0.87 s), Burger turning 1.04 s (ddtrack
    # 1.06 s, needing mu = 0.955: MuJoCo's more lightly loaded wheel carries 1 % less than the static load, from the
    # wheels' own mass and gyroscopic moment in the turn, which the planar model has not)
    assert abs(onset - reached) <= 2, f"{name}: slides in period {onset}, ddtrack needs mu in period {reached}"
    assert 0.95 < needed[onset] < 1.03, f"{name}: slides where ddtrack needs mu = {needed[onset]:.3f}"
    before = slice(20, onset - 1)
    at_ends = (needed[:-1] + needed[1:]) / 2.0  # [k]: needed at the end of period k, as MuJoCo's is read
    gap = np.abs(np.array(used[before]) - at_ends[before]).max()
    print(f"{name} turn {turn}: onset {onset * PERIOD:.2f} s, ddtrack {reached * PERIOD:.2f} s, gap in mu {gap:.4f}")
    # measured: paper 0.005 (straight and turning), Burger 0.024 (its wheels' loads, above)
    assert gap < 0.04, f"{name}: MuJoCo's friction differs from the required friction by {gap:.3f} before slip"
    # and then it slides: within 10 periods the wheel's contact point moves at 10 times its speed within grip
    for u in torques[onset + 1 : onset + 11]:
        mj.advance(u, PERIOD)
    assert mj.slip_speeds().max() > 10 * max(slips[before]), f"{name}: the wheels did not slip"


@pytest.mark.parametrize("torque", [4.0, 4.2])
def test_acceleration_beyond_grip_is_traction_limited(torque: float) -> None:
    """From rest, straight, with torques beyond grip: MuJoCo's robot accelerates at mu times its wheels' normal load
    over m, within a few per cent of mu g (1 - d / l_c) (docs/model.md §1.5), short of the no-slip
    plant's.

    The paper's robot with geared wheels (J_w = 0.01 kg m^2), just beyond grip (the no-slip plant would need
    mu = 1.09 and 1.14): MuJoCo's sliding wheels chatter on the floor (its soft contacts push sliding bodies apart),
    1 mm at 4 N m, 2.6 mm at 4.2 N m, 15 mm at 5 N m, and with the light 0.1 kg wheels the chassis leaves the floor,
    so the check stays near grip. The normal loads are MuJoCo's own, averaged over every time step: they move with
    the chatter, which puts the acceleration a few per cent either side of the static-load limit."""
    params, caster = robot("paper")
    params = dataclasses.replace(params, wheel_inertia=0.01)
    no_slip = 2.0 * torque / (float(params.wheel_radius) * float(params.effective_mass))
    limit = FLOOR * GRAVITY * (1.0 - float(params.com_offset) / caster)
    assert no_slip > 1.05 * limit  # the premise: beyond grip
    timestep = 2e-4
    mj = MujocoRobot(params, friction=FLOOR, caster_position=caster, timestep=timestep)
    mj.settle()
    mj.advance(np.array([torque, torque]), 0.1)  # the slip develops
    start, loads, heights = mj.body()[3], [], []
    steps = round(0.2 / timestep)
    for _ in range(steps):
        mj.advance(np.array([torque, torque]), timestep)
        forces = mj.contact_forces()
        loads.append(sum(forces[tyre][0] for tyre in ("tyre_right", "tyre_left") if tyre in forces))
        heights.append(mj.data.qpos[2])
    acceleration = (mj.body()[3] - start) / (steps * timestep)
    traction = FLOOR * np.mean(loads) / float(params.mass)
    print(
        f"{torque} N m: a = {acceleration:.3f}, mu N / m = {traction:.3f}, limit {limit:.3f}, no slip {no_slip:.3f}, "
        f"hop {np.ptp(heights) * 1e3:.3f} mm"
    )
    # measured: 4 N m: 7.930 against mu N / m = 7.935 and mu g (1 - d / l_c) = 8.172; 4.2 N m: 8.513, 8.522
    assert mj.slip_speeds().min() > 0.1, "the wheels grip"
    assert abs(acceleration - traction) < 0.01 * traction, f"{acceleration:.3f} m/s^2 is not mu N / m = {traction:.3f}"
    assert 0.94 * limit < acceleration < 1.06 * limit, (
        f"{acceleration:.3f} m/s^2 against mu g (1 - d / l_c) {limit:.3f}"
    )
    assert np.ptp(heights) < 0.1 * float(params.wheel_radius), "the chassis left the floor"
    # ddtrack's own slip plant on the same robot, floor and caster: its sliding wheels take mu N_i from the floor at
    # the static loads (model.md §1.10), so it accelerates at the limit itself; MuJoCo's loads move with its chatter
    ours = slip_states(params, caster, torque, 0.3)
    slip_acceleration = (ours[30, 3] - ours[10, 3]) / 0.2
    spins = ours[30, 6:8] * float(params.wheel_radius) - ours[30, 3]  # each contact's slip at 0.3 s
    print(f"slip plant: a = {slip_acceleration:.4f}, slips {spins}, MuJoCo's {mj.slip_speeds()}")
    assert slip_acceleration == pytest.approx(limit, rel=1e-3)
    assert slip_acceleration == pytest.approx(acceleration, rel=0.06)  # the static-load limit against MuJoCo's
    # MuJoCo's two wheels slide unevenly (its chatter shares the load unequally: 0.36 and 0.62 m/s after 0.3 s at
    # 4 N m), the slip plant's alike; their mean agrees (0.486 against 0.492 m/s; 0.784 against 0.771 at 4.2 N m)
    assert spins[0] == spins[1] and spins.mean() == pytest.approx(mj.slip_speeds().mean(), rel=0.05)


def slip_states(params: RobotParams, caster: float, torque: float, duration: float) -> np.ndarray:
    """ddtrack's :class:`~ddtrack.model.SlipPlant` states (:data:`~ddtrack.model.slip.SLIP_STATE`) each period
    from rest under ``torque`` [N m] on both wheels, on the floor of mu = ``FLOOR`` with a slip speed of 1 mm/s."""
    plant = slip_plant(params, friction=FLOOR, slip_speed=1e-3, caster=caster, period=PERIOD, substeps=20)
    solver = RK4(int(plant.substeps))

    def period(x: jax.Array, u: jax.Array) -> tuple[jax.Array, jax.Array]:
        return plant.advance(x, u, jnp.zeros(2), PERIOD, solver), x

    torques = jnp.full((round(duration / PERIOD), 2), torque)
    last, states = jax.lax.scan(period, plant.init(jnp.zeros(5)), torques)
    return np.vstack([np.asarray(states), np.asarray(last)[None]])


def test_paper_torque_limit_is_beyond_a_real_floor() -> None:
    """The paper's 10 N m per wheel on its 10 kg robot with light wheels: ddtrack's no-slip plant accelerates at
    40 m/s^2 and says the run needs mu of about 4; MuJoCo's robot on a floor with mu = 1 cannot follow: its wheels
    spin up, chatter, and throw the chassis off the floor."""
    params, caster = robot("paper")
    torques = np.full((30, 2), 10.0)
    ours = ddtrack_run(params, torques)
    assert needed_friction(params, caster, ours).max() > 3.5
    mj = MujocoRobot(params, friction=FLOOR, caster_position=caster, timestep=2e-4)
    mj.settle()
    heights = []
    for u in torques:
        mj.advance(u, PERIOD)
        heights.append(mj.data.qpos[2] - float(params.wheel_radius))
    print(f"10 N m: ddtrack v = {ours[-1, 3]:.2f} m/s, MuJoCo {mj.body()[3]:.2f} m/s, lifted {max(heights):.3f} m")
    assert max(heights) > float(params.wheel_radius), "MuJoCo's robot stayed on the floor"
    assert abs(mj.body()[3]) < ours[-1, 3] / 3.0
