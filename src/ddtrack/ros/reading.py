"""Reading ROS 2 bags (MCAP or SQLite, a rosbag2 folder or a storage file) with errors a user can act on.

Every problem with the user's bag is a :class:`ConfigError` naming the bag and the option, so the command line
prints one line and exits 2 having written nothing: a missing file, a corrupt or truncated one, a topic the bag
does not have (with the topics it has and a "did you mean"), a message type that is not the one asked for.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from ..errors import ConfigError, did_you_mean
from .messages import stamp_nanoseconds


@contextmanager
def open_bag(path: Path) -> Iterator[Any]:
    """An open ``rosbags`` reader of ``path`` (a rosbag2 folder, a ``.mcap`` or a ``.db3`` file)."""
    from rosbags.highlevel import AnyReader, AnyReaderError

    from .messages import typestore

    if not path.exists():
        raise ConfigError("BAG", f"'{path}' does not exist", "give a rosbag2 folder or its .mcap or .db3 file")
    try:
        reader = AnyReader([path], default_typestore=typestore())
        reader.open()
    except (AnyReaderError, OSError, ValueError, KeyError, EOFError) as exc:
        raise ConfigError("BAG", f"'{path}' cannot be read as a ROS 2 bag ({_reason(exc)})", _BAG_HINT) from None
    try:
        yield reader
    finally:
        reader.close()


_BAG_HINT = "give a rosbag2 folder (with metadata.yaml) or its .mcap or .db3 file, whole (not truncated)"


def _reason(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0][:160] if text else type(exc).__name__


def topic_messages(reader: Any, topic: str, msgtypes: tuple[str, ...], *, option: str) -> list[tuple[int, Any]]:
    """Every message on ``topic`` as (bag time [ns], message), in the order stored; ``topic`` must exist and
    carry one of ``msgtypes`` (ConfigError naming ``option`` otherwise)."""
    connections = [c for c in reader.connections if c.topic == topic]
    if not connections:
        have = sorted({c.topic for c in reader.connections})
        listed = ", ".join(f"{c.topic} ({c.msgtype})" for c in sorted(reader.connections, key=lambda c: c.topic))
        raise ConfigError(
            option,
            f"the bag has no topic '{topic}'; it has {listed or 'no topics'}",
            did_you_mean(topic, have) if have else "record the topic first",
        )
    wrong = [c.msgtype for c in connections if c.msgtype not in msgtypes]
    if wrong:
        raise ConfigError(
            option, f"topic '{topic}' carries {wrong[0]}, not {' or '.join(msgtypes)}", "give a topic of that type"
        )
    messages = []
    try:
        for connection, bag_time, raw in reader.messages(connections=connections):
            messages.append((int(bag_time), reader.deserialize(raw, connection.msgtype)))
    except Exception as exc:  # rosbags raises many kinds on a damaged file: each is the bag's fault, not ours
        raise ConfigError(
            "BAG", f"the bag's messages on '{topic}' cannot be read ({_reason(exc)})", _BAG_HINT
        ) from None
    if not messages:
        raise ConfigError(option, f"topic '{topic}' holds no messages", "give a topic that was recorded")
    return messages


def header_or_bag_time(bag_time: int, msg: Any) -> int:
    """A message's header stamp [ns], or its bag receive time where it has no header (a Twist) or left it
    unstamped (0)."""
    stamped = stamp_nanoseconds(msg.header) if hasattr(msg, "header") else 0
    return stamped if stamped > 0 else bag_time
