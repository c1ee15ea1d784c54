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


#: DDS domains of each pytest worker: a block of its own (gw0 20-69, gw1 70-119, ...), so that tests running at once
#: in two workers never hear each other (domains derived from process ids once collided); a worker runs its tests
#: one at a time, and each test file takes its own offsets in the block
DOMAINS_PER_WORKER = 50


def worker_domain(offset: int) -> int:
    """The DDS domain ``offset`` of this pytest worker's block (:data:`DOMAINS_PER_WORKER`); 20 to 219."""
    worker = int(os.environ.get("PYTEST_XDIST_WORKER", "gw0").removeprefix("gw") or 0)
    return 20 + (worker * DOMAINS_PER_WORKER + offset % DOMAINS_PER_WORKER) % 200


def loopback_environment(domain: int) -> dict[str, str]:
    """The environment of a process a test starts: the loopback configuration and the DDS ``domain``."""
    return dict(os.environ, CYCLONEDDS_URI=LOOPBACK, ROS_DOMAIN_ID=str(domain))


#: the source text of ros2_types.py, a user's plain node's ROS 2 types: a plain node's script starts with it
ROS2_TYPES = Path(__file__).with_name("ros2_types.py").read_text()
