"""Session store: TTL expiry, eviction of the oldest idle session, and a clear capacity error."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from service.errors import CapacityExceeded, SessionExists, SessionNotFound
from service.sessions import SessionStore
from tests.helpers.scenes import INTRINSICS, BoxScene, circle_views
from vgn_contract.schemas import SessionCreate


class Clock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def store(max_sessions: int = 3, ttl_s: float = 60.0) -> tuple[SessionStore, Clock]:
    clock = Clock()
    return SessionStore(max_sessions, ttl_s, cloud_resolution=40, clock=clock), clock


def create(s: SessionStore, session_id: str) -> str:
    return s.create(SessionCreate(session_id=session_id)).session_id


def test_generated_ids_are_unique():
    s, _ = store()
    ids = {s.create(SessionCreate()).session_id for _ in range(3)}
    assert len(ids) == 3


def test_duplicate_id_is_refused():
    s, _ = store()
    create(s, "a")
    with pytest.raises(SessionExists):
        create(s, "a")


def test_idle_sessions_expire_after_ttl():
    s, clock = store(ttl_s=60)
    create(s, "a")
    clock.now += 59
    assert s.info("a").session_id == "a"
    clock.now += 61
    with pytest.raises(SessionNotFound, match="expired"):
        s.info("a")


def test_use_refreshes_the_ttl():
    s, clock = store(ttl_s=60)
    create(s, "a")
    clock.now += 50
    with s.use("a"):
        pass
    clock.now += 50
    assert s.info("a").expires_at == pytest.approx(clock.now + 10)


def test_sweep_drops_expired_sessions():
    s, clock = store(ttl_s=60)
    create(s, "a")
    create(s, "b")
    clock.now += 30
    with s.use("b"):
        pass
    clock.now += 40
    assert s.sweep() == 1
    assert [info.session_id for info in s.list()] == ["b"]


def test_limit_evicts_the_least_recently_used_idle_session():
    s, clock = store(max_sessions=3)
    for name in "abc":
        create(s, name)
        clock.now += 1
    with s.use("a"):
        pass  # "a" is now the most recently used
    create(s, "d")
    assert sorted(info.session_id for info in s.list()) == ["a", "c", "d"]


def test_busy_sessions_are_never_evicted():
    s, _ = store(max_sessions=2)
    create(s, "a")
    create(s, "b")
    with s.use("a"), s.use("b"), pytest.raises(CapacityExceeded, match="every session is in use"):
        create(s, "c")
    create(s, "c")  # once they are idle again, the oldest goes


def test_busy_sessions_do_not_expire():
    s, clock = store(ttl_s=10)
    create(s, "a")
    with s.use("a") as session:
        clock.now += 100
        assert s.sweep() == 0
        assert session.session_id == "a"


def test_concurrent_frames_to_one_session_are_all_counted(core):
    """The per-session lock serialises integrations: no frame is lost under concurrency."""
    session_id = core.create_session(SessionCreate(intrinsics=INTRINSICS)).session_id
    views = circle_views(6)
    depths = [BoxScene().depth(view) for view in views]
    errors: list[BaseException] = []

    def upload(i: int) -> None:
        try:
            core.add_frame(session_id, depths[i % 6], views[i % 6])
        except BaseException as error:  # pragma: no cover - reported below
            errors.append(error)

    threads = [threading.Thread(target=upload, args=(i,)) for i in range(12)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert not errors
    assert core.session_info(session_id).frame_count == 12
    sequential = core.create_session(SessionCreate(intrinsics=INTRINSICS)).session_id
    for i in range(12):
        core.add_frame(sequential, depths[i % 6], views[i % 6])
    # TSDF fusion is a weighted average: any order gives the same grid, a race does not.
    np.testing.assert_allclose(core.grid(session_id), core.grid(sequential), atol=1e-5)
