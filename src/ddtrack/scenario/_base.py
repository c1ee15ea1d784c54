"""What every section shares: the pydantic base that forbids unknown keys and non-finite numbers, the
numeric types with their bounds, the input limits, and the error a validator raises about one field.
"""

from __future__ import annotations

import errno
from pathlib import Path
from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field

Positive = Annotated[float, Field(gt=0.0)]
NonNegative = Annotated[float, Field(ge=0.0)]
Pair = tuple[float, float]
MAX_COORDINATE = 1e6  # [m]: 1000 km; far larger positions and lengths break the plots (ticks of 1e308 m)
Coordinate = Annotated[float, Field(ge=-MAX_COORDINATE, le=MAX_COORDINATE)]
Position = tuple[Coordinate, Coordinate]
Length = Annotated[float, Field(gt=0.0, le=MAX_COORDINATE)]


class FieldError(ValueError):
    """A validator's error about one field of its section (so the message names ``section.field``)."""

    def __init__(self, field: str, message: str, hint: str = "") -> None:
        super().__init__(message)
        self.field, self.hint = field, hint


MAX_CONTROL_PERIODS = 2_000_000  # about 0.5 GB of recorded series; longer runs belong in chunks
MAX_SEED = 2**63 - 1  # jax.random.PRNGKey takes an int64
MAX_INPUT_BYTES = 64 * 2**20  # a scenario, sweep or waypoints file larger than this is a mistake


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True, strict=False)


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
