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
import signal
import tempfile
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


@contextlib.contextmanager
def atomic_writer(path: Path, mode: str = "wb") -> Iterator[IO]:
    """A file to write ``path``'s new content into; it replaces ``path`` when the block ends
    without error and is removed otherwise. The result gets an ordinary file's mode."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    descriptor, temporary = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
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
