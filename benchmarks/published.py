"""Which files of a results tree the documentation may read: those in the tree's own folders.

``docs/results/.gitignore`` keeps each result folder's top-level files (tables, records) and
leaves out everything deeper (the per-scenario run folders ``benchmarks.clutter`` writes). A
page that read a deeper file would read differently on a fresh clone than where the run was
made, and ``python -m benchmarks.report --check`` would fail there only.
"""

from __future__ import annotations

from pathlib import Path


def published(results: Path, name: str) -> list[Path]:
    """Every ``results/FOLDER/name``, in path order; files in deeper folders are not published."""
    return sorted(results.glob(f"*/{name}"))
