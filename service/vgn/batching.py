"""Micro-batching: grasp requests that arrive together share one forward pass.

Why: on a GPU one forward of a batch of 32 grids costs little more than one of a single
grid, so concurrent sessions would otherwise queue behind each other for nothing. One forward
runs at a time: it takes the first waiting grid, waits at most
``window_s`` for others (none on a CPU by default, where a batch costs as much as its parts),
also takes whatever is already queued, up to ``max_batch``, and runs them as one batch.
Grids of different resolutions are run as separate batches. One forward at a time also
keeps CPU inference from oversubscribing the cores.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: A batched forward: (B, N, N, N) float32 grids → per-grid outputs, in order.
BatchForward = Callable[[np.ndarray], list]


@dataclass
class BatchStats:
    """Forward passes run and grids they carried (``GET /model`` reports them)."""

    batches: int = 0
    grids: int = 0
    largest: int = 0
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def record(self, size: int) -> None:
        """Count one forward pass that carried ``size`` grids."""
        with self.lock:
            self.batches += 1
            self.grids += size
            self.largest = max(self.largest, size)

    def as_dict(self) -> dict[str, float | int]:
        """The counts and the mean batch size, read consistently under the lock."""
        with self.lock:
            mean = self.grids / self.batches if self.batches else 0.0
            return {"batches": self.batches, "grids": self.grids, "largest": self.largest, "mean": mean}


class MicroBatcher:
    """Runs ``forward`` on batches of concurrently submitted grids.

    No thread of its own: a caller that finds no forward running becomes the *leader* and
    runs the batch in its own thread, the others wait for it and for their results. A lone
    request therefore never hands its grid to another thread (each hand-off costs a wake-up,
    which on a loaded machine can take longer than the forward).
    """

    def __init__(self, forward: BatchForward, window_s: float = 0.0, max_batch: int = 32) -> None:
        self._forward = forward
        self.window_s = window_s
        self.max_batch = max_batch
        self._queue: queue.SimpleQueue[tuple[np.ndarray, Future]] = queue.SimpleQueue()
        self._turn = threading.Condition()
        self._leading = False
        self.stats = BatchStats()

    def run(self, grid: np.ndarray) -> Any:
        """The output for one grid, from a forward pass it may share with others."""
        return self.run_many([grid])[0]

    def run_many(self, grids: list[np.ndarray]) -> list[Any]:
        """The outputs for several grids of one request, queued together so that they share
        a forward pass (with each other and with concurrent requests)."""
        futures: list[Future] = [Future() for _ in grids]
        for grid, future in zip(grids, futures, strict=True):
            self._queue.put((grid, future))
        while not all(future.done() for future in futures):
            with self._turn:
                while self._leading and not all(future.done() for future in futures):
                    self._turn.wait()
                if all(future.done() for future in futures):
                    break
                self._leading = True
            try:
                self._run(self._collect())
            finally:
                with self._turn:
                    self._leading = False
                    self._turn.notify_all()
        return [future.result() for future in futures]

    def _collect(self) -> list[tuple[np.ndarray, Future]]:
        """What is queued, and what arrives within the window, up to ``max_batch``."""
        pending: list[tuple[np.ndarray, Future]] = []
        deadline = time.perf_counter() + self.window_s
        while len(pending) < self.max_batch:
            remaining = deadline - time.perf_counter()
            try:
                item = self._queue.get(timeout=remaining) if remaining > 0 else self._queue.get_nowait()
            except queue.Empty:
                break
            pending.append(item)
        return pending

    def _run(self, pending: list[tuple[np.ndarray, Future]]) -> None:
        by_shape: dict[tuple[int, ...], list[tuple[np.ndarray, Future]]] = {}
        for grid, future in pending:
            if future.set_running_or_notify_cancel():
                by_shape.setdefault(grid.shape, []).append((grid, future))
        for group in by_shape.values():
            try:
                outputs = self._forward(np.stack([grid for grid, _ in group]))
            except BaseException as error:  # every waiting request must hear of it
                for _, future in group:
                    future.set_exception(error)
                continue
            self.stats.record(len(group))
            for (_, future), output in zip(group, outputs, strict=True):
                future.set_result(output)
