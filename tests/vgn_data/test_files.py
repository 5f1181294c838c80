"""Atomic writes: what a killed writer leaves, and how a resumed run clears it away."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from vgn_data.files import (
    CRASH_VARIABLE,
    UNMARKED_TEMPORARY_AGE_S,
    remove_stale_temporaries,
    write_atomically,
)

WRITE = "from pathlib import Path; from vgn_data.files import write_atomically; write_atomically(Path({!r}), 'new')"


def killed_write(path: Path) -> subprocess.CompletedProcess:
    """A process that dies (SIGKILL) after writing ``path``'s temporary, before the rename."""
    environment = {**os.environ, CRASH_VARIABLE: path.name}
    root = Path(__file__).resolve().parents[2]
    return subprocess.run([sys.executable, "-c", WRITE.format(str(path))], env=environment, cwd=root)


def test_a_killed_writers_temporary_is_removed_and_the_old_file_kept(tmp_path: Path):
    target = tmp_path / "nested" / "rounds.csv"
    write_atomically(target, "old")
    assert killed_write(target).returncode == -signal.SIGKILL
    (leftover,) = target.parent.glob(".*.tmp")
    assert leftover.read_text() == "new" and target.read_text() == "old"
    assert remove_stale_temporaries(tmp_path) == [leftover]
    assert not leftover.exists() and target.read_text() == "old"


def test_temporaries_of_live_writers_and_recent_unmarked_ones_stay(tmp_path: Path):
    own = tmp_path / f".a.csv.pid{os.getpid()}.x1y2.tmp"
    recent_unmarked = tmp_path / ".b.csv.x1y2.tmp"
    old_unmarked = tmp_path / ".c.csv.x1y2.tmp"
    other_name = tmp_path / "sub" / ".weights.pid999999999.x1y2.tmp"
    for path in (own, recent_unmarked, old_unmarked, other_name):
        path.parent.mkdir(exist_ok=True)
        path.write_text("partial")
    aged = time.time() - UNMARKED_TEMPORARY_AGE_S - 60
    os.utime(old_unmarked, (aged, aged))
    removed = remove_stale_temporaries(tmp_path, ".[abc].*.tmp", recursive=False)
    assert removed == [old_unmarked], "a live writer's file and a fresh one without a pid stay"
    assert own.exists() and recent_unmarked.exists() and other_name.exists()
    assert remove_stale_temporaries(tmp_path) == [other_name], "no such process: its writer is dead"
