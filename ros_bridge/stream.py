"""Planning continuously: the node's frames go into a gRPC ``Track`` stream, and the grasps the
service plans after each come back as soon as they are ready, for a robot that keeps looking
while it moves (docs/closed-loop.md).

A stream waits on the service, so it runs on a thread of its own and hands what happens to the
node through ``deliver``; the node publishes on its own thread. Nothing here imports ROS.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from ros_bridge.assemble import Frame
from vgn_contract.schemas import GraspResult, Pose


class TrackClient(Protocol):
    """What a stream needs of ``GRPCClient``: its ``track`` and a ``close`` that cancels it."""

    def track(
        self,
        session_id: str,
        frames: Iterable[tuple[np.ndarray, Pose]],
        **options: Any,
    ) -> Iterator[GraspResult]:
        """The grasps after each frame, as ``GRPCClient.track``."""

    def close(self) -> None:
        """Close the connection, cancelling the stream."""


@dataclass(frozen=True)
class Update:
    """The grasps planned after a frame of stream number ``stream``."""

    result: GraspResult
    stream: int


@dataclass(frozen=True)
class Ended:
    """A stream ended with ``lost`` frames that got no update: it failed with ``error`` (the next
    opens in ``retry_in`` s), or ``error`` is None and it was ended on purpose."""

    error: Exception | None
    lost: int
    retry_in: float = 0.0


@dataclass
class _Open:
    """The stream being sent: one session and one camera."""

    session_id: str
    frame: Frame  # its first
    sent: int = 0
    done: bool = False


class TrackStream:
    """Frames in (``send``), ``Update`` and ``Ended`` out (``deliver``, called on the stream's thread).

    Each stream has a client of its own from ``open_client``, so that closing it cancels the
    stream and nothing else. A stream follows one session and one camera: a frame for another
    session or with other intrinsics ends it, and the next one opens with that frame. A stream
    that fails is delivered as ``Ended`` and opened again with the frames that come next,
    ``backoff`` s later at first and twice as long each time up to ``max_backoff``. At most
    ``backlog`` frames wait to be sent: a camera faster than the service loses its oldest.
    ``options`` are ``track``'s keyword arguments besides the intrinsics (grasp options,
    ``depth_scale``, ``max_depth``).
    """

    def __init__(
        self,
        open_client: Callable[[], TrackClient],
        deliver: Callable[[Update | Ended], None],
        options: dict[str, Any],
        backlog: int = 8,
        backoff: float = 0.5,
        max_backoff: float = 10.0,
    ) -> None:
        self._open_client, self._deliver, self._options = open_client, deliver, options
        self._backlog, self._backoff, self._max_backoff = backlog, backoff, max_backoff
        self._lock = threading.Condition()
        self._waiting: deque[tuple[str, Frame]] = deque()
        self._open: _Open | None = None
        self._client: TrackClient | None = None  # the open stream's, closed to cancel it
        self._ending = False  # the open stream is to end once its frames in flight are planned
        self._closed = False
        #: The number of the stream frames sent now go into; ``stop`` moves it on, so that an
        #: update of an earlier stream is known as stale.
        self.stream = 0
        self._thread = threading.Thread(target=self._run, name="vgn-track", daemon=True)
        self._thread.start()

    def send(self, session_id: str, frame: Frame) -> int:
        """Queue ``frame`` for ``session_id``'s stream; how many of the oldest waiting frames
        were dropped to keep within the backlog."""
        with self._lock:
            self._waiting.append((session_id, frame))
            dropped = 0
            while len(self._waiting) > self._backlog:
                self._waiting.popleft()
                dropped += 1
            self._lock.notify_all()
        return dropped

    def stop(self, timeout: float) -> int:
        """End the stream for a reset of its session, and wait: the frames not yet sent are
        dropped (their count returned), those in flight are still planned, and a stream still
        open after ``timeout`` s is cancelled. The next frame opens a new stream."""
        with self._lock:
            dropped = len(self._waiting)
            self._waiting.clear()
            self.stream += 1
            if self._open is None:
                return dropped
            self._ending = True
            self._lock.notify_all()
            if not self._lock.wait_for(lambda: self._open is None, timeout):
                self._cancel()
                self._lock.wait_for(lambda: self._open is None, timeout)
        return dropped

    def close(self, timeout: float = 5.0) -> None:
        """Cancel the stream for good and wait up to ``timeout`` s for its thread."""
        with self._lock:
            self._closed = True
            self._cancel()
            self._lock.notify_all()
        self._thread.join(timeout)

    def _cancel(self) -> None:
        """Close the open stream's client (the lock held): its call ends at once."""
        if self._client is not None:
            self._client.close()

    def _run(self) -> None:
        delay = self._backoff
        while True:
            with self._lock:
                self._lock.wait_for(lambda: self._waiting or self._closed)
                if self._closed:
                    return
                session_id, frame = self._waiting.popleft()
                opened = self._open = _Open(session_id, frame)
                number = self.stream
            planned, error = 0, None
            try:
                client = self._open_client()
                with self._lock:
                    self._client = client
                    if self._closed:
                        client.close()
                frames = self._frames(opened)
                updates = client.track(session_id, frames, intrinsics=frame.intrinsics, **self._options)
                for result in updates:
                    planned += 1
                    delay = self._backoff
                    self._deliver(Update(result, number))
            except Exception as failure:  # a dropped stream is reported and opened again, never raised
                error = failure
            with self._lock:
                if self._client is not None:
                    self._client.close()
                on_purpose = self._closed or self._ending
                lost = opened.sent - planned
                if error is not None and not on_purpose:
                    lost += len(self._waiting)  # sent while the stream was failing: stale by now
                    self._waiting.clear()
                opened.done = True
                self._open, self._client, self._ending = None, None, False
                self._lock.notify_all()
            if error is None or on_purpose:
                if lost:
                    self._deliver(Ended(None, lost))
                continue
            self._deliver(Ended(error, lost, delay))
            with self._lock:
                self._lock.wait_for(lambda: self._closed, delay)
            delay = min(2 * delay, self._max_backoff)

    def _frames(self, opened: _Open) -> Iterator[tuple[np.ndarray, Pose]]:
        """The stream's frames as gRPC asks for them: its first, then each that comes for the
        same session and camera, until the stream is to end."""
        frame = opened.frame
        while True:
            opened.sent += 1
            yield frame.depth, frame.pose
            with self._lock:
                self._lock.wait_for(lambda: self._waiting or self._ending or self._closed or opened.done)
                if self._ending or self._closed or opened.done:
                    return
                session_id, frame = self._waiting[0]
                if session_id != opened.session_id or frame.intrinsics != opened.frame.intrinsics:
                    return  # the next stream's first frame
                self._waiting.popleft()
