"""Exceptions. User mistakes are :class:`ConfigError` (exit code 2), never a traceback."""

from __future__ import annotations

import difflib
from collections.abc import Iterable


class DdtrackError(Exception):
    """Base class of every error ddtrack raises on purpose."""


class ConfigError(DdtrackError):
    """A scenario, option or input file is invalid.

    Parameters
    ----------
    field : str
        Dotted path of the offending field, e.g. ``"robot.mass"`` (empty when none applies).
    message : str
        What was expected and what came.
    suggestion : str, optional
        How to fix it, e.g. a "did you mean" hint.
    """

    def __init__(self, field: str, message: str, suggestion: str = "") -> None:
        self.field = field
        self.message = message
        self.suggestion = suggestion
        head = f"{field}: {message}" if field else message
        super().__init__(f"{head}\n  hint: {suggestion}" if suggestion else head)


class RunError(DdtrackError):
    """A run could not be carried out (e.g. an output folder that cannot be written)."""


def did_you_mean(word: str, choices: Iterable[str]) -> str:
    """Return ``"did you mean 'x'?"`` for the closest choice, or a list of valid choices."""
    choices = sorted(choices)
    close = difflib.get_close_matches(word, choices, n=1, cutoff=0.6)
    if close:
        return f"did you mean '{close[0]}'?"
    return "valid: " + ", ".join(repr(c) for c in choices)
