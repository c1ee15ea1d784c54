"""ROS 2 live, with no ROS installation: topics published and subscribed over DDS as ROS 2 nodes do (docs/ros.md).

The transport is Cyclone DDS (the optional ``cyclonedds`` package: ``pip install 'ddtrack[ros]'``) with ROS 2's
conventions: a topic ``/cmd_vel`` is the DDS topic ``rt/cmd_vel``, a message type is named as ROS 2's middlewares
name it (``ddtrack.ros.wire``), payloads are plain CDR (XCDR1), the QoS profiles are rclcpp's, and the domain is
``ROS_DOMAIN_ID``'s. Messages are the ``rosbags`` instances ``ddtrack.ros.messages`` builds, as for a bag::

    with Participant() as node:
        commands = node.publisher("/cmd_vel", "geometry_msgs/msg/Twist")
        odometry = node.subscriber("/odom", "nav_msgs/msg/Odometry", qos=SENSOR_DATA_QOS)
        commands.publish(twist(0.2, 0.1))
        for message in odometry.wait(timeout=1.0):
            ...
"""

from __future__ import annotations

import os
import re
import time
from dataclasses import dataclass
from types import TracebackType
from typing import Any

from ..errors import ConfigError, RunError
from .wire import from_idl, idl_type, require_cyclonedds, to_idl

#: the highest domain id whose ports the RTPS port mapping can give (7400 + 250 d + offsets stays under 65536)
MAX_DOMAIN = 232
#: a ROS 2 topic name: tokens of letters, digits and underscores, not starting with a digit, split by '/'
_TOPIC = re.compile(r"/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*")


@dataclass(frozen=True)
class QosProfile:
    """The QoS a ROS 2 publisher offers or a subscription requests; a pair matches when both are met.

    Attributes
    ----------
    reliable : bool
        Reliable (resent until acknowledged) or best effort (a lost sample stays lost).
    transient_local : bool
        The publisher keeps its last ``depth`` messages for subscriptions that join later (volatile otherwise).
    depth : int
        Keep last ``depth`` messages in the history.
    """

    reliable: bool
    transient_local: bool
    depth: int

    def __post_init__(self) -> None:
        if not 1 <= self.depth <= 2**31 - 1:  # DDS keeps at least one sample; its depth is an int32
            raise ConfigError("qos.depth", f"{self.depth} is not a history depth", "give a depth of 1 or more")


#: rclcpp's default (``rclcpp::QoS(10)``, ``rmw_qos_profile_default``): reliable, volatile, keep last 10
DEFAULT_QOS = QosProfile(reliable=True, transient_local=False, depth=10)
#: rclcpp's ``SensorDataQoS`` (``rmw_qos_profile_sensor_data``): best effort, volatile, keep last 5
SENSOR_DATA_QOS = QosProfile(reliable=False, transient_local=False, depth=5)
#: ``/tf_static`` as tf2's static broadcaster offers it (and ``/robot_description`` too): reliable, transient local,
#: keep last 1, so a node that starts later still gets the fixed frames
TF_STATIC_QOS = QosProfile(reliable=True, transient_local=True, depth=1)


def dds_topic_name(topic: str) -> str:
    """The DDS topic of a ROS 2 topic: ``/cmd_vel`` -> ``rt/cmd_vel`` (a name without '/' is in the root namespace).

    Parameters
    ----------
    topic : str
        A fully qualified ROS 2 topic name (``/robot1/cmd_vel``), or one relative to the root namespace.

    Returns
    -------
    str
        ``rt`` and the fully qualified name, as rmw_cyclonedds and rmw_fastrtps name the topic on DDS.
    """
    if not _TOPIC.fullmatch(topic) or "__" in topic:
        raise ConfigError("topic", f"'{topic}' is not a ROS 2 topic name", "give a name like /cmd_vel or /robot1/odom")
    return "rt" + (topic if topic.startswith("/") else "/" + topic)


def domain_id(domain: int | None = None) -> int:
    """The DDS domain of a node: ``domain`` when given, else ``ROS_DOMAIN_ID`` as ROS 2 reads it, else 0.

    Parameters
    ----------
    domain : int, optional
        A domain id in 0..232, overriding the environment.

    Returns
    -------
    int
        The domain id.
    """
    source, text = ("domain", str(domain)) if domain is not None else ("ROS_DOMAIN_ID", os.environ.get("ROS_DOMAIN_ID"))
    if text is None or not text.strip():
        return 0
    if not text.strip().isdigit() or int(text) > MAX_DOMAIN:
        hint = f"give an integer in 0..{MAX_DOMAIN} (ROS 2 advises 0..101)"
        raise ConfigError(source, f"'{text}' is not a DDS domain id", hint)
    return int(text)


def _dds_qos(qos: QosProfile, *, reader: bool) -> Any:
    """The Cyclone DDS QoS of a profile: a writer offers plain CDR (XCDR1) only, as ROS 2 writes messages; a reader
    takes XCDR2 as well (it decodes both, and so matches a DDS writer that offers XCDR2 first)."""
    from cyclonedds.qos import Policy, Qos
    from cyclonedds.util import duration

    reliability = Policy.Reliability.Reliable(duration(seconds=1)) if qos.reliable else Policy.Reliability.BestEffort
    durability = Policy.Durability.TransientLocal if qos.transient_local else Policy.Durability.Volatile
    representation = Policy.DataRepresentation(use_cdrv0_representation=True, use_xcdrv2_representation=reader)
    return Qos(reliability, durability, Policy.History.KeepLast(qos.depth), representation)


class Publisher:
    """A ROS 2 publisher on one topic; :meth:`Participant.publisher` makes it.

    Attributes
    ----------
    topic : str
        The ROS 2 topic, e.g. ``/cmd_vel``.
    msgtype : str
        The ROS 2 message type, e.g. ``geometry_msgs/msg/Twist``.
    """

    def __init__(self, participant: Participant, topic: str, msgtype: str, writer: Any) -> None:
        self._participant, self.topic, self.msgtype, self._writer = participant, topic, msgtype, writer

    def publish(self, message: Any) -> None:
        """Send one message (a rosbags instance of ``msgtype``) to every matched subscription."""
        self._participant._check_open()
        given = getattr(message, "__msgtype__", type(message).__name__)
        if given != self.msgtype:
            raise ConfigError("message", f"'{self.topic}' carries {self.msgtype}, not {given}", "publish its type")
        self._writer.write(to_idl(message, self.msgtype))

    def subscriptions(self) -> int:
        """How many subscriptions (in this process or others) are matched now: a volatile message reaches only them."""
        self._participant._check_open()
        return len(self._writer.get_matched_subscriptions())

    def wait_for_subscriptions(self, count: int = 1, timeout: float = 10.0) -> bool:
        """Wait until ``count`` subscriptions are matched, or ``timeout`` seconds; whether they were."""
        deadline = time.monotonic() + timeout
        while self.subscriptions() < count:
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.02)
        return True

    def flush(self, timeout: float = 5.0) -> bool:
        """Wait until every reliable subscription acknowledged what was sent (before a process exits); whether so."""
        from cyclonedds.util import duration

        self._participant._check_open()
        try:
            return bool(self._writer.wait_for_acks(duration(seconds=timeout)))
        except AttributeError:  # cyclonedds 11.0.1 reads a missing constant where its wait ends unacknowledged
            return False


class Subscriber:
    """A ROS 2 subscription to one topic; :meth:`Participant.subscriber` makes it.

    Attributes
    ----------
    topic : str
        The ROS 2 topic, e.g. ``/odom``.
    msgtype : str
        The ROS 2 message type, e.g. ``nav_msgs/msg/Odometry``.
    """

    def __init__(self, participant: Participant, topic: str, msgtype: str, reader: Any, waitset: Any) -> None:
        self._participant, self.topic, self.msgtype = participant, topic, msgtype
        self._reader, self._waitset = reader, waitset

    def take(self) -> list[Any]:
        """The messages received since the last take, oldest first (non-blocking: an empty list when none)."""
        from cyclonedds.internal import InvalidSample

        self._participant._check_open()
        messages = []
        while samples := self._reader.take(N=256):
            messages += [from_idl(s, self.msgtype) for s in samples if not isinstance(s, InvalidSample)]
        return messages

    def wait(self, timeout: float) -> list[Any]:
        """The messages received, waiting up to ``timeout`` seconds for the first (an empty list when none came)."""
        from cyclonedds.util import duration

        deadline = time.monotonic() + timeout
        while not (messages := self.take()):
            left = deadline - time.monotonic()
            if left <= 0:
                break
            self._waitset.wait(duration(seconds=left))  # wakes on new data, or a writer leaving (no message)
        return messages

    def publishers(self) -> int:
        """How many publishers (in this process or others) are matched now."""
        self._participant._check_open()
        return len(self._reader.get_matched_publications())


class Participant:
    """A DDS participant in a ROS 2 domain: the publishers and subscriptions of one node, as a context manager.

    Parameters
    ----------
    domain : int, optional
        The DDS domain; ``ROS_DOMAIN_ID`` (else 0) when not given, as a ROS 2 node reads it.

    Raises
    ------
    ConfigError
        Without ``cyclonedds`` installed (the message gives the install line), or for a bad domain id.
    """

    def __init__(self, domain: int | None = None) -> None:
        self.domain = domain_id(domain)
        require_cyclonedds()
        from cyclonedds.domain import DomainParticipant

        self._participant: Any = DomainParticipant(self.domain)
        self._topics: dict[str, tuple[str, Any]] = {}
        self._entities: list[Any] = []  # writers, readers, conditions, waitsets: deleted last to first on close
        self._closed = False

    def __enter__(self) -> Participant:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None, tb: TracebackType | None) -> None:
        self.close()

    def _check_open(self) -> None:
        if self._closed:
            raise RunError("the DDS participant is closed: publish and take inside its `with` block")

    def _topic(self, topic: str, msgtype: str) -> Any:
        """The participant's DDS topic for a ROS 2 topic, made once (a second type on one topic is refused)."""
        from cyclonedds.topic import Topic

        self._check_open()
        name = dds_topic_name(topic)
        if name in self._topics:
            known, entity = self._topics[name]
            if known != msgtype:
                raise ConfigError("msgtype", f"'{topic}' carries {known} here, not {msgtype}", "one type per topic")
            return entity
        entity = Topic(self._participant, name, idl_type(msgtype))
        self._topics[name] = (msgtype, entity)
        return entity

    def publisher(self, topic: str, msgtype: str, qos: QosProfile = DEFAULT_QOS) -> Publisher:
        """A publisher of ``msgtype`` messages on the ROS 2 ``topic`` (e.g. ``/cmd_vel``), offering ``qos``."""
        from cyclonedds.pub import DataWriter

        writer = DataWriter(self._participant, self._topic(topic, msgtype), qos=_dds_qos(qos, reader=False))
        self._entities.append(writer)
        return Publisher(self, topic, msgtype, writer)

    def subscriber(self, topic: str, msgtype: str, qos: QosProfile = DEFAULT_QOS) -> Subscriber:
        """A subscription to ``msgtype`` messages on the ROS 2 ``topic`` (e.g. ``/odom``), requesting ``qos``."""
        from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState, WaitSet
        from cyclonedds.sub import DataReader

        reader = DataReader(self._participant, self._topic(topic, msgtype), qos=_dds_qos(qos, reader=True))
        condition = ReadCondition(reader, SampleState.Any | ViewState.Any | InstanceState.Any)
        waitset = WaitSet(self._participant)
        waitset.attach(condition)
        self._entities += [reader, condition, waitset]
        return Subscriber(self, topic, msgtype, reader, waitset)

    def close(self) -> None:
        """Leave the domain: delete the readers, writers and topics, then the participant (idempotent)."""
        if self._closed:
            return
        self._closed = True
        entities = self._entities[::-1] + [entity for _, entity in self._topics.values()] + [self._participant]
        for entity in entities:
            entity.__del__()  # cyclonedds deletes an entity when its object dies; here, now and in this order
        self._entities, self._topics = [], {}
