"""Atomic file writes, used for every file the project writes (datasets, results, models).

A reader sees either the old file or the new one, never a torn one: the data goes to a
unique temporary file beside the target, is flushed to disk, then renamed over it.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


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
