"""Sessions: one fused scene each, guarded by a lock, expiring after a TTL."""

from __future__ import annotations

import threading
import time
import uuid
from collections import OrderedDict
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

from service.cloud_fusion import CloudFusion, shared_fusion
from service.errors import CapacityExceeded, SessionExists, SessionNotFound
from service.snapshot import Snapshot
from service.tsdf import SceneVolume
from vgn_contract.gripper_description import GripperDescription, default_gripper
from vgn_contract.schemas import Intrinsics, SessionCreate, SessionInfo, Workspace


@dataclass
class Session:
    """A workspace being fused. Mutate it only while holding ``lock`` (see ``SessionStore.use``)."""

    session_id: str
    workspace: Workspace
    intrinsics: Intrinsics | None
    volume: SceneVolume
    created_at: float
    last_used_at: float
    frame_count: int = 0
    integration_ms: float = 0.0
    users: int = 0  # requests holding or waiting for the session; only idle ones are evicted
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False)
    #: Bumped by every change of the volume (frame, reset): what a kept network output is for.
    revision: int = 0
    #: ((revision, turn averaging), output) of the last forward pass on this session's grid,
    #: reused until the volume changes (planning again without a new frame costs detection only).
    network_output: tuple[tuple[int, bool], Any] | None = field(default=None, repr=False)
    #: The hand the session plans for: the one its clearance and grip checks measure.
    hand: GripperDescription = field(default_factory=default_gripper, repr=False)

    def reset(self) -> None:
        """Empty the volume and its counts; a kept network output no longer applies."""
        self.volume.reset()
        self.frame_count = 0
        self.integration_ms = 0.0
        self.revision += 1
        self.network_output = None

    def fused_frame(self, elapsed_ms: float) -> None:
        """Account for a frame just fused into the volume."""
        self.frame_count += 1
        self.integration_ms += elapsed_ms
        self.revision += 1
        self.network_output = None

    def info(self, ttl_s: float) -> SessionInfo:
        """The session as the API reports it, expiring ``ttl_s`` after its last use."""
        return SessionInfo(
            session_id=self.session_id,
            workspace=self.workspace,
            intrinsics=self.intrinsics,
            frame_count=self.frame_count,
            integration_ms=round(self.integration_ms, 3),
            created_at=self.created_at,
            last_used_at=self.last_used_at,
            expires_at=self.last_used_at + ttl_s,
            decay=self.volume.decay,
            gripper=self.hand.name,
        )


#: What a request on an ended session is told, by how it ended.
ENDED_MESSAGES = {
    "deleted": "session {id!r} was deleted",
    "expired": "session {id!r} expired after {ttl:g} s idle",
    "evicted": "session {id!r} was evicted to make room for a new one (VGN_MAX_SESSIONS={limit})",
    "closed": "session {id!r} ended with the service",
}
#: Ended sessions a store remembers, so that it can tell "ended here" from "never here".
ENDED_KEPT = 4096


class SessionStore:
    """Thread-safe registry of sessions with a TTL and a size limit.

    At the limit, creating a session evicts the least recently used *idle* one; when every
    session is in use the creation fails with ``CapacityExceeded``.
    """

    def __init__(
        self,
        max_sessions: int,
        ttl_s: float,
        cloud_resolution: int,
        cloud_max_pending: int = 512,
        clock: Callable[[], float] = time.time,
        cloud_fusion: CloudFusion | None = None,
        register_scale: bool = False,
    ) -> None:
        self.max_sessions = max_sessions
        self._register_scale = register_scale
        self.ttl_s = ttl_s
        self._cloud_resolution = cloud_resolution
        self._cloud_max_pending = cloud_max_pending
        self.cloud_fusion = cloud_fusion or shared_fusion()
        self._clock = clock
        self._sessions: OrderedDict[str, Session] = OrderedDict()  # least recently used first
        #: How recently ended sessions ended, by id, oldest first (``ENDED_KEPT`` at most).
        self._ended: OrderedDict[str, str] = OrderedDict()
        self._lock = threading.Lock()

    def create(
        self, spec: SessionCreate, snapshot: Snapshot | None = None, hand: GripperDescription | None = None
    ) -> Session:
        """Register a new session for ``hand`` (default: the default gripper), dropping expired
        ones first and evicting the least recently used idle one at the limit. With a ``snapshot``
        (whose settings ``spec`` carries) the session starts from its volumes and counts, never
        visible half restored."""
        now = self._clock()
        workspace = spec.workspace
        volume = SceneVolume(
            workspace.size,
            workspace.resolution,
            workspace.pose.as_matrix(),
            self._cloud_resolution,
            self._cloud_max_pending,
            self.cloud_fusion,
            spec.decay,
            self._register_scale,
        )
        if snapshot is not None:
            volume.restore(snapshot.coarse, snapshot.fine)
        with self._lock:
            self._drop_expired(now)
            session_id = spec.session_id or uuid.uuid4().hex
            if session_id in self._sessions:
                raise SessionExists(f"session {session_id!r} already exists")
            if len(self._sessions) >= self.max_sessions:
                self._evict_one()
            self._ended.pop(session_id, None)
            session = Session(
                session_id, workspace, spec.intrinsics, volume, now, now, hand=hand or default_gripper()
            )
            if snapshot is not None:
                session.frame_count, session.integration_ms = snapshot.frame_count, snapshot.integration_ms
            self._sessions[session_id] = session
            return session

    @contextmanager
    def use(self, session_id: str) -> Iterator[Session]:
        """Hold a session exclusively: others wait for it, and neither eviction nor expiry
        takes it meanwhile (an explicit delete does; the holder finishes on its own copy)."""
        with self._lock:
            session = self._live(session_id, self._clock())
            session.users += 1
        try:
            with session.lock:
                yield session
        finally:
            with self._lock:
                session.users -= 1
                session.last_used_at = self._clock()
                if session_id in self._sessions:
                    self._sessions.move_to_end(session_id)

    def info(self, session_id: str) -> SessionInfo:
        """A live session's state; ``SessionNotFound`` for an unknown or expired id."""
        with self._lock:
            return self._live(session_id, self._clock()).info(self.ttl_s)

    def hand(self, session_id: str) -> GripperDescription:
        """The hand a live session plans for (it never changes); ``SessionNotFound`` as ``info``."""
        with self._lock:
            return self._live(session_id, self._clock()).hand

    def list(self) -> list[SessionInfo]:
        """Every live session, least recently used first, after dropping the expired."""
        with self._lock:
            self._drop_expired(self._clock())
            return [s.info(self.ttl_s) for s in self._sessions.values()]

    def delete(self, session_id: str) -> None:
        """Remove a live session now, even one in use; ``SessionNotFound`` if it is already gone."""
        with self._lock:
            self._live(session_id, self._clock())
            self._remove(session_id, "deleted")

    def sweep(self) -> int:
        """Drop expired sessions; returns how many went."""
        with self._lock:
            return self._drop_expired(self._clock())

    def close(self) -> None:
        """Drop every session and stop the cloud worker (the service shuts down)."""
        with self._lock:
            for session_id in list(self._sessions):
                self._remove(session_id, "closed")
        self.cloud_fusion.close()

    def __len__(self) -> int:
        return len(self._sessions)

    # Helpers below expect self._lock to be held.
    def _live(self, session_id: str, now: float) -> Session:
        session = self._sessions.get(session_id)
        if session is None:
            ended = self._ended.get(session_id)
            raise SessionNotFound(ENDED_MESSAGES.get(ended, "session {id!r} does not exist").format(
                id=session_id, ttl=self.ttl_s, limit=self.max_sessions), ended)  # fmt: skip
        if self._expired(session, now):
            self._remove(session_id, "expired")
            raise SessionNotFound(f"session {session_id!r} expired after {self.ttl_s:g} s idle", "expired")
        return session

    def _expired(self, session: Session, now: float) -> bool:
        return session.users == 0 and now - session.last_used_at > self.ttl_s

    def _drop_expired(self, now: float) -> int:
        expired = [sid for sid, s in self._sessions.items() if self._expired(s, now)]
        for session_id in expired:
            self._remove(session_id, "expired")
        return len(expired)

    def _remove(self, session_id: str, how: str) -> None:
        """Forget a session, remembering ``how`` it ended, and free the frames it queued for its
        cloud (a request still holding it finishes on its own copy)."""
        self._sessions.pop(session_id).volume.close()
        self._ended[session_id] = how
        self._ended.move_to_end(session_id)
        if len(self._ended) > ENDED_KEPT:
            self._ended.popitem(last=False)

    def _evict_one(self) -> None:
        for session_id, session in self._sessions.items():  # least recently used first
            if session.users == 0:
                self._remove(session_id, "evicted")
                return
        raise CapacityExceeded(
            f"the session limit ({self.max_sessions}) is reached and every session is in use; "
            "delete a session or retry later"
        )
