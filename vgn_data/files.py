"""Atomic file writes, used for every file the project writes (datasets, results, models).

A reader sees either the old file or the new one, never a torn one: the data goes to a
unique temporary file beside the target, is flushed to disk, then renamed over it.

Crash tests need a process to die at the worst moment of a write, every time. Setting
``VGN_CRASH_AT_WRITE=NAME[:N]`` makes the process SIGKILL itself on the N-th write (default
the first) of a file called NAME: an atomic write dies after its temporary file is complete
and before the rename, an append (``crash_point`` callers) halfway through its text. Unset,
as in production, it costs one dictionary lookup per write.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import IO


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


CRASH_VARIABLE = "VGN_CRASH_AT_WRITE"
_writes_seen: dict[str, int] = {}


def crash_point(path: Path) -> bool:
    """Whether this write of ``path`` is the one ``VGN_CRASH_AT_WRITE`` names (counts writes
    of that name in this process); the caller then calls ``crash_now`` mid-write."""
    spec = os.environ.get(CRASH_VARIABLE)
    if not spec:
        return False
    name, _, nth = spec.partition(":")
    if Path(path).name != name:
        return False
    _writes_seen[name] = _writes_seen.get(name, 0) + 1
    return _writes_seen[name] == int(nth or 1)


def crash_now() -> None:
    """Die as a power cut or ``kill -9`` would: no cleanup, no exception handlers."""
    os.kill(os.getpid(), signal.SIGKILL)


#: Temporary files carry their writer's process id, so that a resumed run can tell the leftovers
#: of a killed writer from the files of one still writing.
TEMPORARY_PID_MARK = "pid"
_TEMPORARY_NAME = re.compile(rf"^\..+\.{TEMPORARY_PID_MARK}(\d+)\.[^.]+\.tmp$")
#: Temporaries without a process id (older writers) count as abandoned after this long.
UNMARKED_TEMPORARY_AGE_S = 3600.0


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def remove_stale_temporaries(folder: Path, pattern: str = ".*.tmp", recursive: bool = True) -> list[Path]:
    """Delete the temporary files (``pattern``) that killed writers left in ``folder`` and,
    when ``recursive``, below it, and return them: a write is never completed from its
    temporary, so they are garbage. Those of live processes on this machine stay: a run may
    resume beside another one still writing."""
    removed = []
    candidates = Path(folder).rglob(pattern) if recursive else Path(folder).glob(pattern)
    for candidate in candidates:
        match = _TEMPORARY_NAME.match(candidate.name)
        try:
            if match:
                stale = not _process_alive(int(match.group(1)))
            else:
                stale = time.time() - candidate.stat().st_mtime > UNMARKED_TEMPORARY_AGE_S
            if stale and candidate.is_file():
                candidate.unlink()
                removed.append(candidate)
        except FileNotFoundError:  # renamed or removed meanwhile by its writer
            continue
    return removed


@contextlib.contextmanager
def atomic_writer(path: Path, mode: str = "wb") -> Iterator[IO]:
    """A file to write ``path``'s new content into; it replaces ``path`` when the block ends
    without error and is removed otherwise. The result gets an ordinary file's mode."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    prefix = f".{path.name}.{TEMPORARY_PID_MARK}{os.getpid()}."
    descriptor, temporary = tempfile.mkstemp(prefix=prefix, suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(descriptor, mode) as stream:
            yield stream
            stream.flush()
            os.fsync(stream.fileno())
        if crash_point(path):
            crash_now()
        os.chmod(temporary, 0o666 & ~_umask())  # mkstemp creates 0600
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


def check_settings(path: Path, settings: dict, may_change: tuple[str, ...] = ()) -> None:
    """Record a run's settings in ``path``, or, resuming, refuse settings that differ from
    the recorded ones (except ``may_change``): one folder holds one kind of run."""
    path = Path(path)
    if path.exists():
        previous = json.loads(path.read_text())
        changed = sorted(
            k
            for k in set(previous) | set(settings)
            if k not in may_change and previous.get(k) != settings.get(k)
        )
        if changed:
            raise ValueError(
                f"{path.parent} holds a run with other settings ({', '.join(changed)}); "
                "use another folder, or the same settings to resume"
            )
    write_atomically(path, json.dumps(settings, indent=2, sort_keys=True) + "\n")


def write_atomically(path: Path, data: str | bytes) -> None:
    """Replace ``path`` with ``data`` (text is written as UTF-8)."""
    with atomic_writer(path, "wb") as stream:
        stream.write(data.encode() if isinstance(data, str) else data)
