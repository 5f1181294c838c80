"""Fusing queued frames into sessions' cloud volumes off the request path.

Open3D holds the GIL for the whole of a fine (120³) integration, so fusing while frames
stream in or grasps are planned stalls every request of the process, whichever thread does
it. One shared worker therefore fuses queued frames only in a lull: no frame has arrived and
no planning has run in the process for ``idle_s`` (the service wraps planning in
:meth:`CloudFusion.planning`), or at once for a queue an upload waits on (full). It fuses
only clouds likely to be read (read before, or a queue past a quarter of its bound); the
rest wait for a cloud read. The thread starts on the first frame and ends after
``linger_s`` with nothing queued, and on ``close``. Figures: docs/design.md.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Iterator
from typing import Protocol

logger = logging.getLogger(__name__)

#: Quiet time after the last frame the process received before the worker fuses a queue.
IDLE_S = 0.05
#: Queued bytes across all sessions past which uploads wait for the worker (memory bound).
MAX_QUEUED_BYTES = 512 * 1024 * 1024
#: Seconds the worker thread waits with nothing queued before it ends (restarted on demand).
LINGER_S = 5.0


class FusionQueue(Protocol):
    """What the worker needs from a volume with queued frames (``SceneVolume``)."""

    def fusion_wanted(self) -> tuple[bool, bool]:
        """(worth fusing in a lull, wanted now: an upload waits for room)."""

    def fuse_next(self) -> bool:
        """Fuse its oldest queued frame; False when nothing was queued."""


class CloudFusion:
    """One daemon thread fusing queued frames of any number of volumes, those an upload
    waits on first."""

    def __init__(
        self, idle_s: float = IDLE_S, max_queued_bytes: int = MAX_QUEUED_BYTES, linger_s: float = LINGER_S
    ) -> None:
        self.idle_s = idle_s
        self.max_queued_bytes = max_queued_bytes
        self.linger_s = linger_s
        self.closed = False
        self._queues: set[FusionQueue] = set()
        self._queued_bytes = 0
        self._last_frame_at = 0.0
        self._last_planning_at = 0.0
        self._planning = 0  # plans running now
        self._bytes_lock = threading.Lock()  # apart from _wake: volumes account holding their own lock
        self._wake = threading.Condition()
        self._thread: threading.Thread | None = None

    # Called by volumes -----------------------------------------------------------------------
    def notify(self, queue: FusionQueue, frame: bool = False) -> None:
        """``queue`` has frames (``frame``: one just arrived) or an upload waits on it."""
        with self._wake:
            if self.closed:
                return
            if frame:
                self._last_frame_at = time.monotonic()
                if queue in self._queues:
                    return  # the worker's lull timer already covers it: no wake-up per frame
            self._queues.add(queue)
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="cloud-fusion", daemon=True)
                self._thread.start()
            self._wake.notify()

    @contextlib.contextmanager
    def planning(self) -> Iterator[None]:
        """Mark grasp planning as running: no fusion starts during it, nor for ``idle_s``
        after it (one already running finishes its frame)."""
        with self._wake:
            self._planning += 1
        try:
            yield
        finally:
            with self._wake:
                self._planning -= 1
                self._last_planning_at = time.monotonic()

    def forget(self, queue: FusionQueue) -> None:
        """Stop fusing ``queue`` (its volume closed); frames it still holds are its own to drop."""
        with self._wake:
            self._queues.discard(queue)

    def close(self, timeout_s: float = 10.0) -> None:
        """Stop the worker (after the frame it is fusing) and take no more work. Close the
        volumes first: an upload waiting for room is woken by its volume's ``close``."""
        with self._wake:
            self.closed = True
            self._queues.clear()
            thread = self._thread
            self._wake.notify_all()
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout_s)

    @property
    def running(self) -> bool:
        """Whether the worker thread is alive (it ends when idle or closed)."""
        thread = self._thread
        return thread is not None and thread.is_alive()

    def account(self, delta_bytes: int) -> None:
        """Add (or with a negative ``delta_bytes`` remove) queued frame bytes, across every volume."""
        with self._bytes_lock:
            self._queued_bytes += delta_bytes

    def over_budget(self) -> bool:
        """Whether the queued frames of all volumes together reach
        ``max_queued_bytes``: uploads then wait for room."""
        return self._queued_bytes >= self.max_queued_bytes

    @property
    def queued_bytes(self) -> int:
        """Bytes of frames queued across every volume and not yet fused."""
        return self._queued_bytes

    # The worker ------------------------------------------------------------------------------
    def _next_due(self) -> FusionQueue | None:
        """The queue to fuse now, waiting until one is due; None when closed or after
        ``linger_s`` with nothing queued. Call with ``_wake`` held."""
        idle_since = time.monotonic()
        while not self.closed:
            last_activity = max(self._last_frame_at, self._last_planning_at)
            lull = last_activity + self.idle_s - time.monotonic()
            if self._planning:
                lull = max(lull, self.idle_s)  # looked at again once it may be over
            in_lull = None
            for queue in list(self._queues):
                worth, now = queue.fusion_wanted()
                if now:
                    return queue
                if not worth:
                    self._queues.discard(queue)  # notified again when that changes
                elif in_lull is None:
                    in_lull = queue
            if in_lull is not None:
                if lull <= 0:
                    return in_lull
                self._wake.wait(lull)
                idle_since = time.monotonic()
                continue
            idle = time.monotonic() - idle_since  # nothing queued worth fusing
            if idle >= self.linger_s:
                return None
            self._wake.wait(self.linger_s - idle)
        return None

    def _run(self) -> None:
        try:
            while True:
                with self._wake:
                    queue = self._next_due()
                    if queue is None:
                        self._thread = None  # still under the lock, so the next notify starts another
                        return
                try:
                    queue.fuse_next()
                except Exception:  # a bad frame must not stop the cloud of every other session
                    logger.exception("fusing a queued frame into the cloud volume failed")
        except BaseException:  # the next notify starts another rather than waiting on a dead one
            with self._wake:
                self._thread = None
            raise


_shared: CloudFusion | None = None
_shared_lock = threading.Lock()


def shared_fusion() -> CloudFusion:
    """The process's worker, started on the first queued frame."""
    global _shared
    with _shared_lock:
        if _shared is None:
            _shared = CloudFusion()
        return _shared
