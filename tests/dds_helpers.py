"""What the DDS tests share: every participant on the loopback only, in a domain of the test process's own."""

from __future__ import annotations

import os

LOOPBACK = (
    '<CycloneDDS><Domain><General><Interfaces><NetworkInterface name="lo"/></Interfaces>'
    "<AllowMulticast>false</AllowMulticast></General>"  # lo has no multicast here: discovery goes to the peer
    '<Discovery><Peers><Peer address="127.0.0.1"/></Peers><ParticipantIndex>auto</ParticipantIndex></Discovery>'
    "</Domain></CycloneDDS>"
)


def loopback_environment(domain: int) -> dict[str, str]:
    """The environment of a process a test starts: the loopback configuration and the DDS ``domain``."""
    return dict(os.environ, CYCLONEDDS_URI=LOOPBACK, ROS_DOMAIN_ID=str(domain))
