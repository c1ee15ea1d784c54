"""Compiled programs in a long-lived process: release them before the operating system's limit is reached.

XLA maps the code and data of every program it compiles into the process separately, and JAX keeps every
compiled program for reuse. Linux refuses a process more than ``vm.max_map_count`` mappings (65,530 by default);
at the limit an XLA compile fails to allocate and the process crashes (a segmentation fault, not an exception).
One distinct ddtrack run compiles programs holding about 600 mappings, so a process that runs a few hundred
distinct configurations (a sweep's worker, a test session) reaches it. :func:`release_compilations` empties JAX's
caches once a process holds a given share of its limit: later runs of a released program compile it again.

Beside JAX's persistent cache this module also keeps a ledger of the simulation programs studies compiled there
(:func:`compiled_programs`), and the programs themselves as ``jax.export`` serialized them (:func:`exported`), so a
later process reads a program back instead of tracing it again.
"""

from __future__ import annotations

import gc
import hashlib
import itertools
import logging
import math
import os
import threading
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from functools import cache
from pathlib import Path
from typing import Any

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


EXPORTS = "ddtrack-exported"  #: beside JAX's cache: programs as jax.export serialized them, one file per key
_EXPORTED: dict[str, Callable[..., Any] | None] = {}  # this process's: key -> its exported program's jitted call
_EXPORTING = threading.Lock()  # a batch's shares ask from threads of their own


def _plain(value: Any) -> bool:
    """Whether ``value``'s repr says all of it: None, a bool, int, float or str, or a tuple of them."""
    if isinstance(value, tuple | list):
        return all(_plain(item) for item in value)
    return value is None or isinstance(value, bool | int | float | str)


def _structure_text(tree: Any) -> str | None:
    """A pytree structure as text that names every node's type and static values, or None where the text could
    hide a difference: a type from outside ddtrack (a plugin's code may change under the same name) or a static
    value that is not plain data."""
    node = tree.node_data()
    if node is None:
        return "*"
    kind, static = node
    module = getattr(kind, "__module__", "")
    if module not in ("builtins", "collections") and not module.startswith("ddtrack."):
        return None
    if not (_plain(static) or static is kind):  # a named tuple's node names its own class
        return None
    children = [_structure_text(child) for child in tree.children()]
    if any(child is None for child in children):
        return None
    return f"{module}.{kind.__qualname__}{static!r}({','.join(children)})"  # type: ignore[arg-type]


def call_exported(
    name: str, function: Callable[..., Any], args: tuple, numbers: Mapping[str, Any], static: Mapping[str, Any]
) -> Any:
    """``function(*args, **numbers, **static)`` (``function`` jitted, ``static`` its static arguments), run from its
    exported program where :func:`exported` has one, else by ``function`` itself: the same bits either way."""
    import jax

    program = exported(name, function, (args, dict(numbers)), static)
    if program is None:
        return function(*args, **numbers, **static)
    return program(*jax.tree_util.tree_leaves((args, dict(numbers))))


def exported(
    name: str, function: Callable[..., Any], traced: tuple, static: Mapping[str, Any]
) -> Callable[..., Any] | None:
    """The program of ``function(*args, **numbers, **static)``, ``traced`` = (args, numbers) (every leaf traced,
    ``static`` plain values), as a jitted callable of ``traced``'s leaves, from its ``jax.export`` serialization
    beside the persistent cache: the first process that needs a structure exports it there, and every later one
    deserializes it instead of tracing and lowering it again (about 2 s a program, warm). Its compiled form then
    comes from the persistent cache as before, and its results are the jitted function's to the bit
    (``tests/test_programs.py``). None where this cannot be kept safely: no persistent cache in this process, no
    ``flatbuffers``, or a structure with a type from outside ddtrack or a static value that is not plain data (its
    key could not tell two programs apart)."""
    import jax

    folder = jax.config.jax_compilation_cache_dir  # type: ignore[attr-defined]  # read(), refused for this flag
    leaves, tree = jax.tree_util.tree_flatten(traced)
    structure = _structure_text(tree)
    if not folder or structure is None or not all(_plain(value) for value in static.values()):
        return None
    avals = [jax.typeof(leaf) for leaf in leaves]
    shapes = ";".join(f"{aval.dtype}{list(aval.shape)}{'w' if aval.weak_type else ''}" for aval in avals)
    key = ledger_entry(f"{name} {jax.default_backend()} {structure} {shapes} {sorted(static.items())!r}")
    with _EXPORTING:
        if key not in _EXPORTED:
            program = _exported_program(Path(folder) / EXPORTS / f"{key}.bin", function, tree, avals, static)
            if program is not None:
                program.__name__ = program.__qualname__ = name  # "jit(name)" in JAX's logs, as the jitted function's
            _EXPORTED[key] = None if program is None else jax.jit(program)  # a failure is not tried again
    return _EXPORTED[key]


def _exported_program(
    path: Path, function: Callable[..., Any], tree: Any, avals: list, static: Mapping[str, Any]
) -> Callable[..., Any] | None:
    """The call of the program at ``path``, exported there first if absent or unreadable (written whole: a
    temporary file renamed); None where JAX cannot export it (no ``flatbuffers``; a host callback in the program)."""
    import jax

    try:
        program = jax.export.deserialize(bytearray(path.read_bytes()))
    except Exception:  # absent, or cut short by a full disk: exported again
        try:

            def flat(*leaves: Any) -> Any:
                args, numbers = jax.tree_util.tree_unflatten(tree, leaves)
                return function(*args, **numbers, **static)

            specs = [jax.ShapeDtypeStruct(aval.shape, aval.dtype, weak_type=aval.weak_type) for aval in avals]
            program = jax.export.export(jax.jit(flat))(*specs)
            serialized = program.serialize()
        except Exception:  # the plain jit then runs it, as before
            return None
        keep(path, serialized)
    return lambda *leaves: program.call(*leaves)


def keep(path: Path, data: bytes | bytearray) -> None:
    """Write ``data`` whole to ``path`` beside the persistent cache (a temporary file renamed, so a concurrent
    reader never sees half of it); a read-only or full cache only loses the file, which is made again next time."""
    try:
        path.parent.mkdir(exist_ok=True)
        temporary = path.with_suffix(f".{os.getpid()}.{threading.get_ident()}")
        temporary.write_bytes(data)
        os.replace(temporary, path)
    except OSError:
        pass


def padded_length(n: int) -> int:
    """The next power of two at least ``n`` (and at least 1024): work done elementwise over ``n`` items is done over
    this many and cut, so that one compiled program serves inputs of many lengths instead of one program each."""
    return max(1024, 1 << (n - 1).bit_length())


def bucketed_length(n: int) -> int:
    """The run length a simulation program of ``n`` control periods is compiled for: the least ceil(2^(j/4)) at
    least ``n`` (a quarter of an octave: at most 19 % more periods), so runs of many lengths share a few programs;
    the periods past ``n`` are simulated and cut."""
    return next(length for j in itertools.count() if (length := math.ceil(2 ** (j / 4))) >= n)


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
