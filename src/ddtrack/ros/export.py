"""``ddtrack export``: a run folder as a ROS 2 bag (MCAP) that Foxglove and ``ros2 bag`` open, or as CSV with units.

One message per control period on each periodic topic, stamped at ``start + t`` (header stamp and the bag's
receive time alike). Frames are named by the caller: the world ``odom`` and the body ``base_link`` by default (a
TurtleBot3 calls its body ``base_footprint``); the odometry estimate moves a frame of its own, the body's name
with ``_estimate``, so a viewer shows truth and estimate side by side:

===================  ==========================================  ===============================================
topic                type                                        what
===================  ==========================================  ===============================================
/clock               rosgraph_msgs/msg/Clock                     the stamp, for ``use_sim_time``
/tf                  tf2_msgs/msg/TFMessage                      odom -> body (true pose), odom -> estimate,
                                                                 body -> each wheel (its angle)
/odom                nav_msgs/msg/Odometry                       true pose, and body twist (v, 0, omega)
/odom_estimate       nav_msgs/msg/Odometry                       the odometry estimate ([sensing] odometry only),
                                                                 with the estimator's covariances
/reference           geometry_msgs/msg/PoseStamped               the reference pose
/cmd_vel             geometry_msgs/msg/Twist (or TwistStamped)   the velocity command (v_cmd, omega_cmd), if any
/joint_states        sensor_msgs/msg/JointState                  wheel angles [rad], speeds [rad/s], torques [N m]
/robot_description   std_msgs/msg/String                         the robot's URDF, once (transient local)
/tf_static           tf2_msgs/msg/TFMessage                      the URDF's fixed joints, once (transient local)
/reference_path      nav_msgs/msg/Path                           the whole reference, once (transient local)
/path                nav_msgs/msg/Path                           the whole driven path, once at the end (likewise)
===================  ==========================================  ===============================================
"""

from __future__ import annotations

import datetime
import math
import os
import re
import shutil
import tempfile
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from decimal import ROUND_HALF_EVEN, Decimal
from pathlib import Path
from typing import IO, Any

import numpy as np

from ..errors import ConfigError, RunError
from ..model.traction import wheel_speeds
from ..outdir import MARKER_TIME_FORMAT, atomic_write, read_marker
from .covariance import CovariancePropagation, odometry_covariances
from .messages import (
    BODY_FRAME,
    NANOSECONDS,
    WHEEL_JOINTS,
    WORLD_FRAME,
    header,
    message,
    no_covariance,
    planar_pose,
    stamp,
    twist,
    typestore,
    yaw_quaternion,
)
from .urdf import Fixed, fixed_links, robot_urdf, wheel_offsets

#: units of the time-series columns, for the CSV header; a column not listed (a plugin's log) gets none
COLUMN_UNITS = {
    "t": "s",
    **dict.fromkeys(("x", "y", "x_ref", "y_ref", "e_x", "e_y", "e_tr", "odom_x", "odom_y", "odom_ex", "odom_ey"), "m"),
    **dict.fromkeys(("theta", "theta_ref", "e_theta", "odom_theta", "odom_etheta", "phi_r", "phi_l"), "rad"),
    **dict.fromkeys(("pi_r", "pi_l"), "rad"),
    **dict.fromkeys(("v", "v_ref", "v_cmd", "odom_v", "v_star", "u", "w"), "m/s"),
    **dict.fromkeys(("slip_r", "slip_l", "slip_lateral"), "m/s"),
    **dict.fromkeys(("omega", "omega_ref", "omega_cmd", "odom_omega", "omega_star", "r"), "rad/s"),
    **dict.fromkeys(("wheel_speed_r", "wheel_speed_l", "phidot_r", "phidot_l"), "rad/s"),
    **dict.fromkeys(("tau_r", "tau_l"), "N m"),
    **dict.fromkeys(("i_r", "i_l"), "A"),
    **dict.fromkeys(("u_r", "u_l"), "V"),
    **dict.fromkeys(("force_rx", "force_lx", "force_y", "normal_r", "normal_l"), "N"),
    "kx": "1/s",
    "ky": "1/m^2",
    "ktheta": "1/m",
    "m_hat": "kg",
    "inertia_hat": "kg m^2",
    **dict.fromkeys(("saturated", "gate", "rotating", "mu_required", "mu_used", "sliding", "emulator_loss"), "1"),
    "sensing_clock": "1",
}


@dataclass(frozen=True)
class Export:
    """What ``export_run`` wrote: the file, and the number of messages per topic (empty for CSV)."""

    path: Path
    rows: int
    counts: Mapping[str, int]


def export_run(
    folder: Path,
    to: Path,
    *,
    start: float | Decimal | None = None,
    twist_stamped: bool = False,
    odom_frame: str = WORLD_FRAME,
    base_frame: str = BODY_FRAME,
    overwrite: bool = False,
) -> Export:
    """Write the run folder ``folder`` to ``to``: ``.mcap`` (one MCAP file, a rosbag2 storage file), ``.csv``
    (the time series, units in the header), or a path without suffix (a rosbag2 folder: ``metadata.yaml`` and
    its MCAP file, what ``ros2 bag record`` writes).

    ``start`` [s since the epoch] stamps t = 0, read to the nanosecond when given as a :class:`~decimal.Decimal` (a
    float holds about 0.2 µs at today's epoch times); by default the time the run folder was written. The file
    appears whole or not at all; an existing ``to`` is replaced only with ``overwrite`` (and a folder only when
    it is a rosbag2 folder). ``odom_frame`` and ``base_frame`` name the world and the body frames.
    """
    from ..animation import read_run

    for option, frame in (("--odom-frame", odom_frame), ("--base-frame", base_frame)):
        check_frame(option, frame)
    if odom_frame == base_frame:
        raise ConfigError("--base-frame", f"the body and the world are both '{odom_frame}'", "give two names")

    columns, scenario = read_run(folder)
    kind = to.suffix.lower()
    if kind not in (".mcap", ".csv", ""):
        raise ConfigError("--to", f"'{to}' has the suffix '{to.suffix}'", "give FILE.mcap, FILE.csv or a folder name")
    check_target(to, overwrite=overwrite)
    if kind == ".csv":
        atomic_write(to, lambda file: write_csv(columns, file))
        return Export(to, len(columns["t"]), {})
    origin = _origin_nanoseconds(folder, start)
    plant = scenario.plant_params()
    wheels = wheel_signals(columns, half_axle=plant.half_axle, wheel_radius=plant.wheel_radius)
    viewer = viewer_of(scenario, columns, Frames(odom_frame, base_frame))
    counts = write_bag(to, bag_messages(columns, wheels, origin, twist_stamped=twist_stamped, viewer=viewer))
    return Export(to, len(columns["t"]), counts)


def check_frame(option: str, frame: str) -> None:
    """Refuse a frame name tf2 would not take: empty, with a leading '/', or with white space."""
    if not frame or frame.startswith("/") or any(c.isspace() for c in frame):
        raise ConfigError(option, f"'{frame}' is not a tf2 frame name", "give a name like base_footprint (no '/')")


@dataclass(frozen=True)
class Frames:
    """The frames of an exported run: the world the run started in, the true body, and the estimate's body."""

    odom: str = WORLD_FRAME
    base: str = BODY_FRAME

    @property
    def estimate(self) -> str:
        return f"{self.base}_estimate"


@dataclass(frozen=True)
class Viewer:
    """What a viewer needs beside the time series: frame names, the robot's URDF and fixed joints, the wheels'
    origins, and the odometry estimate's covariances ((N, 36) each; None without an estimate)."""

    frames: Frames
    urdf: str
    fixed: tuple[Fixed, ...]
    wheels: Mapping[str, tuple[float, float, float]]
    pose_covariance: np.ndarray | None = None
    twist_covariance: np.ndarray | None = None


def viewer_of(scenario: Any, columns: Mapping[str, np.ndarray], frames: Frames) -> Viewer:
    """The :class:`Viewer` of a run: the robot drawn from the true plant's geometry, the caster where the slip
    plants put it, the estimate's covariances from ``[sensing]`` with the controller's nominal R-hat, L-hat."""
    plant = scenario.plant_params()
    robot = scenario.robot.preset_robot()
    caster = scenario.plant.caster_position
    if caster is None and robot is not None:
        caster = robot.caster_position
    name = re.sub(r"\W+", "_", robot.name).strip("_").lower() if robot is not None else "ddtrack_robot"
    geometry = {"wheel_radius": plant.wheel_radius, "half_axle": plant.half_axle}
    estimated = all(f"odom_{name}" in columns for name in ("theta", "v", "omega"))
    propagation = CovariancePropagation.of(scenario) if estimated else None
    covariances = (None, None) if propagation is None else odometry_covariances(columns, propagation)
    return Viewer(
        frames,
        robot_urdf(name, frames.base, caster=caster, **geometry),
        fixed_links(wheel_radius=plant.wheel_radius, caster=caster),
        wheel_offsets(**geometry),
        *covariances,
    )


def check_target(to: Path, *, overwrite: bool, option: str = "--to") -> None:
    """Refuse (ConfigError naming ``option``, before any work) to replace ``to`` without ``overwrite``, or ever to
    replace a folder that is not a rosbag2 folder, or a folder by a file."""
    if not to.exists():
        return
    if not overwrite:
        raise ConfigError(option, f"'{to}' exists", "give a new path, or add --overwrite to replace it")
    if to.is_dir() and (to.suffix or not (to / "metadata.yaml").is_file()):
        raise ConfigError(option, f"'{to}' is a folder that is not a rosbag2 folder", "give another path")


def _origin_nanoseconds(folder: Path, start: float | Decimal | None) -> int:
    """t = 0 in nanoseconds since the epoch: ``start`` (a Decimal exactly, to the nearest nanosecond), else when
    the run folder was written."""
    if isinstance(start, Decimal):
        return int((start * NANOSECONDS).to_integral_value(rounding=ROUND_HALF_EVEN))
    if start is not None:
        return round(start * NANOSECONDS)
    marker = read_marker(folder) or {}
    written = marker.get("written") if isinstance(marker, dict) else None
    if isinstance(written, str):
        try:
            return round(datetime.datetime.strptime(written, MARKER_TIME_FORMAT).timestamp() * NANOSECONDS)
        except ValueError:
            pass  # an older or edited marker: fall back to the time series' own file time
    return (folder / "timeseries.parquet").stat().st_mtime_ns


def write_csv(columns: Mapping[str, np.ndarray], file: IO[bytes]) -> None:
    """The time series as CSV: a header of ``name [unit]`` (just ``name`` when the unit is not known), then one
    row per control period, every value with the 17 significant digits that give its float64 back."""
    names = list(columns)
    head = ",".join(f"{name} [{COLUMN_UNITS[name]}]" if name in COLUMN_UNITS else name for name in names)
    table = np.column_stack([np.asarray(columns[name], dtype=float) for name in names])
    file.write((head + "\n").encode())
    file.write("".join(",".join(map(repr, map(float, row))) + "\n" for row in table).encode())


def wheel_signals(columns: Mapping[str, np.ndarray], *, half_axle: float, wheel_radius: float) -> dict[str, np.ndarray]:
    """Each drive wheel's angle [rad], speed [rad/s] and torque [N m] (NaN: the plant takes no torque).

    Speeds are the plant's own wheel spins where it has them (a slip plant), else those of rolling without slip,
    (v +- L omega) / R; angles are the recorded ones (encoders on), else the speeds integrated (trapezoid)."""
    right, left = wheel_speeds(columns["v"], columns["omega"], wheel_radius=wheel_radius, half_axle=half_axle)
    rolling = {"r": right, "l": left}
    speed = {}
    for side in "rl":
        own = next((columns[name] for name in (f"phidot_{side}", f"wheel_speed_{side}") if name in columns), None)
        speed[side] = rolling[side] if own is None else np.asarray(own, dtype=float)
    t = columns["t"]
    signals = {}
    for side in ("r", "l"):
        angle = columns.get(f"phi_{side}")
        if angle is None:
            steps = np.diff(t) * 0.5 * (speed[side][1:] + speed[side][:-1])
            angle = np.concatenate([[0.0], np.cumsum(steps)])
        signals[f"angle_{side}"] = np.asarray(angle, dtype=float)
        signals[f"speed_{side}"] = speed[side]
        signals[f"torque_{side}"] = np.asarray(columns.get(f"tau_{side}", np.full(t.shape, np.nan)), dtype=float)
    return signals


def bag_messages(
    columns: Mapping[str, np.ndarray],
    wheels: Mapping[str, np.ndarray],
    origin: int,
    *,
    twist_stamped: bool,
    viewer: Viewer | None = None,
) -> Iterator[tuple[str, str, int, Any]]:
    """(topic, type, time [ns], message) of an exported run, in time order; ``viewer`` the frames, URDF and
    covariances (default: frames odom and base_link, a robot drawn from nothing but the wheels' signals)."""
    frames = viewer.frames if viewer is not None else Frames()
    stamps = origin + np.round(np.asarray(columns["t"]) * NANOSECONDS).astype(np.int64)
    path_poses = lambda prefix, frame_stamps: [  # noqa: E731
        message("geometry_msgs/msg/PoseStamped", header=header(int(s), frames.odom), pose=planar_pose(x, y, th))
        for s, x, y, th in zip(
            frame_stamps, columns[f"x{prefix}"], columns[f"y{prefix}"], columns[f"theta{prefix}"], strict=True
        )
    ]
    first, last = int(stamps[0]), int(stamps[-1])
    path_type = "nav_msgs/msg/Path"
    if viewer is not None:
        yield "/robot_description", STRING, first, message(STRING, data=viewer.urdf)
        static = [_transform(first, frames.base, fixed.child, (fixed.x, fixed.y, fixed.z)) for fixed in viewer.fixed]
        yield "/tf_static", TF, first, message(TF, transforms=static)
    yield (
        "/reference_path",
        path_type,
        first,
        message(path_type, header=header(first, frames.odom), poses=path_poses("_ref", stamps)),
    )
    has_torque = not np.all(np.isnan(wheels["torque_r"]))
    estimate = all(f"odom_{name}" in columns for name in ("x", "y", "theta", "v", "omega"))
    for k, s in enumerate(map(int, stamps)):
        yield "/clock", CLOCK, s, message(CLOCK, clock=stamp(s))
        pose = planar_pose(columns["x"][k], columns["y"][k], columns["theta"][k])
        moving = [_transform(s, frames.odom, frames.base, (columns["x"][k], columns["y"][k], 0.0), columns["theta"][k])]
        if estimate:
            where = (columns["odom_x"][k], columns["odom_y"][k], 0.0)
            moving.append(_transform(s, frames.odom, frames.estimate, where, columns["odom_theta"][k]))
        if viewer is not None:  # what robot_state_publisher would send from the joint states
            for side, (link, origin_) in zip("rl", viewer.wheels.items(), strict=True):
                moving.append(_transform(s, frames.base, link, origin_, pitch=wheels[f"angle_{side}"][k]))
        yield "/tf", TF, s, message(TF, transforms=moving)
        yield "/odom", ODOMETRY, s, _odometry(s, pose, columns["v"][k], columns["omega"][k], frames.odom, frames.base)
        if estimate:
            seen = planar_pose(columns["odom_x"][k], columns["odom_y"][k], columns["odom_theta"][k])
            spread = {}
            if viewer is not None and viewer.pose_covariance is not None and viewer.twist_covariance is not None:
                spread = {"pose_covariance": viewer.pose_covariance[k], "twist_covariance": viewer.twist_covariance[k]}
            odometry = _odometry(
                s, seen, columns["odom_v"][k], columns["odom_omega"][k], frames.odom, frames.estimate, **spread
            )
            yield "/odom_estimate", ODOMETRY, s, odometry
        reference = planar_pose(columns["x_ref"][k], columns["y_ref"][k], columns["theta_ref"][k])
        yield (
            "/reference",
            "geometry_msgs/msg/PoseStamped",
            s,
            message("geometry_msgs/msg/PoseStamped", header=header(s, frames.odom), pose=reference),
        )
        if "v_cmd" in columns:  # absent where a torque law logged no velocity command
            command = twist(columns["v_cmd"][k], columns["omega_cmd"][k])
            if twist_stamped:
                yield (
                    "/cmd_vel",
                    "geometry_msgs/msg/TwistStamped",
                    s,
                    message("geometry_msgs/msg/TwistStamped", header=header(s, frames.base), twist=command),
                )
            else:
                yield "/cmd_vel", "geometry_msgs/msg/Twist", s, command
        yield (
            "/joint_states",
            "sensor_msgs/msg/JointState",
            s,
            message(
                "sensor_msgs/msg/JointState",
                header=header(s, frames.base),
                name=list(WHEEL_JOINTS),
                position=np.array([wheels["angle_r"][k], wheels["angle_l"][k]]),
                velocity=np.array([wheels["speed_r"][k], wheels["speed_l"][k]]),
                effort=np.array([wheels["torque_r"][k], wheels["torque_l"][k]]) if has_torque else np.zeros(0),
            ),
        )
    yield "/path", path_type, last, message(path_type, header=header(last, frames.odom), poses=path_poses("", stamps))


TF, ODOMETRY, CLOCK, STRING = (
    "tf2_msgs/msg/TFMessage",
    "nav_msgs/msg/Odometry",
    "rosgraph_msgs/msg/Clock",
    "std_msgs/msg/String",
)
#: the topics published once, that a late subscriber must still get: transient local, as robot_state_publisher and
#: Nav2's map and plan publishers offer them
LATCHED = ("/robot_description", "/tf_static", "/reference_path", "/path")


def _transform(
    nanoseconds: int,
    parent: str,
    child: str,
    where: tuple[float, float, float],
    yaw: float = 0.0,
    *,
    pitch: float = 0.0,
) -> Any:
    """``geometry_msgs/msg/TransformStamped`` of ``child`` in ``parent``: at ``where`` [m], turned by ``yaw`` about
    z or by ``pitch`` about y (a wheel's spin) [rad]."""
    if pitch:
        half = 0.5 * float(pitch)
        rotation = message("geometry_msgs/msg/Quaternion", x=0.0, y=math.sin(half), z=0.0, w=math.cos(half))
    else:
        rotation = yaw_quaternion(yaw)
    x, y, z = map(float, where)
    return message(
        "geometry_msgs/msg/TransformStamped",
        header=header(nanoseconds, parent),
        child_frame_id=child,
        transform=message(
            "geometry_msgs/msg/Transform",
            translation=message("geometry_msgs/msg/Vector3", x=x, y=y, z=z),
            rotation=rotation,
        ),
    )


def _odometry(
    nanoseconds: int,
    pose: Any,
    v: float,
    omega: float,
    world: str,
    body: str,
    *,
    pose_covariance: np.ndarray | None = None,
    twist_covariance: np.ndarray | None = None,
) -> Any:
    """``nav_msgs/msg/Odometry`` of a planar pose in ``world``, its twist in ``body``; covariances default to
    zeros (the true state is known exactly)."""
    return message(
        ODOMETRY,
        header=header(nanoseconds, world),
        child_frame_id=body,
        pose=message(
            "geometry_msgs/msg/PoseWithCovariance",
            pose=pose,
            covariance=no_covariance() if pose_covariance is None else np.asarray(pose_covariance, dtype=float),
        ),
        twist=message(
            "geometry_msgs/msg/TwistWithCovariance",
            twist=twist(v, omega),
            covariance=no_covariance() if twist_covariance is None else np.asarray(twist_covariance, dtype=float),
        ),
    )


def write_bag(to: Path, messages: Iterable[tuple[str, str, int, Any]]) -> dict[str, int]:
    """Write ``messages`` (topic, type, time [ns], message) as a rosbag2 with MCAP storage: one ``.mcap`` file when
    ``to`` has that suffix, else a rosbag2 folder. The bag is written in a hidden sibling folder and then moved into
    place (the MCAP file, or the whole folder): a failure midway leaves nothing behind. Returns the messages per
    topic."""
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
    from rosbags.rosbag2 import StoragePlugin, Writer

    unset = QosTime(0, 0)  # rosbag2's "default" deadline, lifespan and lease
    latched = Qos(
        QosHistory.KEEP_LAST,
        1,
        QosReliability.RELIABLE,
        QosDurability.TRANSIENT_LOCAL,
        unset,
        unset,
        QosLiveliness.AUTOMATIC,
        unset,
        False,
    )

    parent = to.parent if str(to.parent) else Path(".")
    try:
        parent.mkdir(parents=True, exist_ok=True)
        scratch = Path(tempfile.mkdtemp(prefix=f".{to.name}.", dir=parent))
    except OSError as exc:
        raise RunError(f"cannot write '{to}' ({exc.strerror or exc})") from exc
    bag = scratch / (to.stem if to.suffix else to.name)
    store, counts = typestore(), dict[str, int]()
    try:
        with Writer(bag, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
            connections: dict[str, Any] = {}
            for topic, msgtype, nanoseconds, msg in messages:
                if topic not in connections:
                    qos = (latched,) if topic in LATCHED else ()
                    connections[topic] = writer.add_connection(
                        topic, msgtype, typestore=store, offered_qos_profiles=qos
                    )
                writer.write(connections[topic], nanoseconds, store.serialize_cdr(msg, msgtype))
                counts[topic] = counts.get(topic, 0) + 1
        if to.suffix:
            os.replace(bag / f"{bag.name}.mcap", to)
        else:
            if to.exists():  # an earlier export's rosbag2 folder (checked by the caller)
                shutil.rmtree(to)
            os.replace(bag, to)
    except OSError as exc:
        raise RunError(f"cannot write '{to}' ({exc.strerror or exc}); nothing partial was left") from exc
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    return counts
