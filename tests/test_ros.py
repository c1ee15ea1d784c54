"""ROS 2 bags out and in (docs/ros.md): a run exported as MCAP and read back by rosbags and by mcap's own reader,
references imported from bags, and every bad input refused with one line, exit 2, nothing written."""

from __future__ import annotations

import csv
from collections import Counter
from decimal import Decimal
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pyarrow.parquet as pq
import pytest
from conftest import SCENARIOS
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from rosbags.interfaces import QosDurability
from rosbags.rosbag2 import StoragePlugin, Writer

from ddtrack.ros.messages import NANOSECONDS, header, message, planar_pose, twist, typestore

START = 1_700_000_000.25  # the stamp of t = 0 [s since the epoch]; a quarter second checks the nanoseconds field
PERIODIC = ("/clock", "/tf", "/odom", "/odom_estimate", "/reference", "/cmd_vel", "/joint_states")
ONCE = ("/robot_description", "/tf_static", "/reference_path", "/path")  # transient local


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory) -> Path:
    """A short run of the Burger over cmd_vel with odometry (the plant logs torques; the controller sees odometry)."""
    from ddtrack.cli import main

    folder = tmp_path_factory.mktemp("ros") / "run"
    code = main(
        [
            "run",
            str(SCENARIOS / "burger_cmd_vel_figure8.toml"),
            "--set",
            "simulation.duration=3",
            "--set",
            "simulation.metric_window=[0, 3]",
            "--out",
            str(folder),
        ]
    )
    assert code == 0
    return folder


@pytest.fixture(scope="module")
def columns(run_folder) -> dict[str, np.ndarray]:
    table = pq.read_table(run_folder / "timeseries.parquet")
    return {name: table.column(name).to_numpy() for name in table.column_names}


@pytest.fixture(scope="module")
def bag(run_folder, tmp_path_factory) -> Path:
    from ddtrack.cli import main

    path = tmp_path_factory.mktemp("bag") / "run.mcap"
    assert main(["export", str(run_folder), "--to", str(path), "--start", repr(START)]) == 0
    return path


def read_rows(path: Path) -> np.ndarray:
    """A CSV written by ``ddtrack import``: ``#`` lines, a header, rows; as a structured array by column name."""
    lines = [line for line in path.read_text().splitlines() if not line.startswith("#")]
    return np.genfromtxt(lines, delimiter=",", names=True)


def expected_stamps(columns) -> np.ndarray:
    # the start as given on the command line, exactly: START * 1e9 in floats is 128 ns short
    return int(Decimal(repr(START)) * NANOSECONDS) + np.round(columns["t"] * NANOSECONDS).astype(np.int64)


def test_mcap_own_reader_sees_every_topic_once_per_period_with_frames_and_stamps(bag, columns):
    n = len(columns["t"])
    by_topic: dict[str, list] = {}
    with bag.open("rb") as file:
        for _, channel, raw, decoded in make_reader(file, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            by_topic.setdefault(channel.topic, []).append((raw.log_time, decoded))
    assert {topic: len(items) for topic, items in by_topic.items()} == {
        **dict.fromkeys(PERIODIC, n),
        **dict.fromkeys(ONCE, 1),
    }
    stamps = expected_stamps(columns)
    for topic in ("/odom", "/odom_estimate", "/reference", "/joint_states", "/clock"):
        items = by_topic[topic]
        assert [log_time for log_time, _ in items] == stamps.tolist(), topic
        stamped = [m.clock if topic == "/clock" else m.header.stamp for _, m in items]
        assert [s.sec * NANOSECONDS + s.nanosec for s in stamped] == stamps.tolist(), topic
    odom = by_topic["/odom"][-1][1]
    assert (odom.header.frame_id, odom.child_frame_id) == ("odom", "base_link")
    assert odom.pose.pose.position.x == columns["x"][-1] and odom.pose.pose.position.y == columns["y"][-1]
    assert odom.twist.twist.linear.x == columns["v"][-1] and odom.twist.twist.angular.z == columns["omega"][-1]
    estimate = by_topic["/odom_estimate"][-1][1]
    assert estimate.pose.pose.position.x == columns["odom_x"][-1]
    transform = by_topic["/tf"][7][1].transforms[0]
    assert (transform.header.frame_id, transform.child_frame_id) == ("odom", "base_link")
    half = columns["theta"][7] / 2
    assert transform.transform.rotation.z == pytest.approx(np.sin(half), abs=1e-15)
    assert transform.transform.rotation.w == pytest.approx(np.cos(half), abs=1e-15)
    joints = by_topic["/joint_states"][5][1]
    assert list(joints.name) == ["wheel_right_joint", "wheel_left_joint"]
    assert list(joints.effort) == [columns["tau_r"][5], columns["tau_l"][5]]
    assert list(joints.position) == [columns["phi_r"][5], columns["phi_l"][5]]  # the encoders' wheel angles
    command = by_topic["/cmd_vel"][3][1]
    assert (command.linear.x, command.angular.z) == (columns["v_cmd"][3], columns["omega_cmd"][3])
    with bag.open("rb") as file:
        summary = make_reader(file).get_summary()
    assert summary is not None and summary.statistics.message_count == len(PERIODIC) * n + len(ONCE)
    assert {s.name for s in summary.schemas.values()} >= {"nav_msgs/msg/Odometry", "tf2_msgs/msg/TFMessage"}


def test_rosbags_reads_the_same_bag_and_its_rosbag2_metadata(bag, columns):
    with AnyReader([bag], default_typestore=typestore()) as reader:
        counts = Counter(c.topic for c in reader.connections for _ in range(c.msgcount))
        assert counts["/tf"] == len(columns["t"]) and counts["/path"] == 1
        assert reader.start_time == int(Decimal(repr(START)) * NANOSECONDS)
        paths = [
            reader.deserialize(raw, c.msgtype)
            for c, _, raw in reader.messages(connections=[c for c in reader.connections if c.topic == "/path"])
        ]
    driven = paths[0].poses
    assert len(driven) == len(columns["t"])
    assert [p.pose.position.x for p in driven] == columns["x"].tolist()


def test_a_viewer_gets_the_robot_its_frames_and_the_one_shot_topics_latched(run_folder, columns, tmp_path, cli):
    folder = tmp_path / "viewer"
    code, _, err = cli(
        "export", run_folder, "--to", folder, "--odom-frame", "world", "--base-frame", "base_footprint", "--start", "1"
    )
    assert code == 0, err
    with AnyReader([folder], default_typestore=typestore()) as reader:
        durability = {c.topic: [q.durability for q in c.ext.offered_qos_profiles] for c in reader.connections}
        by_topic: dict[str, list] = {}
        for c, _, raw in reader.messages():
            by_topic.setdefault(c.topic, []).append(reader.deserialize(raw, c.msgtype))
    assert all(durability[topic] == [QosDurability.TRANSIENT_LOCAL] for topic in ONCE)
    assert all(durability[topic] == [] for topic in PERIODIC)  # the recorder's defaults: volatile
    robot = ElementTree.fromstring(by_topic["/robot_description"][0].data)
    links = {link.get("name") for link in robot.iter("link")}
    joints = {joint.get("name"): joint for joint in robot.iter("joint")}
    assert robot.get("name") == "turtlebot3_burger" and "base_footprint" in links
    wheel = joints["wheel_left_joint"]
    assert wheel.get("type") == "continuous" and wheel.find("parent").get("link") == "base_footprint"
    assert [float(x) for x in wheel.find("origin").get("xyz").split()] == [0.0, 0.08, 0.033]  # L and R of the Burger
    static = by_topic["/tf_static"][0].transforms
    assert {t.child_frame_id for t in static} == {"chassis_link", "caster_link"} <= links
    assert all(t.header.frame_id == "base_footprint" for t in static)
    k = 9
    moving = {t.child_frame_id: t for t in by_topic["/tf"][k].transforms}
    assert set(moving) == {"base_footprint", "base_footprint_estimate", "wheel_right_link", "wheel_left_link"}
    assert moving["base_footprint_estimate"].header.frame_id == "world"
    assert moving["base_footprint_estimate"].transform.translation.x == columns["odom_x"][k]
    spin = moving["wheel_right_link"].transform.rotation  # a turn of phi_r about the axle (body y)
    assert (spin.y, spin.w) == pytest.approx((np.sin(columns["phi_r"][k] / 2), np.cos(columns["phi_r"][k] / 2)))
    estimate, truth = by_topic["/odom_estimate"][k], by_topic["/odom"][k]
    assert (estimate.header.frame_id, estimate.child_frame_id) == ("world", "base_footprint_estimate")
    assert (truth.header.frame_id, truth.child_frame_id) == ("world", "base_footprint")
    assert not truth.pose.covariance.any() and not truth.twist.covariance.any()  # the true state is exact


def test_the_estimates_covariances_are_the_encoders_and_the_gyros_errors_carried_along_the_run(bag, columns):
    """The Burger's odometry drives by its encoders and turns by its gyro (the preset's use_imu)."""
    from ddtrack.robots import OPENCR_MPU9250

    with AnyReader([bag], default_typestore=typestore()) as reader:
        topic = [c for c in reader.connections if c.topic == "/odom_estimate"]
        estimates = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(connections=topic)]
    pose = np.array([m.pose.covariance for m in estimates]).reshape(-1, 6, 6)
    twist_ = np.array([m.twist.covariance for m in estimates]).reshape(-1, 6, 6)
    count, period = 2 * np.pi / 4096, 0.05  # the Burger's XL430 count [rad], its control period [s]
    radius = 0.03333  # the odometry's nominal R-hat (the scenario's worn tyre), the one its estimate uses
    speed = radius * count / np.sqrt(12) / period  # std of R-hat (e0 - e1 + e0' - e1') / 2 / T_c
    density = OPENCR_MPU9250.noise_density
    assert np.sqrt(twist_[:, 0, 0]) == pytest.approx(np.full(len(columns["t"]), speed), rel=1e-12)
    assert np.sqrt(twist_[:, 5, 5]) == pytest.approx(np.full(len(columns["t"]), density / np.sqrt(period)), rel=1e-12)
    # the heading's error is the gyro's random walk, N^2 T_c per period, whatever the encoders read
    periods = np.arange(len(columns["t"]))
    assert pose[:, 5, 5] == pytest.approx(density**2 * period * periods, rel=1e-9, abs=1e-30)
    assert not pose[0].any() and np.all(np.diff(pose[1:, 0, 0] + pose[1:, 1, 1]) >= -1e-20)  # position drifts
    assert np.allclose(pose, np.swapaxes(pose, 1, 2)) and np.all(np.linalg.eigvalsh(pose[-1]) >= -1e-20)


def test_a_rosbag2_folder_holds_metadata_and_its_mcap(run_folder, tmp_path, cli):
    folder = tmp_path / "bag"
    code, out, _ = cli("export", run_folder, "--to", folder, "--start", "1700000000", "--twist-stamped")
    assert code == 0 and "/cmd_vel" in out
    assert sorted(p.name for p in folder.iterdir()) == ["bag.mcap", "metadata.yaml"]
    with AnyReader([folder], default_typestore=typestore()) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
    assert types["/cmd_vel"] == "geometry_msgs/msg/TwistStamped"


def test_start_is_read_to_the_nanosecond(run_folder, tmp_path, cli):
    """``--start 1700000000.123456789`` stamps t = 0 at exactly that nanosecond (as a float it was ...123456768), in
    the header and the bag's log time alike; a start that is not a time is refused, naming the option."""
    path = tmp_path / "exact.mcap"
    assert cli("export", run_folder, "--to", path, "--start", "1700000000.123456789")[0] == 0
    with path.open("rb") as file:
        _, _, raw, decoded = next(
            m
            for m in make_reader(file, decoder_factories=[DecoderFactory()]).iter_decoded_messages()
            if m[1].topic == "/odom"
        )
    assert raw.log_time == 1_700_000_000_123_456_789
    assert (decoded.header.stamp.sec, decoded.header.stamp.nanosec) == (1_700_000_000, 123_456_789)
    for bad in ("soon", "-5", "nan", "inf"):
        code, _, err = cli("export", run_folder, "--to", tmp_path / "bad.mcap", "--start", bad)
        assert code == 2 and err.startswith("error: --start") and not (tmp_path / "bad.mcap").exists()


def test_export_then_import_gives_back_the_reference_and_the_path(bag, columns, tmp_path, cli):
    reference, driven = tmp_path / "reference.csv", tmp_path / "driven.csv"
    assert cli("import", bag, "--path-topic", "/reference_path", "--out", reference)[0] == 0
    code, out, _ = cli("import", bag, "--odom-topic", "/odom", "--out", driven)
    assert code == 0 and 'file = "driven.csv"' in out
    ref = read_rows(reference)
    assert ref.dtype.names == ("t", "x", "y", "yaw")
    np.testing.assert_allclose(ref["x"], columns["x_ref"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(ref["y"], columns["y_ref"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(ref["t"], columns["t"], rtol=0, atol=1e-9)
    drove = read_rows(driven)
    assert drove.dtype.names == ("t", "x", "y", "yaw", "v")
    np.testing.assert_allclose(drove["x"], columns["x"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(drove["y"], columns["y"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(drove["v"], columns["v"], rtol=0, atol=0)
    wrapped = np.angle(np.exp(1j * (drove["yaw"] - columns["theta"])))
    assert np.max(np.abs(wrapped)) < 1e-12


def test_csv_export_names_units_and_gives_every_float_back(run_folder, columns, tmp_path, cli):
    out = tmp_path / "run.csv"
    assert cli("export", run_folder, "--to", out)[0] == 0
    with out.open() as file:
        rows = list(csv.reader(file))
    head = rows[0]
    assert head[:6] == ["t [s]", "x [m]", "y [m]", "theta [rad]", "v [m/s]", "omega [rad/s]"]
    assert "tau_r [N m]" in head and "odom_ex [m]" in head and "i_r [A]" in head
    assert all(" [" in name for name in head), [name for name in head if " [" not in name]  # every column has a unit
    values = np.array(rows[1:], dtype=float)
    assert values.shape == (len(columns["t"]), len(columns))
    np.testing.assert_array_equal(values, np.column_stack(list(columns.values())))


def write_bag(path: Path, topic: str, msgtype: str, items: list[tuple[int, object]]) -> None:
    """A one-topic bag of (receive time [ns], message)."""
    with Writer(path, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        connection = writer.add_connection(topic, msgtype, typestore=typestore())
        for nanoseconds, msg in items:
            writer.write(connection, nanoseconds, typestore().serialize_cdr(msg, msgtype))


def plan(points: list[tuple[float, float]], stamps: list[int]) -> object:
    poses = [
        message("geometry_msgs/msg/PoseStamped", header=header(s, "map"), pose=planar_pose(x, y, 0.0))
        for (x, y), s in zip(points, stamps, strict=True)
    ]
    return message("nav_msgs/msg/Path", header=header(stamps[0], "map"), poses=poses)


def test_an_unstamped_plan_needs_a_speed_and_then_loses_its_repeated_points(tmp_path, cli):
    points = [(0.0, 0.0), (1.0, 0.0), (1.0, 0.0), (1.0, 0.0), (2.0, 1.0)]
    path = tmp_path / "plan"
    write_bag(path, "/plan", "nav_msgs/msg/Path", [(5, plan(points, [0] * 5))])
    out = tmp_path / "plan.csv"
    code, _, err = cli("import", path, "--path-topic", "/plan", "--out", out)
    assert code == 2 and "--speed" in err and not out.exists()
    code, stdout, err = cli("import", path, "--path-topic", "/plan", "--speed", "0.3", "--out", out)
    assert code == 0 and "speed = 0.3" in stdout and "dropped 2 repeated points (rows 2, 3)" in err
    rows = read_rows(out)
    assert rows.dtype.names == ("x", "y") and rows["x"].tolist() == [0.0, 1.0, 2.0]


def test_a_stamped_plan_keeps_its_stops_and_drops_exact_repeats(tmp_path, cli):
    second = NANOSECONDS
    points = [(0.0, 0.0), (1.0, 0.0), (1.0, 0.0), (1.0, 0.0), (2.0, 0.0)]
    stamps = [10 * second, 12 * second, 12 * second, 15 * second, 17 * second]  # a repeat, then a 3 s stop
    path = tmp_path / "plan"
    write_bag(path, "/plan", "nav_msgs/msg/Path", [(5, plan(points, stamps))])
    out = tmp_path / "plan.csv"
    code, _, err = cli("import", path, "--path-topic", "/plan", "--out", out)
    assert code == 0 and "dropped 1 repeat (rows 2)" in err
    rows = read_rows(out)
    assert rows["t"].tolist() == [0.0, 2.0, 5.0, 7.0] and rows["x"].tolist() == [0.0, 1.0, 1.0, 2.0]


def odometry(nanoseconds: int, x: float) -> object:
    return message(
        "nav_msgs/msg/Odometry",
        header=header(nanoseconds, "odom"),
        child_frame_id="base_link",
        pose=message("geometry_msgs/msg/PoseWithCovariance", pose=planar_pose(x, 0.0, 0.0), covariance=np.zeros(36)),
        twist=message("geometry_msgs/msg/TwistWithCovariance", twist=twist(0.1, 0.0), covariance=np.zeros(36)),
    )


@pytest.mark.parametrize(
    ("stamps", "problem"),
    [([0, 2, 1], "'/odom' message 2 (stamp 1.000000001 s) goes back in time"), ([0, 1, 1], "repeats the stamp")],
)
def test_odometry_whose_stamps_go_back_or_repeat_is_refused_naming_the_message(tmp_path, cli, stamps, problem):
    path = tmp_path / "odom"
    # received in order, 1 s apart, but stamped out of order: the header stamps time the trajectory
    items = [
        ((k + 1) * NANOSECONDS, odometry(s * NANOSECONDS + 1, x))
        for k, (s, x) in enumerate(zip(stamps, (0.0, 0.1, 0.2), strict=True))
    ]
    write_bag(path, "/odom", "nav_msgs/msg/Odometry", items)
    out = tmp_path / "odom.csv"
    code, _, err = cli("import", path, "--odom-topic", "/odom", "--out", out)
    assert code == 2 and problem in err and not out.exists()
    assert "Traceback" not in err and len(err.strip().splitlines()) == 2


def test_bad_bags_and_options_are_refused_with_one_line_and_nothing_written(bag, run_folder, tmp_path, cli):
    out = tmp_path / "x.csv"
    cases = [
        (("import", bag, "--path-topic", "/reference_pth", "--out", out), "did you mean '/reference_path'?"),
        (
            ("import", bag, "--path-topic", "/odom", "--out", out),
            "carries nav_msgs/msg/Odometry, not nav_msgs/msg/Path",
        ),
        (("import", tmp_path / "missing.mcap", "--odom-topic", "/odom", "--out", out), "does not exist"),
        (("import", bag, "--out", out), "exactly one of --path-topic and --odom-topic"),
        (("import", bag, "--odom-topic", "/odom", "--speed", "1", "--out", out), "timed by its stamps"),
        (("import", bag, "--odom-topic", "/odom", "--out", tmp_path / "x.txt"), "is not a .csv file"),
        (("export", run_folder, "--to", tmp_path / "x.bag"), "give FILE.mcap, FILE.csv or a folder name"),
        (("export", tmp_path, "--to", tmp_path / "y.mcap"), "is not a run folder"),
        (("export", run_folder, "--to", tmp_path / "y.mcap", "--base-frame", "/base"), "is not a tf2 frame name"),
        (("export", run_folder, "--to", tmp_path / "y.mcap", "--odom-frame", "base_link"), "give two names"),
    ]
    truncated = tmp_path / "truncated.mcap"
    truncated.write_bytes(bag.read_bytes()[: bag.stat().st_size // 2])
    cases.append((("import", truncated, "--odom-topic", "/odom", "--out", out), "cannot be read as a ROS 2 bag"))
    for args, expected in cases:
        code, _, err = cli(*args)
        assert code == 2 and expected in err, (args, err)
        assert "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["truncated.mcap"]


def test_existing_outputs_are_replaced_only_with_overwrite(bag, run_folder, tmp_path, cli):
    target, csv_out = tmp_path / "run.mcap", tmp_path / "odom.csv"
    target.write_bytes(b"keep")
    csv_out.write_text("keep")
    assert cli("export", run_folder, "--to", target)[0] == 2 and target.read_bytes() == b"keep"
    assert cli("import", bag, "--odom-topic", "/odom", "--out", csv_out)[0] == 2 and csv_out.read_text() == "keep"
    assert cli("export", run_folder, "--to", target, "--overwrite")[0] == 0 and target.read_bytes()[:5] == b"\x89MCAP"
    assert cli("import", bag, "--odom-topic", "/odom", "--out", csv_out, "--overwrite")[0] == 0
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no scratch left behind
