"""Output folders: each holds exactly one command's output, written atomically.

Every command that writes a folder (``run``, ``mc``, ``tune``, ``reproduce``, ``sweep``, ``bench``) first calls
:func:`check_output`, before any simulation. The same command's earlier output is replaced; another command's
output only with ``--overwrite``; a folder ddtrack did not write (no marker ``ddtrack.json``) never, so a mistyped
``--out`` cannot delete a user's files. One-shot commands build their whole output in a hidden sibling folder
(:func:`staged_folder`) and swap it in when it is complete, so a folder never mixes two runs (an old
``identification.json`` or ``figures/gains.png`` beside a new run) and a failure midway leaves the old output as
it was. ``sweep`` and ``bench`` resume in place instead, and only the same study.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from importlib.metadata import version
from pathlib import Path
from typing import IO

from .errors import RunError

MARKER = "ddtrack.json"  #: written into every output folder: {"command", "study", "version", "written"}


#: how the marker records when a folder was written (local time with its UTC offset)
MARKER_TIME_FORMAT = "%Y-%m-%dT%H:%M:%S%z"


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write(path: Path, write: Callable[[IO[bytes]], object]) -> None:
    """Write ``path`` through ``write(file)`` on a temporary sibling, then rename it into place.

    A write that fails midway (a full disk, a folder that went read-only) removes its temporary and
    raises :class:`RunError` naming ``path`` and the cause (``No space left on device``): the folder
    keeps only the files that were whole before, and the command line prints one line, exit code 2.
    """
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise RunError(f"cannot write '{path}' ({exc.strerror or exc})") from exc
    try:
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp's 0600 would hide results from the user's group
        with os.fdopen(fd, "wb") as file:
            write(file)
            file.flush()
            os.fsync(file.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        Path(tmp).unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise RunError(
                f"cannot write '{path}' ({exc.strerror or exc}); "
                "nothing partial was left: free some space or choose another --out"
            ) from exc
        raise


def check_writable(folder: Path) -> None:
    """Fail early, before any simulation, if ``folder`` cannot be created or written. Creates nothing: a
    command that fails later (an unreachable scheduler, a diverged case) leaves no empty folder behind."""
    existing = Path(folder).absolute()
    while not existing.exists():
        existing = existing.parent
    try:
        if not existing.is_dir():
            raise NotADirectoryError(20, "Not a directory", str(existing))
        with tempfile.TemporaryFile(dir=existing):
            pass
    except OSError as exc:
        raise RunError(
            f"output folder '{folder}' cannot be written ({exc.strerror or exc}); choose another with --out"
        ) from None


#: a file each command's output has always held: folders written before the marker existed are still known
SIGNATURES = {
    "run": "metrics.json",
    "mc": "summary.json",
    "tune": "tune.json",
    "reproduce": "table1.json",
    "sweep": "records",
    "bench": "leaderboard.json",
}


def read_marker(folder: Path) -> dict | None:
    """Which command wrote ``folder`` (its marker, else its signature file), or None when ddtrack did not."""
    folder = Path(folder)
    try:
        marker = json.loads((folder / MARKER).read_text())
    except (OSError, ValueError):
        marker = None
    if isinstance(marker, dict) and isinstance(marker.get("command"), str):
        return marker
    found = [command for command, name in SIGNATURES.items() if (folder / name).exists()]
    return {"command": found[0], "study": None} if len(found) == 1 else None


def check_output(folder: Path, *, command: str, overwrite: bool, study: str | None = None) -> bool:
    """Decide, before any work, whether ``command`` may write ``folder``; return True when it resumes.

    An absent or empty folder is written. An earlier output of the same command is replaced whole (it is the
    same question asked again); ``sweep`` and ``bench`` (``study`` given: an identity of their plan) resume the
    same study instead, and replace another study only with ``overwrite``. Another command's output needs
    ``overwrite``. A folder ddtrack did not write is never touched. Raises :class:`RunError` (exit code 2)
    naming the folder and the fix.
    """
    folder = Path(folder)
    check_writable(folder)
    if not folder.exists():
        return False
    if not folder.is_dir():
        raise RunError(f"--out '{folder}' is a file, not a folder: choose another --out")
    if not any(folder.iterdir()):
        return False
    marker = read_marker(folder)
    if marker is None:
        raise RunError(
            f"--out '{folder}' holds files ddtrack did not write (no {MARKER}); ddtrack replaces only "
            "its own output folders: choose another --out, or empty it yourself"
        )
    if marker["command"] == command and study is None:
        return False  # replaced whole by staged_folder
    if marker["command"] == command and marker.get("study") == study and not overwrite:
        return True
    if not overwrite:
        what = (
            f"another `ddtrack {command}` study ({marker.get('study') or 'unknown'})"
            if marker["command"] == command
            else f"the output of `ddtrack {marker['command']}`"
        )
        raise RunError(
            f"--out '{folder}' already holds {what}: add --overwrite to replace it whole, or choose another --out"
        )
    return False


def _marker_bytes(command: str, study: str | None) -> bytes:
    marker = {
        "command": command,
        "study": study,
        "version": version("ddtrack"),
        "written": time.strftime(MARKER_TIME_FORMAT),
    }
    return (json.dumps(marker, indent=2) + "\n").encode()


def write_marker(folder: Path, *, command: str, study: str | None = None) -> None:
    """Mark ``folder`` as ``command``'s output (``study``: the plan a resumable command may resume)."""
    atomic_write(Path(folder) / MARKER, lambda f: f.write(_marker_bytes(command, study)))


def _swap_in(stage: Path, folder: Path) -> None:
    """Put ``stage`` where ``folder`` is: the old folder is renamed aside, the new one renamed in, the old
    removed; if the second rename fails, the old folder is put back."""
    old = None
    if folder.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", suffix=".old", dir=folder.parent))
        os.replace(folder, old / folder.name)
    try:
        os.replace(stage, folder)
    except OSError:
        if old is not None:
            os.replace(old / folder.name, folder)
            shutil.rmtree(old, ignore_errors=True)
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


@contextmanager
def staged_folder(folder: Path, *, command: str) -> Iterator[Path]:
    """Yield a hidden sibling of ``folder`` to write into; on success, mark it and swap it in whole.

    On any error the staging folder is removed and ``folder`` is left exactly as it was.
    """
    folder = Path(folder)
    try:
        folder.parent.mkdir(parents=True, exist_ok=True)
        stage = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", suffix=".new", dir=folder.parent))
        os.chmod(stage, 0o777 & ~_umask())  # mkdtemp's 0700 would hide results from the user's group
    except OSError as exc:
        raise RunError(f"cannot write '{folder}' ({exc.strerror or exc}); choose another --out") from None
    try:
        yield stage
        write_marker(stage, command=command)
        _swap_in(stage, folder)
    except BaseException as exc:
        shutil.rmtree(stage, ignore_errors=True)
        if isinstance(exc, OSError):
            raise RunError(f"cannot replace '{folder}' ({exc.strerror or exc}); it was left as it was") from exc
        if isinstance(exc, RunError):  # name the user's folder, not the hidden staging one
            raise RunError(str(exc).replace(str(stage), str(folder))) from exc.__cause__
        raise


def start_resumable(folder: Path, *, command: str, study: str, resume: bool) -> None:
    """Prepare ``folder`` for ``sweep`` or ``bench``: keep it to resume, or (after ``check_output`` allowed an
    overwrite) remove the old output whole; then mark it, so a killed study is found again."""
    folder = Path(folder)
    if folder.exists() and not resume and any(folder.iterdir()):
        aside = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", suffix=".old", dir=folder.parent))
        os.replace(folder, aside / folder.name)
        shutil.rmtree(aside, ignore_errors=True)
    write_marker(folder, command=command, study=study)


__all__ = [
    "MARKER",
    "SIGNATURES",
    "atomic_write",
    "check_output",
    "check_writable",
    "read_marker",
    "staged_folder",
    "start_resumable",
    "write_marker",
]
