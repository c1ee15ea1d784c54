"""What every section shares: the pydantic base that forbids unknown keys and non-finite numbers, the
numeric types with their bounds, the input limits, and the error a validator raises about one field.
"""

from __future__ import annotations

import errno
from pathlib import Path

from ..parameters import MAX_COORDINATE, Coordinate, Length, NonNegative, Pair, Parameters, Position, Positive

# re-exported: every section's bounded numeric types
__all__ = ["MAX_COORDINATE", "Coordinate", "Length", "NonNegative", "Pair", "Position", "Positive"]


class FieldError(ValueError):
    """A validator's error about one field of its section (so the message names ``section.field``)."""

    def __init__(self, field: str, message: str, hint: str = "") -> None:
        super().__init__(message)
        self.field, self.hint = field, hint


MAX_CONTROL_PERIODS = 2_000_000  # about 0.5 GB of recorded series; longer runs belong in chunks
MAX_SEED = 2**63 - 1  # jax.random.PRNGKey takes an int64
MAX_INPUT_BYTES = 64 * 2**20  # a scenario, sweep or waypoints file larger than this is a mistake


class _Section(Parameters):
    """The root of every scenario section (unknown keys and non-finite numbers are errors; frozen)."""


def read_input(path: Path) -> bytes:
    """The bytes of a regular file of at most ``MAX_INPUT_BYTES``; :class:`OSError` for anything else (a
    device such as /dev/zero or a pipe would never end, or fill the memory)."""
    if path.exists() and not path.is_file() and not path.is_dir():
        raise OSError(errno.EINVAL, "not a regular file")
    with path.open("rb") as f:
        data = f.read(MAX_INPUT_BYTES + 1)
    if len(data) > MAX_INPUT_BYTES:
        raise OSError(errno.EFBIG, f"larger than {MAX_INPUT_BYTES // 2**20} MiB")
    return data
