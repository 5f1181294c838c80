"""How the benchmarks time an operation: the call, its samples and the schedule of rounds.

The latency, gRPC and inference-backend benchmarks share it so that their rows are measured
the same way (the same warm-up, percentiles and interleaving) and can sit side by side.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class Operation:
    """One thing to time: ``call(i)`` is the i-th call (warm-up calls included)."""

    name: str
    group: str
    call: Callable[[int], object]
    note: str = ""
    #: Untimed, just before each call (e.g. a new frame, so the call cannot reuse old work).
    prepare: Callable[[int], object] | None = None


@dataclass
class Measurement:
    """Latency samples (ms) of one named operation."""

    name: str
    group: str
    samples_ms: list[float] = field(default_factory=list)
    note: str = ""

    def percentile(self, q: float) -> float:
        """The ``q``-th percentile of the samples in ms; NaN before any sample."""
        return float(np.percentile(self.samples_ms, q)) if self.samples_ms else float("nan")

    @property
    def p50(self) -> float:
        """Median latency in ms."""
        return self.percentile(50)

    @property
    def p95(self) -> float:
        """95th-percentile latency in ms: the slow tail a robot waits for."""
        return self.percentile(95)

    def as_dict(self) -> dict[str, Any]:
        """The row for the JSON report: percentiles, mean, count and the raw samples."""
        mean = statistics.fmean(self.samples_ms) if self.samples_ms else float("nan")
        return {
            "name": self.name,
            "group": self.group,
            "p50_ms": round(self.p50, 4),
            "p95_ms": round(self.p95, 4),
            "mean_ms": round(mean, 4),
            "n": len(self.samples_ms),
            "note": self.note,
            "samples_ms": self.samples_ms,
        }


def timed(call: Callable[[int], object], i: int, prepare: Callable[[int], object] | None = None) -> float:
    """Milliseconds ``call(i)`` takes (after an untimed ``prepare(i)``)."""
    if prepare is not None:
        prepare(i)
    started = time.perf_counter()
    call(i)
    return (time.perf_counter() - started) * 1e3


def run_interleaved(
    operations: list[Operation], repeats: int, warmup: int, rotate: bool = False
) -> list[Measurement]:
    """Round-robin: each round calls every operation once; the first ``warmup`` rounds are
    not recorded. ``rotate``: round i starts at operation i (mod their count), so that no
    operation always follows the same one (what ran just before can cost the next call: a
    server thread that went idle, caches another front end filled)."""
    rows = [Measurement(op.name, op.group, note=op.note) for op in operations]
    order = list(range(len(operations)))
    for i in range(warmup + repeats):
        start = i % len(order) if rotate else 0
        for k in order[start:] + order[:start]:
            elapsed = timed(operations[k].call, i, operations[k].prepare)
            if i >= warmup:
                rows[k].samples_ms.append(elapsed)
    return rows


def run_blocks(operations: list[Operation], repeats: int, warmup: int) -> list[Measurement]:
    """Each operation's ``warmup`` untimed and ``repeats`` timed calls back to back."""
    rows = []
    for op in operations:
        for i in range(warmup):
            timed(op.call, i, op.prepare)
        samples = [timed(op.call, i, op.prepare) for i in range(warmup, warmup + repeats)]
        rows.append(Measurement(op.name, op.group, samples, op.note))
    return rows


def find(rows: list[Measurement], name: str) -> Measurement:
    """The row called ``name`` (StopIteration when the run did not measure it)."""
    return next(row for row in rows if row.name == name)
