"""Reference generators against SPEC 6 item 25 and SPEC 4.2-4.3.

Every trajectory is evaluated through one jitted ``vmap`` over a grid of times (the trajectory is a
jit argument, so each class compiles once per grid size).
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ddtrack  # noqa: F401  (turns on float64)
from ddtrack.trajectories import Circle, FigureEight, Line, PiecewisePath, Reference, Sinusoid, polyline_path, square

V_R = 0.5
SIDE = 10.0
C0, C1, C2, C3 = (10.0, 0.0), (20.0, 0.0), (20.0, 10.0), (10.0, 10.0)  # SPEC 4.3
FD_STEP = 1e-3  # [s] central-difference step
# central differences: truncation h^2/6 max|f'''| <= 1e-7 (|p'''| <= v^3/r^2 = 0.5 m/s^3 on the rounded square's
# arcs, less elsewhere); rounding eps |p| / h <= 5e-12 for |p| <= 20 m. 1e-6 is 10x above both, far below any
# formula error (a wrong factor or sign gives errors of order v_r, omega_r, ...)
FD_TOL = 1e-6

call = jax.jit(lambda traj, t: traj(t))
evaluate = jax.jit(jax.vmap(lambda traj, t: traj(t), in_axes=(None, 0)))


def as_np(ref: Reference) -> dict:
    return {name: np.asarray(value) for name, value in ref._asdict().items()}


def wrap(angle):
    return np.mod(np.asarray(angle) + np.pi, 2 * np.pi) - np.pi


SMOOTH = {
    "line": Line(start=(1.0, -2.0), heading=2.5, speed=0.7),
    "paper_line": Line(heading=math.pi / 4, speed=V_R),
    "circle": Circle(center=(1.0, 2.0), radius=3.0, speed=0.6, start_angle=0.3),
    "circle_cw": Circle(center=(-1.0, 0.5), radius=1.5, speed=0.4, clockwise=True),
    "figure_eight": FigureEight(center=(1.0, 1.0), size=3.0, period=40.0),
    "sinusoid": Sinusoid(start=(0.0, 1.0), heading=-0.4, speed=0.5, amplitude=1.0, wavelength=8.0),
}
PIECEWISE = {
    "square": square(),
    "rounded_square": square(corner_radius=0.5),
    "open_polyline": polyline_path([(0.0, 0.0), (3.0, 0.0), (3.0, 4.0), (-1.0, 4.0)], speed=0.4),
    "rounded_open_polyline": polyline_path(
        [(0.0, 0.0), (3.0, 0.0), (3.0, 4.0), (-1.0, 1.0)], speed=0.4, corner_radius=0.6
    ),
    "rounded_zigzag": polyline_path(
        [(0.0, 0.0), (3.0, 0.0), (5.0, -2.0), (8.0, -2.0), (8.0, -6.0)], speed=0.5, corner_radius=0.5
    ),  # right and left turns
    "rounded_loop": polyline_path(
        [(0.0, 0.0), (4.0, 1.0), (1.0, 3.0), (0.0, 0.0)], speed=0.3, corner_radius=0.4, loop=True
    ),
}
ALL = {**SMOOTH, **PIECEWISE}


def joint_times(path: PiecewisePath, t_max: float) -> np.ndarray:
    """Times at which a piecewise path changes segment (every lap for a loop) and its end time."""
    lap = path.length / path.speed
    offsets = np.asarray(path.offsets) / path.speed
    laps = np.arange(0, math.ceil(t_max / lap) + 1) if path.loop else np.array([0])
    return np.concatenate([(offsets[None] + lap * laps[:, None]).ravel(), lap * (laps + 1)])


def sample_times(name, traj, n=401):
    """A grid over a lap (two laps of a loop), keeping away from segment joints and from the end."""
    if name in SMOOTH:
        return np.linspace(0.5, 60.0, n)
    lap = traj.length / traj.speed
    t_max = 2 * lap if traj.loop else lap
    t = np.linspace(0.0, t_max, n)
    joints = joint_times(traj, t_max)
    far = np.min(np.abs(t[:, None] - joints[None]), axis=1) > 3 * FD_STEP
    return t[far & (t > 3 * FD_STEP) & (t < t_max - 3 * FD_STEP)]


# --- SPEC 6.25: speed, heading, yaw rate and their derivatives agree with the position -----------


@pytest.mark.parametrize("name", list(ALL))
def test_reference_agrees_with_finite_differences_of_its_position(name):
    traj = ALL[name]
    t = sample_times(name, traj)
    n = t.size
    ref = as_np(evaluate(traj, jnp.asarray(np.concatenate([t - FD_STEP, t, t + FD_STEP]))))
    before, now, after = ({k: v[i * n : (i + 1) * n] for k, v in ref.items()} for i in range(3))

    def diff(field):
        return (after[field] - before[field]) / (2 * FD_STEP)

    x_dot, y_dot = diff("x"), diff("y")
    np.testing.assert_allclose(np.hypot(x_dot, y_dot), now["v"], rtol=0, atol=FD_TOL)  # ||p_dot|| = v_r
    np.testing.assert_allclose(wrap(now["theta"] - np.arctan2(y_dot, x_dot)), 0.0, rtol=0, atol=FD_TOL)
    omega_fd = wrap(after["theta"] - before["theta"]) / (2 * FD_STEP)  # derivative of the unwrapped heading
    np.testing.assert_allclose(omega_fd, now["omega"], rtol=0, atol=FD_TOL)
    np.testing.assert_allclose(diff("v"), now["v_dot"], rtol=0, atol=FD_TOL)
    np.testing.assert_allclose(diff("omega"), now["omega_dot"], rtol=0, atol=FD_TOL)
    # headings are reported wrapped to (-pi, pi]
    assert np.all((now["theta"] > -np.pi) & (now["theta"] <= np.pi))
    assert np.all(now["v"] > 0.0)  # moving everywhere on the sampled part


@pytest.mark.parametrize("name", ["figure_eight", "sinusoid"])
def test_curved_references_exercise_every_field(name):
    """The finite-difference test above is not vacuous: these curves have v_dot, omega, omega_dot != 0."""
    ref = as_np(evaluate(SMOOTH[name], jnp.linspace(0.5, 60.0, 401)))
    for field in ("v_dot", "omega", "omega_dot"):
        assert np.max(np.abs(ref[field])) > 1e-3, field
    assert np.ptp(np.unwrap(ref["theta"])) > 1.0  # turns by more than a radian


def test_smooth_curves_closed_forms():
    t = jnp.linspace(0.0, 50.0, 201)
    tn = np.asarray(t)
    line = as_np(evaluate(SMOOTH["paper_line"], t))
    # SPEC 4.2: x_r = y_r = v_r t / sqrt 2, theta_r = pi/4, omega_r = v_dot = omega_dot = 0
    np.testing.assert_allclose(line["x"], V_R * tn / np.sqrt(2), rtol=1e-15, atol=1e-14)  # rounding only
    np.testing.assert_allclose(line["y"], V_R * tn / np.sqrt(2), rtol=1e-15, atol=1e-14)
    np.testing.assert_allclose(line["theta"], np.pi / 4, rtol=1e-15)
    np.testing.assert_allclose(line["v"], V_R, rtol=1e-15)
    assert np.all(line["omega"] == 0) and np.all(line["v_dot"] == 0) and np.all(line["omega_dot"] == 0)
    for name, sign in (("circle", 1.0), ("circle_cw", -1.0)):
        c = SMOOTH[name]
        ref = as_np(evaluate(c, t))
        radius = np.hypot(ref["x"] - c.center[0], ref["y"] - c.center[1])
        np.testing.assert_allclose(radius, c.radius, rtol=1e-14)  # on the circle, up to rounding
        np.testing.assert_allclose(ref["omega"], sign * c.speed / c.radius, rtol=1e-13)  # omega_r = +-v_r / r
        np.testing.assert_allclose(ref["v_dot"], 0.0, atol=1e-14)
        np.testing.assert_allclose(ref["omega_dot"], 0.0, atol=1e-14)
        # the heading is the tangent: perpendicular to the radius, turning the right way
        radial = np.arctan2(ref["y"] - c.center[1], ref["x"] - c.center[0])
        np.testing.assert_allclose(wrap(ref["theta"] - radial - sign * np.pi / 2), 0.0, atol=1e-12)
    # figure eight (lemniscate of Gerono): both lobes in one period; v = size w sqrt(cos^2 wt + cos^2 2wt), which
    # lies in [sqrt(7)/4, sqrt(2)] size w (minimum at cos^2 wt = 3/8, NOT size w at the lobe tips as the
    # FigureEight docstring says); it never stops
    f8 = SMOOTH["figure_eight"]
    ref = as_np(evaluate(f8, t))
    w = 2 * np.pi / f8.period
    np.testing.assert_allclose(ref["x"], 1.0 + 3.0 * np.sin(w * tn), rtol=0, atol=1e-14)  # rounding
    np.testing.assert_allclose(ref["y"], 1.0 + 1.5 * np.sin(2 * w * tn), rtol=0, atol=1e-14)
    speed = 3.0 * w * np.sqrt(np.cos(w * tn) ** 2 + np.cos(2 * w * tn) ** 2)
    np.testing.assert_allclose(ref["v"], speed, rtol=1e-14)  # rounding
    assert np.all(ref["v"] >= np.sqrt(7) / 4 * 3.0 * w * (1 - 1e-14)) and np.all(ref["v"] <= np.sqrt(2) * 3.0 * w)
    # sinusoid: the axis is run at v along its heading, the lateral offset is A sin(2 pi s / wavelength)
    sn = SMOOTH["sinusoid"]
    ref = as_np(evaluate(sn, t))
    dx, dy = ref["x"] - sn.start[0], ref["y"] - sn.start[1]
    along = np.cos(sn.heading) * dx + np.sin(sn.heading) * dy
    across = -np.sin(sn.heading) * dx + np.cos(sn.heading) * dy
    np.testing.assert_allclose(along, sn.speed * tn, rtol=0, atol=1e-13)  # rounding on 25 m
    np.testing.assert_allclose(across, sn.amplitude * np.sin(2 * np.pi * sn.speed * tn / sn.wavelength), atol=1e-13)


# --- SPEC 4.3: the square ----------------------------------------------------------------------


def sharp_square_closed_form(t):
    """Position and heading of the sharp square of SPEC 4.3 (independent of the package)."""
    s = np.mod(V_R * t, 4 * SIDE)
    side, along = np.floor(s / SIDE).astype(int), np.mod(s, SIDE)
    corners = np.array([C0, C1, C2, C3])
    directions = np.array([(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)])
    headings = np.array([0.0, np.pi / 2, np.pi, -np.pi / 2])
    p = corners[side] + along[:, None] * directions[side]
    return p, headings[side]


def test_sharp_square_follows_spec():
    sq = PIECEWISE["square"]
    lap = 4 * SIDE / V_R
    assert sq.length == pytest.approx(4 * SIDE, rel=1e-15) and sq.loop
    t = np.linspace(0.0, 2 * lap, 1601)
    t = t[np.min(np.abs(np.mod(t, SIDE / V_R)[:, None] - np.array([0.0, SIDE / V_R])[None]), axis=1) > 1e-6]
    ref = as_np(evaluate(sq, jnp.asarray(t)))
    p, heading = sharp_square_closed_form(t)
    np.testing.assert_allclose(np.column_stack([ref["x"], ref["y"]]), p, rtol=0, atol=1e-12)  # rounding on 40 m
    np.testing.assert_allclose(ref["theta"], heading, rtol=0, atol=1e-15)  # piecewise constant, exact
    np.testing.assert_allclose(ref["v"], V_R, rtol=1e-15)
    assert np.all(ref["omega"] == 0) and np.all(ref["v_dot"] == 0) and np.all(ref["omega_dot"] == 0)


def test_sharp_square_hits_corners_and_closes():
    sq = PIECEWISE["square"]
    leg = SIDE / V_R
    corner_times = np.array([0.0, leg, 2 * leg, 3 * leg, 4 * leg, 8 * leg])
    ref = as_np(evaluate(sq, jnp.asarray(corner_times)))
    expected = np.array([C0, C1, C2, C3, C0, C0])
    np.testing.assert_allclose(np.column_stack([ref["x"], ref["y"]]), expected, rtol=0, atol=1e-12)  # rounding
    # headings on either side of each corner: 0 -> pi/2 -> pi -> -pi/2 -> 0
    eps = 1e-6
    side = as_np(evaluate(sq, jnp.asarray(np.concatenate([corner_times[1:5] - eps, corner_times[1:5] + eps]))))
    np.testing.assert_allclose(side["theta"][:4], [0.0, np.pi / 2, np.pi, -np.pi / 2], atol=1e-15)
    np.testing.assert_allclose(side["theta"][4:], [np.pi / 2, np.pi, -np.pi / 2, 0.0], atol=1e-15)
    # periodic with period 4S/v_r
    t = jnp.linspace(0.0, 4 * leg, 97) + 0.37  # off the corners, where the heading is discontinuous
    one, two = as_np(evaluate(sq, t)), as_np(evaluate(sq, t + 4 * leg))
    for field in ("x", "y", "theta", "v"):
        np.testing.assert_allclose(two[field], one[field], rtol=0, atol=1e-12)  # rounding in mod(v t, 4S)


def test_rounded_square_lap_length_arcs_and_c1():
    r = 0.5
    rs = PIECEWISE["rounded_square"]
    length = 4 * SIDE - 6 * r + 1.5 * np.pi * r  # SPEC 4.3
    assert rs.length == pytest.approx(length, rel=1e-14)
    lap = length / V_R
    # seven segments: four straights with three quarter-circle fillets between them, C0 stays sharp
    np.testing.assert_allclose(np.asarray(rs.curvatures), [0, 1 / r, 0, 1 / r, 0, 1 / r, 0], rtol=1e-15)
    offsets = np.asarray(rs.offsets)
    expected_offsets = np.cumsum([0, SIDE - r, np.pi * r / 2, SIDE - 2 * r, np.pi * r / 2, SIDE - 2 * r, np.pi * r / 2])
    np.testing.assert_allclose(offsets, expected_offsets, rtol=1e-14)

    # closes at C0 after one lap
    end = as_np(evaluate(rs, jnp.asarray([0.0, lap, 2 * lap])))
    np.testing.assert_allclose(np.column_stack([end["x"], end["y"]]), [C0, C0, C0], atol=1e-12)  # rounding
    assert end["theta"][0] == 0.0  # (at t = k lap the heading is either side of the sharp C0, see below)

    # on the arcs omega_r = v_r / r and the point is at distance r from the fillet centre
    fillet_centres = np.array([(C1[0] - r, C1[1] + r), (C2[0] - r, C2[1] - r), (C3[0] + r, C3[1] - r)])
    for k, centre in zip((1, 3, 5), fillet_centres, strict=True):
        t_arc = np.linspace(offsets[k], offsets[k + 1], 11)[1:-1] / V_R
        arc = as_np(evaluate(rs, jnp.asarray(t_arc)))
        np.testing.assert_allclose(arc["omega"], V_R / r, rtol=1e-15)
        np.testing.assert_allclose(np.hypot(arc["x"] - centre[0], arc["y"] - centre[1]), r, atol=1e-12)
    for k in (0, 2, 4, 6):
        t_line = np.linspace(offsets[k], offsets[k + 1] if k < 6 else length, 11)[1:-1] / V_R
        assert np.all(np.asarray(evaluate(rs, jnp.asarray(t_line)).omega) == 0.0)

    # (C^1 across the joints between segments: test_rounded_paths_are_c1)
    # the start corner C0 is not filleted (SPEC 4.3 rounds C1..C3 only): the heading jumps by pi/2 there
    around = as_np(evaluate(rs, jnp.asarray([lap - 1e-6, lap + 1e-6])))
    assert wrap(around["theta"][1] - around["theta"][0]) == pytest.approx(np.pi / 2, abs=1e-9)


@pytest.mark.parametrize("name", ["rounded_square", "rounded_open_polyline", "rounded_zigzag", "rounded_loop"])
def test_rounded_paths_are_c1(name):
    """Position and heading are continuous across every joint between two segments of a lap."""
    path = PIECEWISE[name]
    curvatures = np.asarray(path.curvatures)
    assert np.any(curvatures > 0) and (name != "rounded_zigzag" or np.any(curvatures < 0))
    delta = 1e-9
    joints = np.asarray(path.offsets)[1:] / path.speed
    left = as_np(evaluate(path, jnp.asarray(joints - delta)))
    right = as_np(evaluate(path, jnp.asarray(joints + delta)))
    gap = np.hypot(right["x"] - left["x"], right["y"] - left["y"])
    assert np.all(gap < 2 * path.speed * delta + 1e-12), gap  # moved v_r * 2 delta, plus rounding on 20 m
    # the heading turns by at most |omega_r| * 2 delta across a joint, plus rounding
    max_turn = 2 * path.speed * np.max(np.abs(curvatures)) * delta + 1e-12
    assert np.all(np.abs(wrap(right["theta"] - left["theta"])) < max_turn)
    # every arc is tangent to the legs it joins: the curvature steps, the heading does not
    assert np.any(np.abs(right["omega"] - left["omega"]) > 0.1)


def test_open_polyline_stops_at_its_end():
    points = [(0.0, 0.0), (3.0, 0.0), (3.0, 4.0), (-1.0, 4.0)]
    for radius in (0.0, 0.6):
        path = polyline_path(points, speed=0.4, corner_radius=radius)
        assert not path.loop
        t_end = path.length / 0.4
        ref = as_np(evaluate(path, jnp.asarray([t_end - 1e-3, t_end, t_end + 1e-3, t_end + 100.0])))
        assert ref["v"][0] == 0.4
        np.testing.assert_array_equal(ref["v"][1:], 0.0)
        np.testing.assert_array_equal(ref["omega"][1:], 0.0)
        # parked at the last point, facing along the last leg
        np.testing.assert_allclose(ref["x"][1:], -1.0, atol=1e-12)  # rounding
        np.testing.assert_allclose(ref["y"][1:], 4.0, atol=1e-12)
        np.testing.assert_allclose(ref["theta"][1:], np.pi, atol=1e-15)
    sharp = polyline_path(points, speed=0.4)
    assert sharp.length == pytest.approx(11.0, rel=1e-15)
    # a sharp path passes through every waypoint at its arc length
    ref = as_np(evaluate(sharp, jnp.asarray([0.0, 3.0 / 0.4, 7.0 / 0.4])))
    np.testing.assert_allclose(np.column_stack([ref["x"], ref["y"]]), points[:3], atol=1e-12)


# --- JAX behaviour ------------------------------------------------------------------------------


@pytest.mark.parametrize("name", list(ALL))
def test_reference_is_float64_under_jit_and_vmap(name):
    traj = ALL[name]
    eager = traj(3)  # a Python int time still gives float64
    assert all(jnp.asarray(value).dtype == jnp.float64 for value in eager), eager
    ts = np.array([0.0, 1.3, 7.0, 31.0, 55.5])
    jitted = [call(traj, t) for t in ts]  # the trajectory is a jit argument (one compilation per class)
    assert all(value.dtype == jnp.float64 and value.shape == () for ref in jitted for value in ref)
    np.testing.assert_allclose(np.array(call(traj, 3.0)), np.array(eager), rtol=1e-14, atol=1e-14)  # same ops
    batched = evaluate(traj, jnp.asarray(ts))  # jit(vmap(.)) over t
    assert all(value.dtype == jnp.float64 and value.shape == (ts.size,) for value in batched)
    np.testing.assert_allclose(np.array(batched), np.array([np.array(r) for r in jitted]).T, rtol=1e-14, atol=1e-14)


def test_jit_treats_trajectory_parameters_as_data():
    """A jitted function taking the trajectory as an argument sees each instance's own parameters."""
    for traj in (Circle(radius=2.0), Circle(radius=5.0, speed=1.0), square(side=4.0), square(side=6.0, speed=1.0)):
        np.testing.assert_allclose(np.array(call(traj, 5.0)), np.array(traj(5.0)), rtol=1e-14, atol=1e-14)
    assert float(call(Circle(radius=5.0, speed=1.0), 5.0).omega) == pytest.approx(0.2, rel=1e-14)
    assert float(call(square(side=4.0), 10.0).x) == pytest.approx(14.0, abs=1e-12)  # 5 m along: C1 + 1 m up
    assert float(call(square(side=4.0), 10.0).y) == pytest.approx(1.0, abs=1e-12)


# --- polyline_path validation -------------------------------------------------------------------


@pytest.mark.parametrize(
    "points, kwargs, match",
    [
        ([(0, 0), (1, 0), (1, 0), (2, 1)], {}, r"point 2 repeats point 1"),
        ([(0, 0), (float("nan"), 1.0), (2, 1)], {}, r"NaN"),
        ([(0, 0), (1.0, float("inf"))], {}, r"finite"),
        ([(0, 0)], {}, r"at least two"),
        ([], {}, r"at least two"),
        ([(0, 0), (1, 0)], {"speed": 0.0}, r"speed must be > 0, got 0"),
        ([(0, 0), (1, 0)], {"speed": -0.5}, r"speed must be > 0, got -0.5"),
        ([(0, 0), (1, 0)], {"speed": float("nan")}, r"speed must be > 0"),
        ([(0, 0), (2, 0), (1, 0)], {"corner_radius": 0.1}, r"reverses direction at point 1"),
        ([(0, 0), (1, 0), (1, 1)], {"corner_radius": 2.0}, r"corner radius 2.0 m does not fit on leg 0"),
        ([(0, 0), (1, 0), (1, 1)], {"corner_radius": -0.1}, r"corner radius must be >= 0"),
    ],
)
def test_polyline_path_rejects_bad_input_with_helpful_message(points, kwargs, match):
    kwargs = {"speed": 0.5, **kwargs}
    with pytest.raises(ValueError, match=match):
        polyline_path(points, **kwargs)


def test_polyline_path_accepts_borderline_input():
    # a sharp U-turn is allowed (only a rounded one is impossible)
    u_turn = polyline_path([(0, 0), (2, 0), (1, 0)], speed=0.5)
    assert u_turn.length == pytest.approx(3.0, rel=1e-15)
    np.testing.assert_allclose(float(u_turn(5.0).theta), np.pi, atol=1e-15)  # 2.5 m: on the way back
    # a radius whose fillet exactly uses a leg fits: 90 degree corner, tangent length r
    exact = polyline_path([(0, 0), (1, 0), (1, 1)], speed=0.5, corner_radius=1.0)
    assert exact.length == pytest.approx(np.pi / 2, rel=1e-14)  # nothing but the quarter circle
    assert np.count_nonzero(np.asarray(exact.curvatures) == 1.0) == 1
    end = exact(np.pi)  # pi/2 m at 0.5 m/s: the end of the fillet, which is the last waypoint
    np.testing.assert_allclose([float(end.x), float(end.y), float(end.theta)], [1.0, 1.0, np.pi / 2], atol=1e-12)


def test_a_switched_trajectory_gives_its_chosen_reference_bit_for_bit():
    """A study's frame (trajectories.switched): each run carries every kind the study uses and picks its own; the
    chosen reference is the trajectory's own, to the bit, and a path padded with unreachable segments is unchanged."""
    from ddtrack.trajectories.switched import pad_path, trajectory_frame

    rounded = square(corner=C0, side=SIDE, speed=V_R, corner_radius=1.0)  # 7 segments
    sharp = square(corner=C0, side=SIDE, speed=V_R)  # 4
    eight = FigureEight(size=2.0, period=30.0)
    assert trajectory_frame([sharp, rounded]) is None  # one kind: the runs keep their own trajectory
    frame = trajectory_frame([eight, sharp, rounded, eight])
    assert frame is not None and frame.segments == 7 and len(frame.stand_ins) == 2
    t = jnp.linspace(0.0, 95.0, 1901)  # across corners and past the first lap (40 s)
    padded = pad_path(sharp, 7)
    assert padded.offsets.shape == (7,) and np.isinf(padded.offsets[4:]).all()
    expected = {name: as_np(evaluate(traj, t)) for name, traj in (("sharp", sharp), ("eight", eight))}
    for key, values in as_np(evaluate(padded, t)).items():
        np.testing.assert_array_equal(values, expected["sharp"][key], err_msg=f"padded: {key}")
    runs = 3  # a batch of runs, as the simulator evaluates a study's trajectories: its own batched, or switched
    over_runs = jax.jit(jax.vmap(lambda traj, t: jax.vmap(traj)(t), in_axes=(0, None)))
    for index, (name, traj) in enumerate((("eight", eight), ("sharp", sharp))):  # the frame's order: first seen
        batch = jax.tree_util.tree_map(lambda leaf: jnp.broadcast_to(leaf, (runs, *jnp.shape(leaf))), traj)
        switched = frame.place(batch, runs)
        assert switched.chosen.tolist() == [index] * runs
        own, chosen = as_np(over_runs(batch, t)), as_np(over_runs(switched, t))
        np.testing.assert_allclose(own["x"][0], expected[name]["x"], rtol=1e-13)  # the trajectory it is
        for key, values in own.items():
            np.testing.assert_array_equal(chosen[key], values, err_msg=f"{name}: {key}")
