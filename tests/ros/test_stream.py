"""The bridge's Track stream without a service: stand-in clients that plan, fail or hang."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterable, Iterator
from typing import Any

import numpy as np

from tests.ros import need_ros

need_ros()

from ros_bridge.assemble import Frame  # noqa: E402
from ros_bridge.stream import Ended, TrackStream, Update  # noqa: E402
from vgn_contract.schemas import GraspResult, Intrinsics, Pose  # noqa: E402

CAMERA = Intrinsics(width=4, height=3, fx=5.0, fy=5.0, cx=2.0, cy=1.5)
OTHER_CAMERA = Intrinsics(width=4, height=3, fx=6.0, fy=6.0, cx=2.0, cy=1.5)


def _frame(camera: Intrinsics = CAMERA) -> Frame:
    return Frame(np.ones((3, 4), np.float32), camera, Pose(position=[0.0, 0.0, 0.5]), 0.0)


class _Client:
    """Plans every frame it is sent (its ``frame_count`` counts them); with ``fail``, the stream
    fails at its first frame; with ``hang``, it takes the first frame and never answers."""

    def __init__(self, fail: bool = False, hang: bool = False) -> None:
        self.fail, self.hang = fail, hang
        self.closed = threading.Event()
        self.calls: list[tuple[str, Any, dict[str, Any]]] = []

    def track(
        self,
        session_id: str,
        frames: Iterable[tuple[np.ndarray, Pose]],
        intrinsics: Any = None,
        **options: Any,
    ) -> Iterator[GraspResult]:
        self.calls.append((session_id, intrinsics, options))
        for count, _ in enumerate(frames, 1):
            if self.fail:
                raise ConnectionError("gRPC UNAVAILABLE: the service went away")
            if self.hang:
                self.closed.wait()
            if self.closed.is_set():
                raise ConnectionError("gRPC CANCELLED: channel closed")
            yield GraspResult(
                grasps=[], planning_ms=1.0, integration_ms=1.0, frame_count=count, model="m", threshold=0.9
            )

    def close(self) -> None:
        self.closed.set()


class _Events:
    """What a stream delivers, collected from its thread."""

    def __init__(self) -> None:
        self.items: list[Update | Ended] = []
        self._lock = threading.Condition()

    def __call__(self, event: Update | Ended) -> None:
        with self._lock:
            self.items.append(event)
            self._lock.notify_all()

    def wait(self, done: Callable[[list[Update | Ended]], bool], timeout: float = 10.0) -> None:
        with self._lock:
            assert self._lock.wait_for(lambda: done(self.items), timeout), f"only {self.items}"

    def of(self, kind: type) -> list[Any]:
        with self._lock:
            return [item for item in self.items if isinstance(item, kind)]


def _until(done: Callable[[], Any], timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not done():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.01)


def _stream(clients: list[_Client], events: _Events, **kwargs: Any) -> TrackStream:
    opened = iter(clients)
    return TrackStream(lambda: next(opened), events, {"max_grasps": 3, "depth_scale": 1000.0}, **kwargs)


def test_one_stream_per_session_and_camera_plans_every_frame():
    clients, events = [_Client(), _Client(), _Client()], _Events()
    stream = _stream(clients, events)
    try:
        for session, camera in [("a", CAMERA), ("a", CAMERA), ("b", CAMERA), ("b", OTHER_CAMERA)]:
            stream.send(session, _frame(camera))
        events.wait(lambda items: len(items) == 4)
    finally:
        stream.close()
    assert [u.result.frame_count for u in events.of(Update)] == [1, 2, 1, 1]
    assert [client.calls[0][:2] for client in clients] == [("a", CAMERA), ("b", CAMERA), ("b", OTHER_CAMERA)]
    assert clients[0].calls[0][2] == {"max_grasps": 3, "depth_scale": 1000.0}


def test_a_failed_stream_is_delivered_and_opened_again_later_and_later():
    clients, events = [_Client(fail=True), _Client(fail=True), _Client()], _Events()
    stream = _stream(clients, events, backoff=0.05)
    try:
        stream.send("a", _frame())
        events.wait(lambda items: len(items) == 1)
        stream.send("a", _frame())
        events.wait(lambda items: len(items) == 2)
        started = time.monotonic()
        stream.send("a", _frame())
        events.wait(lambda items: len(items) == 3)
        assert time.monotonic() - started >= 0.08, "the second retry waits twice as long"
    finally:
        stream.close()
    ended = events.of(Ended)
    assert [(type(e.error), e.lost, e.retry_in) for e in ended] == [
        (ConnectionError, 1, 0.05),
        (ConnectionError, 1, 0.1),
    ]
    assert len(events.of(Update)) == 1


def test_stop_ends_the_stream_and_a_later_frame_opens_the_next():
    clients, events = [_Client(), _Client()], _Events()
    stream = _stream(clients, events)
    try:
        stream.send("a", _frame())
        events.wait(lambda items: len(items) == 1)
        assert stream.stop(timeout=5.0) == 0
        assert clients[0].closed.is_set(), "the stopped stream's client is closed"
        stream.send("a", _frame())
        events.wait(lambda items: len(items) == 2)
    finally:
        stream.close()
    assert [u.stream for u in events.of(Update)] == [0, 1], "the second stream's updates are not stale"


def test_stop_and_close_cancel_a_stream_the_service_does_not_answer():
    clients, events = [_Client(hang=True), _Client(hang=True)], _Events()
    stream = _stream(clients, events, backlog=2)
    try:
        stream.send("a", _frame())
        _until(lambda: clients[0].calls)
        assert [stream.send("a", _frame()) for _ in range(3)] == [0, 0, 1], "the backlog keeps the newest"
        started = time.monotonic()
        assert stream.stop(timeout=0.2) == 2, "the frames not sent are dropped"
        assert time.monotonic() - started < 5.0
        events.wait(lambda items: len(items) == 1)
        assert [(e.error, e.lost) for e in events.of(Ended)] == [(None, 1)], "cancelled on purpose"
        stream.send("a", _frame())
        _until(lambda: clients[1].calls)
    finally:
        started = time.monotonic()
        stream.close(timeout=5.0)
    assert time.monotonic() - started < 5.0 and clients[1].closed.is_set()
    assert not stream._thread.is_alive()
