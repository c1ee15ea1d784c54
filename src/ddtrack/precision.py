"""ddtrack computes in float64: JAX's ``jax_enable_x64`` switch, set explicitly, and checked where it matters.

JAX computes in float32 unless told otherwise, process-wide. ddtrack's numbers (bit-for-bit determinism, finite
differences checked to 1e-9, errors of micrometres on a TurtleBot) need float64, but switching a process-wide
setting is the caller's decision, so ``import ddtrack`` does not do it. The ``ddtrack`` command does, once;
a script calls :func:`enable_float64` once, first; a Gymnasium environment switches it on when created (its
constructor says so); and every entry point that simulates calls :func:`require_float64`, which says what to do.
"""

from __future__ import annotations

import importlib
from contextlib import AbstractContextManager
from typing import cast

from .errors import RunError


def enable_float64() -> None:
    """Make JAX compute in float64 for the whole process (``jax_enable_x64``).

    Call it once, before any JAX array is made: arrays made earlier stay float32.
    """
    import jax

    jax.config.update("jax_enable_x64", True)


def require_float64() -> None:
    """Raise :class:`~ddtrack.errors.RunError` with the fix when JAX is in float32 (a script that did not call
    :func:`enable_float64`)."""
    import jax

    if not jax.config.read("jax_enable_x64"):
        raise RunError(
            "ddtrack computes in float64, and JAX is in float32: call ddtrack.enable_float64() once at the start "
            "of your script, before any JAX array is made (the ddtrack command does it for you)"
        )


def float64_in_this_thread(enabled: bool) -> AbstractContextManager[object]:
    """JAX's float64 switch for the current thread only, as a context manager: a thread that ddtrack starts takes
    its caller's setting through it, since a caller's ``with jax.enable_x64(True):`` block holds only in the
    caller's thread (``jax.enable_x64``, or ``jax.experimental.enable_x64`` in older JAX)."""
    import jax

    switch = getattr(jax, "enable_x64", None)  # a context manager since JAX 0.8 or so
    if switch is None:  # pragma: no cover - older JAX kept it in jax.experimental
        switch = importlib.import_module("jax.experimental").enable_x64
    return cast(AbstractContextManager[object], switch(enabled))
