"""Live ROS 2 over DDS (docs/ros.md): the payloads are the bytes a ROS 2 bag stores, ROS 2's names and QoS, and
messages crossing between separate processes, one of them a plain Cyclone DDS node standing for a user's ROS 2 node.

Every DDS participant here, in this process and in those it starts, talks on the loopback only (``LOOPBACK``: the
``lo`` interface, no multicast, the peer 127.0.0.1) and in a domain of this process's own, so that parallel test
processes do not hear each other.
"""

from __future__ import annotations

import ast
import dataclasses
import json
import os
import random
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from dds_helpers import LOOPBACK, ROS2_TYPES, worker_domain
from rosbags.interfaces import Nodetype

from ddtrack.errors import ConfigError, RunError
from ddtrack.ros import dds, wire
from ddtrack.ros.messages import header, message, planar_pose, stamp, typestore

DOMAIN = worker_domain(0)  # this worker's block's first: this file's
PROCESS_TIMEOUT = 25  # [s] a node that found no peer gives up after 15 s; this only stops a hung process


@pytest.fixture(autouse=True)
def _loopback(monkeypatch):
    """This process's participants on the loopback, in this worker's domain (read when a domain is created)."""
    monkeypatch.setenv("CYCLONEDDS_URI", LOOPBACK)
    monkeypatch.setenv("ROS_DOMAIN_ID", str(DOMAIN))


def _environment() -> dict[str, str]:
    """The environment of a node this test starts: the loopback configuration and this worker's domain."""
    return dict(os.environ, CYCLONEDDS_URI=LOOPBACK, ROS_DOMAIN_ID=str(DOMAIN))


def _vector(x: float, y: float, z: float):
    return message("geometry_msgs/msg/Vector3", x=x, y=y, z=z)


def _twist(seed: float):
    return message("geometry_msgs/msg/Twist", linear=_vector(seed, -2.5, 0.0625), angular=_vector(-0.125, 3.0, seed))


def _covariance(offset: float) -> np.ndarray:
    return np.arange(36) * 0.5 + offset  # every entry distinct, so a transposed or shifted layout shows


def _pose_stamped(nanoseconds: int, frame: str, x: float):
    return message("geometry_msgs/msg/PoseStamped", header=header(nanoseconds, frame), pose=planar_pose(x, -x, 0.3))


def _transform(nanoseconds: int, parent: str, child: str, x: float):
    translation = message("geometry_msgs/msg/Vector3", x=x, y=0.25, z=-0.5)
    rotation = planar_pose(0.0, 0.0, x).orientation
    transform = message("geometry_msgs/msg/Transform", translation=translation, rotation=rotation)
    stamped = header(nanoseconds, parent)
    return message("geometry_msgs/msg/TransformStamped", header=stamped, child_frame_id=child, transform=transform)


T = 1_700_000_000_123_456_789  # [ns] a stamp with every digit of its nanoseconds used
#: each required type with values that exercise the layout: strings of odd lengths (1, 3, 9, 14 characters, so
#: the next field needs padding), sequences of several elements, covariances of 36 distinct values
MESSAGES = {
    "geometry_msgs/msg/Twist": _twist(1.25),
    "geometry_msgs/msg/TwistStamped": message(
        "geometry_msgs/msg/TwistStamped", header=header(T, "base_link"), twist=_twist(-0.75)
    ),
    "nav_msgs/msg/Odometry": message(
        "nav_msgs/msg/Odometry",
        header=header(T, "odo"),
        child_frame_id="base_footprint",
        pose=message(
            "geometry_msgs/msg/PoseWithCovariance", pose=planar_pose(1.5, -2.25, 0.75), covariance=_covariance(0.25)
        ),
        twist=message("geometry_msgs/msg/TwistWithCovariance", twist=_twist(0.5), covariance=_covariance(-7.0)),
    ),
    "nav_msgs/msg/Path": message(
        "nav_msgs/msg/Path",
        header=header(T, "map"),
        poses=[_pose_stamped(T + i, frame, 0.5 * i) for i, frame in enumerate(["m", "odom_x", "map", "base_link"])],
    ),
    "tf2_msgs/msg/TFMessage": message(
        "tf2_msgs/msg/TFMessage",
        transforms=[
            _transform(T, "odom", "base_link", 0.5),
            _transform(T + 1, "base_link", "wheel_left_link", -0.25),
            _transform(T + 2, "b", "caster", 2.0),
        ],
    ),
    "sensor_msgs/msg/JointState": message(
        "sensor_msgs/msg/JointState",
        header=header(T, "base_link"),
        name=["wheel_right_joint", "wheel_left_joint", "c"],
        position=np.array([0.5, -1.25, 3.0]),
        velocity=np.array([2.0, -2.0, 0.125]),
        effort=np.array([0.0625, 0.03125]),  # ROS allows an effort of its own length (here one short)
    ),
    "rosgraph_msgs/msg/Clock": message("rosgraph_msgs/msg/Clock", clock=stamp(T)),
}


def _same(a, b) -> bool:
    """Whether two rosbags messages are equal field by field (numpy arrays in value and element type)."""
    if dataclasses.is_dataclass(a):
        return type(a) is type(b) and all(_same(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(a))
    if isinstance(a, np.ndarray):
        return isinstance(b, np.ndarray) and a.dtype == b.dtype and np.array_equal(a, b)
    if isinstance(a, list):
        return isinstance(b, list) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    return type(a) is type(b) and a == b


def test_ros_2_names_on_dds():
    assert dds.dds_topic_name("/cmd_vel") == "rt/cmd_vel"
    assert dds.dds_topic_name("odom") == "rt/odom"  # relative to the root namespace
    assert dds.dds_topic_name("/robot1/joint_states") == "rt/robot1/joint_states"
    for bad in ("", "/", "/cmd_vel/", "//odom", "/1robot/odom", "/a b", "~/odom", "/odom__x"):
        with pytest.raises(ConfigError, match="not a ROS 2 topic name"):
            dds.dds_topic_name(bad)
    assert wire.dds_type_name("geometry_msgs/msg/Twist") == "geometry_msgs::msg::dds_::Twist_"
    assert wire.idl_type("nav_msgs/msg/Odometry").__idl_typename__ == "nav_msgs::msg::dds_::Odometry_"
    with pytest.raises(ConfigError, match="did you mean 'geometry_msgs/msg/Twist'"):
        wire.idl_type("geometry_msgs/msg/Twst")


def test_qos_profiles_are_rclcpp_s():
    assert dds.DEFAULT_QOS == dds.QosProfile(reliable=True, transient_local=False, depth=10)
    assert dds.SENSOR_DATA_QOS == dds.QosProfile(reliable=False, transient_local=False, depth=5)
    assert dds.TF_STATIC_QOS == dds.QosProfile(reliable=True, transient_local=True, depth=1)
    with pytest.raises(ConfigError, match="qos.depth: 0 is not a history depth"):
        dds.QosProfile(reliable=True, transient_local=False, depth=0)
    from cyclonedds.qos import Policy

    writer = dds._dds_qos(dds.TF_STATIC_QOS, reader=False)
    assert isinstance(writer[Policy.Reliability], Policy.Reliability.Reliable)
    assert writer[Policy.Durability] == Policy.Durability.TransientLocal
    assert writer[Policy.History] == Policy.History.KeepLast(1)
    assert writer[Policy.DataRepresentation] == Policy.DataRepresentation(use_cdrv0_representation=True)
    reader = dds._dds_qos(dds.SENSOR_DATA_QOS, reader=True)
    assert reader[Policy.Reliability] == Policy.Reliability.BestEffort
    assert reader[Policy.Durability] == Policy.Durability.Volatile
    assert reader[Policy.History] == Policy.History.KeepLast(5)


def test_the_domain_is_ros_domain_id_s(monkeypatch):
    assert dds.domain_id() == DOMAIN
    assert dds.domain_id(7) == 7  # the argument wins
    monkeypatch.delenv("ROS_DOMAIN_ID")
    assert dds.domain_id() == 0
    monkeypatch.setenv("ROS_DOMAIN_ID", "x1")
    with pytest.raises(ConfigError, match="ROS_DOMAIN_ID: 'x1' is not a DDS domain id"):
        dds.domain_id()
    with pytest.raises(ConfigError, match="domain: '233'"):
        dds.domain_id(233)


@pytest.mark.parametrize("msgtype", sorted(MESSAGES))
def test_payloads_are_the_bytes_a_bag_stores(msgtype):
    """Cyclone DDS's serialization of the generated type is rosbags' CDR, header included; and reads back."""
    original = MESSAGES[msgtype]
    expected = bytes(typestore().serialize_cdr(original, msgtype))
    assert expected[:4] == b"\x00\x01\x00\x00"  # CDR_LE: plain CDR (XCDR1), little-endian
    assert wire.serialize(original) == expected
    assert _same(wire.deserialize(expected, msgtype), original)
    assert _same(wire.from_idl(wire.to_idl(original), msgtype), original)


_INTEGERS = {"byte": 8, "char": -8, "int8": 8, "int16": 16, "int32": 32, "int64": 64}


def _value(desc, rng: random.Random):
    """A random value of one field description of rosbags' type store (sequences of 1 to 3 elements)."""
    node, info = desc
    if node == Nodetype.NAME:
        return _random_message(info, rng)
    if node == Nodetype.BASE:
        name, bound = info
        if name == "string":
            return "".join(rng.choice("abxyz_09") for _ in range(rng.randint(0, bound or 9)))
        if name == "bool":
            return rng.random() < 0.5
        if name.startswith("float"):
            return float(np.float32(rng.uniform(-9, 9))) if name == "float32" else rng.uniform(-1e6, 1e6)
        bits = _INTEGERS.get(name) or -int(name.removeprefix("uint"))  # negative: unsigned
        return rng.randrange(2 ** (-bits)) if bits < 0 else rng.randrange(-(2 ** (bits - 1)), 2 ** (bits - 1))
    element, length = info
    count = length if node == Nodetype.ARRAY else rng.randint(1, length or 3)
    items = [_value(element, rng) for _ in range(count)]
    if element[0] == Nodetype.BASE and element[1][0] != "string":
        return np.array(items, dtype=wire._DTYPES[element[1][0]])
    return items


def _random_message(msgtype: str, rng: random.Random):
    fields = typestore().fielddefs[msgtype][1]
    return typestore().types[msgtype](**{name: _value(desc, rng) for name, desc in fields})


def test_every_message_of_the_type_store_is_carried_byte_for_byte():
    """Beyond the seven: all of ROS 2 Jazzy's standard messages (bounded strings, byte arrays, nested arrays)."""
    rng = random.Random(38)
    msgtypes = sorted(typestore().fielddefs)
    assert len(msgtypes) > 150
    for msgtype in msgtypes:
        original = _random_message(msgtype, rng)
        expected = bytes(typestore().serialize_cdr(original, msgtype))
        assert wire.serialize(original, msgtype) == expected, msgtype
        assert _same(wire.deserialize(expected, msgtype), original), msgtype


def test_missing_cyclonedds_says_how_to_install_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "cyclonedds", None)  # an import of it now fails, as where it is not installed
    with pytest.raises(ConfigError, match=r"not installed\n  hint: pip install 'ddtrack\[ros\]'"):
        dds.Participant()
    code = (
        "import sys, ddtrack.ros, ddtrack.ros.dds, ddtrack.ros.wire; print([m for m in sys.modules if 'cyclone' in m])"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True)
    assert done.stdout.strip() == "[]"  # importing ddtrack.ros loads no Cyclone DDS


def test_transient_local_reaches_a_late_subscription_and_qos_must_match():
    with dds.Participant() as node:
        static = node.publisher("/tf_static", "tf2_msgs/msg/TFMessage", qos=dds.TF_STATIC_QOS)
        static.publish(MESSAGES["tf2_msgs/msg/TFMessage"])
        late = node.subscriber("/tf_static", "tf2_msgs/msg/TFMessage", qos=dds.TF_STATIC_QOS)
        received = late.wait(timeout=5.0)
        assert len(received) == 1 and _same(received[0], MESSAGES["tf2_msgs/msg/TFMessage"])
        # a best-effort publisher cannot serve a reliable subscription (as in ROS 2); the reverse matches
        sensor = node.publisher("/scan_like", "geometry_msgs/msg/Twist", qos=dds.SENSOR_DATA_QOS)
        reliable = node.subscriber("/scan_like", "geometry_msgs/msg/Twist")
        assert not sensor.wait_for_subscriptions(timeout=0.5) and reliable.publishers() == 0
        best_effort = node.subscriber("/scan_like2", "geometry_msgs/msg/Twist", qos=dds.SENSOR_DATA_QOS)
        assert node.publisher("/scan_like2", "geometry_msgs/msg/Twist").wait_for_subscriptions(timeout=5.0)
        assert best_effort.take() == []
        with pytest.raises(ConfigError, match="carries tf2_msgs/msg/TFMessage here"):
            node.subscriber("/tf_static", "geometry_msgs/msg/Twist")
        with pytest.raises(ConfigError, match="carries tf2_msgs/msg/TFMessage, not rosgraph_msgs/msg/Clock"):
            static.publish(MESSAGES["rosgraph_msgs/msg/Clock"])
    with pytest.raises(RunError, match="closed"):
        static.publish(MESSAGES["tf2_msgs/msg/TFMessage"])


def test_traffic_stays_on_the_loopback(tmp_path, monkeypatch):
    """The configuration the tests give every process selects ``lo`` and nothing else (Cyclone DDS's own trace)."""
    trace = tmp_path / "cyclonedds.log"
    tracing = f"<Tracing><Category>config</Category><OutputFile>{trace}</OutputFile></Tracing>"
    monkeypatch.setenv("CYCLONEDDS_URI", f"{LOOPBACK},<CycloneDDS><Domain>{tracing}</Domain></CycloneDDS>")
    with dds.Participant(domain=worker_domain(13)):  # a domain of its own: its configuration is read anew
        pass
    selected = [line for line in trace.read_text().splitlines() if "selected interfaces:" in line]
    assert len(selected) == 1 and selected[0].split("selected interfaces:")[1].split()[0] == "lo", selected
    assert "AllowMulticast/#text: false" in trace.read_text()


# A user's ROS 2 node, as plain Cyclone DDS: its own types (ros2_types.py), named and laid out as ROS 2's IDL
# defines them, on the DDS topics ROS 2 gives /cmd_vel and /odom. It uses nothing of ddtrack. `listen` prints what
# it received and what it saw of the publishers it matched; `talk` publishes once a subscription is matched and says
# what it matched.
PLAIN_NODE = ROS2_TYPES + textwrap.dedent(
    """
    import dataclasses, json, os, sys, time
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.qos import Policy, Qos
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic
    from cyclonedds.util import duration

    TYPES = {"rt/cmd_vel": Twist, "rt/odom": Odometry}
    QOS = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.Volatile, Policy.History.KeepLast(10))
    mode, values = sys.argv[1], json.loads(sys.argv[2])
    participant = DomainParticipant(int(os.environ["ROS_DOMAIN_ID"]))
    topics = {name: Topic(participant, name, kind) for name, kind in TYPES.items()}
    deadline = time.monotonic() + 15

    def build(kind, value):
        if dataclasses.is_dataclass(kind):
            fields = dataclasses.fields(kind)
            return kind(**{f.name: build(kind.__annotations__[f.name], value[f.name]) for f in fields})
        return value

    def endpoint(data):
        return {"topic": data.topic_name, "type": data.type_name, "qos": sorted(str(p) for p in data.qos)}

    if mode == "listen":
        readers = {name: DataReader(participant, topic, qos=QOS) for name, topic in topics.items()}
        got, seen = {name: [] for name in readers}, {}
        while any(len(samples) < 3 for samples in got.values()) and time.monotonic() < deadline:
            for name, reader in readers.items():
                got[name] += [dataclasses.asdict(s) for s in reader.take(N=10) if isinstance(s, TYPES[name])]
                matched = [reader.get_matched_publication_data(h) for h in reader.get_matched_publications()]
                seen[name] = [endpoint(m) for m in matched if m] or seen.get(name, [])  # the talker leaves once acked
            time.sleep(0.01)
        time.sleep(0.5)  # stay while the talker's last heartbeats are acknowledged
        print(json.dumps({"received": got, "publishers": seen}))
    else:
        writers = {name: DataWriter(participant, topic, qos=QOS) for name, topic in topics.items()}
        while not all(w.get_matched_subscriptions() for w in writers.values()) and time.monotonic() < deadline:
            time.sleep(0.01)
        seen = {n: [endpoint(w.get_matched_subscription_data(h)) for h in w.get_matched_subscriptions()] for n, w in
                writers.items()}
        for name, writer in writers.items():
            for _ in range(3):
                writer.write(build(TYPES[name], values[name]))
        time.sleep(0.5)  # for the acknowledgements (cyclonedds 11.0.1's wait_for_acks fails on its timeout)
        print(json.dumps({"subscribers": seen}))
    """
)

# The same two topics from ddtrack's side: ddtrack.ros.dds with the messages of ddtrack.ros.messages.
DDTRACK_NODE = textwrap.dedent(
    """
    import dataclasses, json, sys
    import numpy as np
    from ddtrack.ros.dds import Participant
    from ddtrack.ros.messages import typestore

    TYPES = {"/cmd_vel": "geometry_msgs/msg/Twist", "/odom": "nav_msgs/msg/Odometry"}
    mode, values = sys.argv[1], json.loads(sys.argv[2])

    def build(msgtype, value):
        fields = typestore().fielddefs[msgtype][1]
        made = {}
        for name, desc in fields:
            v = value[name]
            made[name] = build(desc[1], v) if desc[0] == 2 else np.array(v) if isinstance(v, list) else v
        return typestore().types[msgtype](**made)

    def plain(message):
        if dataclasses.is_dataclass(message):
            fields = [f.name for f in dataclasses.fields(message) if f.name != "__msgtype__"]
            return {name: plain(getattr(message, name)) for name in fields}
        return message.tolist() if isinstance(message, np.ndarray) else message

    with Participant() as node:
        if mode == "talk":
            publishers = {topic: node.publisher(topic, msgtype) for topic, msgtype in TYPES.items()}
            assert all(p.wait_for_subscriptions(1, timeout=15) for p in publishers.values()), "no subscription matched"
            for topic, publisher in publishers.items():
                for _ in range(3):
                    publisher.publish(build(TYPES[topic], values["rt" + topic]))
                assert publisher.flush(timeout=5)
        else:
            subscribers = {topic: node.subscriber(topic, msgtype) for topic, msgtype in TYPES.items()}
            got = {"rt" + topic: [] for topic in subscribers}
            for topic, subscriber in subscribers.items():
                while len(got["rt" + topic]) < 3 and (received := subscriber.wait(timeout=15)):
                    got["rt" + topic] += [plain(message) for message in received]
            print(json.dumps({"received": got}))
    """
)

DDS_TYPES = {"rt/cmd_vel": "geometry_msgs::msg::dds_::Twist_", "rt/odom": "nav_msgs::msg::dds_::Odometry_"}
#: what crosses, by DDS topic: a command and an odometry message with odd-length frames and distinct covariances
VALUES = {
    "rt/cmd_vel": {"linear": {"x": 0.5, "y": -0.125, "z": 0.0625}, "angular": {"x": 0.03125, "y": 0.0, "z": -0.75}},
    "rt/odom": {
        "header": {"stamp": {"sec": 1_700_000_000, "nanosec": 123_456_789}, "frame_id": "odom"},
        "child_frame_id": "base_footprint",
        "pose": {
            "pose": {
                "position": {"x": 1.5, "y": -2.25, "z": 0.0},
                "orientation": {"x": 0.0, "y": 0.0, "z": 0.3826834323650898, "w": 0.9238795325112867},
            },
            "covariance": _covariance(0.25).tolist(),
        },
        "twist": {
            "twist": {"linear": {"x": 0.2, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": -0.4}},
            "covariance": _covariance(-7.0).tolist(),
        },
    },
}


def _exchange(listener: str, talker: str) -> tuple[dict, dict]:
    """Run a listening node and a talking node as two processes on the loopback; what each printed last."""
    argv = json.dumps(VALUES)
    command = {"plain": PLAIN_NODE, "ddtrack": DDTRACK_NODE}
    started = [
        subprocess.Popen(
            [sys.executable, "-c", command[kind], mode, argv],
            env=_environment(),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for kind, mode in ((listener, "listen"), (talker, "talk"))
    ]
    try:
        outputs = [process.communicate(timeout=PROCESS_TIMEOUT) for process in started]
    finally:
        for process in started:
            process.kill()
    for process, (_, err) in zip(started, outputs, strict=True):
        assert process.returncode == 0, err[-2000:]
    listened, talked = (json.loads(out.splitlines()[-1]) if out.strip() else {} for out, _ in outputs)
    return listened, talked


def test_the_plain_node_imports_nothing_of_ddtrack():
    """It stands for a user's ROS 2 node: its types (ros2_types.py) and its code import Cyclone DDS, not ddtrack."""
    tree = ast.parse(PLAIN_NODE)
    imported = {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
    imported |= {alias.name for node in ast.walk(tree) if isinstance(node, ast.Import) for alias in node.names}
    assert {name.split(".")[0] for name in imported} == {"cyclonedds", "dataclasses", "json", "os", "sys", "time"}


def test_a_plain_ros_2_node_receives_what_ddtrack_publishes():
    heard, _ = _exchange(listener="plain", talker="ddtrack")
    assert heard["received"] == {topic: [value] * 3 for topic, value in VALUES.items()}  # all three, intact
    for topic, msgtype in DDS_TYPES.items():
        (publisher,) = heard["publishers"][topic]  # ddtrack's writer, as the plain node discovered it
        assert publisher["topic"] == topic and publisher["type"] == msgtype
        qos = " ".join(publisher["qos"])
        assert "Reliable" in qos and "Volatile" in qos and "KeepLast(depth=10)" in qos
        assert "use_cdrv0_representation=True, use_xcdrv2_representation=False" in qos  # XCDR1 only


def test_ddtrack_receives_what_a_plain_ros_2_node_publishes():
    heard, said = _exchange(listener="ddtrack", talker="plain")
    assert heard["received"] == {topic: [value] * 3 for topic, value in VALUES.items()}
    for topic in ("rt/cmd_vel", "rt/odom"):
        (subscription,) = said["subscribers"][topic]  # ddtrack's reader, as the plain node discovered it
        assert subscription["topic"] == topic
