"""Compiled programs in a long-lived process: release them before the operating system's limit is reached.

XLA maps the code and data of every program it compiles into the process separately, and JAX keeps every
compiled program for reuse. Linux refuses a process more than ``vm.max_map_count`` mappings (65,530 by default);
at the limit an XLA compile fails to allocate and the process crashes (a segmentation fault, not an exception).
One distinct ddtrack run compiles programs holding about 600 mappings, so a process that runs a few hundred
distinct configurations (a sweep's worker, a test session) reaches it. :func:`release_compilations` empties JAX's
caches once a process holds a given share of its limit: later runs of a released program compile it again.
"""

from __future__ import annotations

import gc
import logging
import os
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

MAP_LIMIT_FILE = "/proc/sys/vm/max_map_count"
OWN_MAPS_FILE = "/proc/self/maps"
LOWERING_LOGGER = "jax._src.interpreters.pxla"  #: where JAX says it lowers a program for compilation
RELEASE_AT = 0.5  #: the share of the mapping limit at which compiled programs are released


def enable_compilation_cache() -> None:
    """Turn on JAX's persistent compilation cache in ``$DDTRACK_CACHE_DIR`` or ``~/.cache/ddtrack/jax``:
    a second process (a CLI run, a sweep worker) then skips most of the compile. Every compiled function
    is kept: the run's small random-number jits would otherwise be compiled again each time (0.4 s)."""
    import jax

    root = (
        os.environ.get("DDTRACK_CACHE_DIR")
        or Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "ddtrack"
    )
    try:
        cache = Path(root) / "jax"
        cache.mkdir(parents=True, exist_ok=True)
    except OSError:
        return  # a read-only home only costs compile time
    jax.config.update("jax_compilation_cache_dir", str(cache))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0)


def padded_length(n: int) -> int:
    """The next power of two at least ``n`` (and at least 1024): work done elementwise over ``n`` items is done over
    this many and cut, so that one compiled program serves inputs of many lengths instead of one program each."""
    return max(1024, 1 << (n - 1).bit_length())


def memory_mappings() -> int | None:
    """How many memory mappings this process holds, or None where the system does not say (not Linux)."""
    try:
        with open(OWN_MAPS_FILE, "rb") as maps:
            return sum(1 for _ in maps)
    except OSError:
        return None


def mapping_limit() -> int | None:
    """The most mappings a process may hold (``vm.max_map_count``), or None where the system does not say."""
    try:
        with open(MAP_LIMIT_FILE) as limit:
            return int(limit.read())
    except (OSError, ValueError):
        return None


def release_compilations(share: float = RELEASE_AT) -> bool:
    """Empty JAX's compilation caches if this process holds more than ``share`` of its mapping limit; return
    whether it did. Cheap when it does nothing (one read of the process's mapping list)."""
    held, limit = memory_mappings(), mapping_limit()
    if held is None or limit is None or held <= share * limit:
        return False
    import jax

    jax.clear_caches()
    gc.collect()  # the executables go with their last Python reference
    return True


@contextmanager
def counting_programs() -> Iterator[Counter[str]]:
    """Count the programs JAX lowers for compilation inside the block, by name (e.g. ``jit__metric_series``): each
    is a trace and lower of its own, whether XLA then compiles it or finds it in the persistent cache. A program
    already held in memory (the same function, structure and shapes) is not lowered again and not counted."""
    counts: Counter[str] = Counter()

    class Tally(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            if record.msg.startswith("Compiling %s"):
                counts[str(record.args[0])] += 1  # type: ignore[index]

    logger = logging.getLogger(LOWERING_LOGGER)
    handler, level, propagate = Tally(logging.DEBUG), logger.level, logger.propagate
    logger.addHandler(handler)
    logger.setLevel(logging.DEBUG)
    logger.propagate = False  # the debug lines are for the tally, not for the user's log
    try:
        yield counts
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)
        logger.propagate = propagate
