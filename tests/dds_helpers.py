"""What the DDS tests share: every participant on the loopback only, in a domain of the test process's own; the
ROS 2 types of a plain node standing for a user's."""

from __future__ import annotations

import os
from pathlib import Path

LOOPBACK = (
    '<CycloneDDS><Domain><General><Interfaces><NetworkInterface name="lo"/></Interfaces>'
    "<AllowMulticast>false</AllowMulticast></General>"  # lo has no multicast here: discovery goes to the peer
    '<Discovery><Peers><Peer address="127.0.0.1"/></Peers><ParticipantIndex>auto</ParticipantIndex></Discovery>'
    "</Domain></CycloneDDS>"
)


def loopback_environment(domain: int) -> dict[str, str]:
    """The environment of a process a test starts: the loopback configuration and the DDS ``domain``."""
    return dict(os.environ, CYCLONEDDS_URI=LOOPBACK, ROS_DOMAIN_ID=str(domain))


#: the source text of ros2_types.py, a user's plain node's ROS 2 types: a plain node's script starts with it
ROS2_TYPES = Path(__file__).with_name("ros2_types.py").read_text()
