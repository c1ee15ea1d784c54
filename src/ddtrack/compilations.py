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
import hashlib
import logging
import os
from collections import Counter
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from functools import cache
from pathlib import Path

MAP_LIMIT_FILE = "/proc/sys/vm/max_map_count"
OWN_MAPS_FILE = "/proc/self/maps"
LOWERING_LOGGER = "jax._src.interpreters.pxla"  #: where JAX says it lowers a program for compilation
RELEASE_AT = 0.5  #: the share of the mapping limit at which compiled programs are released


def cache_folder() -> Path:
    """The persistent compilation cache's folder: ``$DDTRACK_CACHE_DIR/jax``, or ``~/.cache/ddtrack/jax``."""
    root = (
        os.environ.get("DDTRACK_CACHE_DIR")
        or Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "ddtrack"
    )
    return Path(root) / "jax"


def enable_compilation_cache() -> None:
    """Turn on JAX's persistent compilation cache in :func:`cache_folder`: a second process (a CLI run, a sweep
    worker) then skips most of the compile. Every compiled function is kept: the run's small random-number jits
    would otherwise be compiled again each time (0.4 s)."""
    import jax

    cache = cache_folder()
    try:
        cache.mkdir(parents=True, exist_ok=True)
    except OSError:
        return  # a read-only home only costs compile time
    jax.config.update("jax_compilation_cache_dir", str(cache))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0)


LEDGER = "ddtrack-programs"  #: beside JAX's cache: one line per simulation program a study compiled into it


@cache
def _source_fingerprint() -> str:
    """What a compiled program depends on besides its key: this package's source, JAX's version and XLA's flags."""
    import jax

    digest = hashlib.sha256(f"{jax.__version__} {os.environ.get('XLA_FLAGS', '')}".encode())
    for path in sorted(Path(__file__).parent.rglob("*.py")):
        digest.update(path.read_bytes())
    return digest.hexdigest()


def ledger_entry(program: str) -> str:
    """The ledger's line for ``program`` (a study's program key): it names this source, JAX and XLA flags too."""
    return hashlib.sha256(f"{_source_fingerprint()} {program}".encode()).hexdigest()[:32]


def compiled_programs() -> set[str]:
    """The ledger's entries (:func:`ledger_entry`) of the programs studies compiled into the persistent cache in
    :func:`cache_folder` (where ``ddtrack``'s commands and a study's workers keep it). Emptying the cache's folder
    empties the ledger with it."""
    try:
        return set((cache_folder() / LEDGER).read_text().split())
    except OSError:
        return set()


def record_compiled(programs: Iterable[str]) -> None:
    """Add ``programs`` (ledger entries) to the ledger, where this process's persistent cache is on; one short append
    per call, which concurrent workers' appends do not interleave."""
    import jax

    folder = jax.config.jax_compilation_cache_dir  # type: ignore[attr-defined]  # read(), refused for this flag
    if folder:
        try:
            with open(Path(folder) / LEDGER, "a") as ledger:
                ledger.write("".join(f"{entry}\n" for entry in programs))
        except OSError:
            pass  # a read-only cache only loses the count


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
