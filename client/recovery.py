"""Sessions that survive a lost replica: what a client keeps to rebuild a session, when it
must, and how, for the HTTP and gRPC clients alike.

Behind a proxy that routes by session id (docs/fleet.md), a session lives in one replica's
memory. When that replica dies, the next one does not know the session (404 / NOT_FOUND) or
fails while the proxy notices (502/503/504, a dropped connection). The client keeps the
session's settings and the frames fused since its last reset, within ``Replay``'s bounds; on
such an error it opens the session again under the same id, replays the frames and retries
the request, so the caller sees a slower call with the same grasps, not an error. Past the
bounds a lost session raises the original error until its next reset.
"""

from __future__ import annotations

import asyncio
import threading
import time
import uuid
from collections import OrderedDict
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeVar

import httpx

from vgn_contract.schemas import SessionCreate

T = TypeVar("T")
#: Statuses a proxy answers with itself while a replica is gone (the service's own carry JSON).
PROXY_STATUSES = (502, 503, 504)


@dataclass(frozen=True)
class Replay:
    """How much a client keeps per session to rebuild it, and how hard it tries.

    ``max_frames`` and ``max_bytes`` bound the frames kept since the session's last reset (their
    encoded bytes, as sent: a 640×480 float32 frame is 1.2 MB, a 16-bit PNG of it about 0.1 MB),
    snapshot included; ``max_sessions`` the sessions kept (the least recently used beyond it can
    no longer be rebuilt). ``attempts`` rebuilds are tried for one call, ``backoff_s`` apart at first
    and twice as long each time, while the proxy notices the lost replica.
    """

    max_frames: int = 64
    max_bytes: int = 128 * 2**20
    max_sessions: int = 256
    attempts: int = 4
    backoff_s: float = 0.25


#: What a client keeps unless told otherwise.
DEFAULT_REPLAY = Replay()


@dataclass
class Rebuild:
    """What opens a session again: its settings, the snapshot it came from, the frames since."""

    spec: SessionCreate
    snapshot: bytes | None
    base_frames: int  # frames the snapshot holds
    frames: list[Any]

    @property
    def frame_count(self) -> int:
        """Frames the session holds once rebuilt."""
        return self.base_frames + len(self.frames)


@dataclass
class _Kept:
    rebuild: Rebuild
    nbytes: int = 0
    overflowed: bool = False
    generation: int = 0  # bumped by every rebuild, so that concurrent callers rebuild once
    lock: threading.Lock = field(default_factory=threading.Lock)  # guards the fields above
    rebuilding: threading.Lock = field(default_factory=threading.Lock)
    rebuilding_async: asyncio.Lock | None = None


class Transport(Protocol):
    """The calls a rebuild makes, over one client's transport; each raises the client's errors."""

    def open(self, plan: Rebuild) -> Any:
        """Create the session from ``plan.spec``, or import ``plan.snapshot`` under its id; its ``SessionInfo``."""

    def delete(self, session_id: str) -> None:
        """Delete the session."""

    def replay(self, session_id: str, frame: Any) -> None:
        """Send a kept frame again."""


class AsyncTransport(Protocol):
    """``Transport`` for the asyncio client."""

    async def open(self, plan: Rebuild) -> Any:
        """As ``Transport.open``."""

    async def delete(self, session_id: str) -> None:
        """As ``Transport.delete``."""

    async def replay(self, session_id: str, frame: Any) -> None:
        """As ``Transport.replay``."""


def is_lost(error: BaseException) -> bool:
    """Whether a call on a session failed as calls do when the replica holding it is gone: the
    session is unknown where the call went (a 404 without ``ended``: one that ended there, deleted
    or expired, is gone for good), the proxy answered in its stead (502/503/504 without the
    service's JSON) or the connection failed. Timeouts are not: the session may be busy, not gone."""
    status = getattr(error, "status", None)
    if status is not None:
        if status == 404:
            return not getattr(error, "ended", None)
        return status in PROXY_STATUSES and not getattr(error, "from_service", True)
    if isinstance(error, httpx.TimeoutException | TimeoutError):
        return False
    return isinstance(error, httpx.TransportError | ConnectionError)


def conflicting(error: BaseException) -> bool:
    """Whether opening a session failed because its id is taken (409 / ALREADY_EXISTS)."""
    return getattr(error, "status", None) == 409


def new_session_id() -> str:
    """An id for a session the caller did not name: the client picks it, so that even the
    request creating the session carries it for the proxy to route by."""
    return uuid.uuid4().hex


def rebuild(transport: Transport, plan: Rebuild) -> Any:
    """Open the session again and replay its frames. A session of that id that still exists
    where the proxy now routes it (the connection failed but the replica lives) is deleted
    first: only the kept frames say what the session holds."""
    session_id = plan.spec.session_id
    assert session_id is not None
    try:
        info = transport.open(plan)
    except Exception as error:
        if not conflicting(error):
            raise
        transport.delete(session_id)
        info = transport.open(plan)
    for frame in plan.frames:
        transport.replay(session_id, frame)
    return info


async def arebuild(transport: AsyncTransport, plan: Rebuild) -> Any:
    """As ``rebuild``, for the asyncio client."""
    session_id = plan.spec.session_id
    assert session_id is not None
    try:
        info = await transport.open(plan)
    except Exception as error:
        if not conflicting(error):
            raise
        await transport.delete(session_id)
        info = await transport.open(plan)
    for frame in plan.frames:
        await transport.replay(session_id, frame)
    return info


class SessionJournal:
    """The sessions a client opened and what rebuilds each (thread-safe); ``replay=None`` keeps nothing."""

    def __init__(self, replay: Replay | None = DEFAULT_REPLAY) -> None:
        self.replay = replay
        self.rebuilds = 0  # sessions rebuilt so far
        self._kept: OrderedDict[str, _Kept] = OrderedDict()  # least recently used first
        self._lock = threading.Lock()

    def opened(self, spec: SessionCreate, snapshot: bytes | None = None, base_frames: int = 0) -> None:
        """A session was created (or imported from ``snapshot``, holding ``base_frames``)."""
        if self.replay is None or spec.session_id is None:
            return
        kept = _Kept(Rebuild(spec, None, base_frames, []))
        with self._lock:
            self._kept[spec.session_id] = kept
            self._kept.move_to_end(spec.session_id)
            while len(self._kept) > self.replay.max_sessions:
                self._kept.popitem(last=False)
        if snapshot is not None:
            with kept.lock:
                self._keep(kept, len(snapshot), lambda: setattr(kept.rebuild, "snapshot", snapshot))

    def fused(self, session_id: str, frame: Any, nbytes: int) -> None:
        """A frame was fused into the session (kept while within the bounds)."""
        kept = self._get(session_id)
        if kept is not None:
            with kept.lock:
                self._keep(kept, nbytes, lambda: kept.rebuild.frames.append(frame))

    def reset(self, session_id: str) -> None:
        """The session was emptied: nothing is needed to rebuild it but its settings."""
        kept = self._get(session_id)
        if kept is not None:
            with kept.lock:
                kept.rebuild.snapshot, kept.rebuild.base_frames, kept.rebuild.frames = None, 0, []
                kept.nbytes, kept.overflowed = 0, False

    def give_up(self, session_id: str) -> None:
        """The session outgrew the bounds in a way ``fused`` does not see (a long stream of frames)."""
        kept = self._get(session_id)
        if kept is not None:
            with kept.lock:
                kept.rebuild.snapshot, kept.rebuild.frames = None, []
                kept.nbytes, kept.overflowed = 0, True

    def forget(self, session_id: str) -> bool:
        """The session was deleted, or ended on the service; whether it was one of this client's."""
        with self._lock:
            return self._kept.pop(session_id, None) is not None

    def _get(self, session_id: str) -> _Kept | None:
        with self._lock:
            kept = self._kept.get(session_id)
            if kept is not None:
                self._kept.move_to_end(session_id)
            return kept

    def _keep(self, kept: _Kept, nbytes: int, keep: Callable[[], None]) -> None:
        """Keep a frame or snapshot (``kept.lock`` held), or give up on the session past the bounds."""
        assert self.replay is not None
        if kept.overflowed:
            return
        items = len(kept.rebuild.frames) + (kept.rebuild.snapshot is not None)
        if items + 1 > self.replay.max_frames or kept.nbytes + nbytes > self.replay.max_bytes:
            kept.rebuild.snapshot, kept.rebuild.frames = None, []  # cannot be rebuilt: free them
            kept.nbytes, kept.overflowed = 0, True
            return
        keep()
        kept.nbytes += nbytes

    def _plan(self, kept: _Kept) -> Rebuild | None:
        with kept.lock:
            if kept.overflowed:
                return None
            rebuild = kept.rebuild
            return Rebuild(rebuild.spec, rebuild.snapshot, rebuild.base_frames, list(rebuild.frames))

    # Opening sessions ---------------------------------------------------------------------------
    def open(self, transport: Transport, plan: Rebuild) -> Any:
        """Open a new session (its ``SessionInfo``) and keep it. A first try that fails as on a
        lost replica is retried; a taken id then is taken by that first try, which did land."""
        try:
            info = transport.open(plan)
        except Exception as error:
            if self.replay is None or not is_lost(error):
                raise
            failure: Exception = error
            for attempt in range(self.replay.attempts):
                time.sleep(self.replay.backoff_s * 2**attempt)
                try:
                    info = rebuild(transport, plan)
                    break
                except Exception as again:
                    if not is_lost(again):
                        raise
                    failure = again
            else:
                raise failure from None
        self.opened(plan.spec, plan.snapshot, plan.base_frames)
        return info

    async def aopen(self, transport: AsyncTransport, plan: Rebuild) -> Any:
        """As ``open``, for the asyncio client."""
        try:
            info = await transport.open(plan)
        except Exception as error:
            if self.replay is None or not is_lost(error):
                raise
            failure: Exception = error
            for attempt in range(self.replay.attempts):
                await asyncio.sleep(self.replay.backoff_s * 2**attempt)
                try:
                    info = await arebuild(transport, plan)
                    break
                except Exception as again:
                    if not is_lost(again):
                        raise
                    failure = again
            else:
                raise failure from None
        self.opened(plan.spec, plan.snapshot, plan.base_frames)
        return info

    # Calls on a session -------------------------------------------------------------------------
    def call(self, session_id: str, send: Callable[[], T], transport: Transport) -> T:
        """``send()``; if it fails as on a lost replica and the session is kept, rebuild it
        (once for concurrent callers) and send again, ``Replay.attempts`` times at most. Any
        other failure, or a session that cannot be rebuilt, raises the original error."""
        kept = self._get(session_id)
        generation = kept.generation if kept else 0
        try:
            return send()
        except Exception as error:
            if getattr(error, "ended", None):
                self.forget(session_id)  # it ended on the service: nothing to rebuild, ever
            if kept is None or not is_lost(error):
                raise
            failure: Exception = error
        assert self.replay is not None
        for attempt in range(self.replay.attempts):
            plan = self._plan(kept)
            if plan is None or self._get(session_id) is not kept:
                raise failure
            try:
                with kept.rebuilding:
                    if kept.generation == generation:  # nobody rebuilt it since it failed
                        rebuild(transport, plan)
                        kept.generation += 1
                        self.rebuilds += 1
                    generation = kept.generation
                return send()
            except Exception as error:
                if not is_lost(error):
                    raise
                failure = error
            time.sleep(self.replay.backoff_s * 2**attempt)
        raise failure

    async def acall(self, session_id: str, send: Callable[[], Awaitable[T]], transport: AsyncTransport) -> T:
        """As ``call``, for the asyncio client."""
        kept = self._get(session_id)
        generation = kept.generation if kept else 0
        try:
            return await send()
        except Exception as error:
            if getattr(error, "ended", None):
                self.forget(session_id)
            if kept is None or not is_lost(error):
                raise
            failure: Exception = error
        assert self.replay is not None
        for attempt in range(self.replay.attempts):
            plan = self._plan(kept)
            if plan is None or self._get(session_id) is not kept:
                raise failure
            kept.rebuilding_async = kept.rebuilding_async or asyncio.Lock()
            try:
                async with kept.rebuilding_async:
                    if kept.generation == generation:
                        await arebuild(transport, plan)
                        kept.generation += 1
                        self.rebuilds += 1
                    generation = kept.generation
                return await send()
            except Exception as error:
                if not is_lost(error):
                    raise
                failure = error
            await asyncio.sleep(self.replay.backoff_s * 2**attempt)
        raise failure
