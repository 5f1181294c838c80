"""Typed Python clients (sync and async) for the grasp-planning API.

Both clients share the request builders and response parsers below, so they only differ in
how they send a request. Neither needs torch, open3d or pybullet.

    with VGNClient("http://127.0.0.1:8000") as vgn:
        session = vgn.create_session(intrinsics=Intrinsics(width=640, height=480, fx=540, fy=540, cx=320, cy=240))
        vgn.add_frame(session.session_id, depth, camera_pose)   # depth (H, W) metres, pose 4x4 camera->world
        best = vgn.grasps(session.session_id).grasps[0]
"""

from __future__ import annotations

import contextlib
import io
import time
from collections.abc import Awaitable, Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, Generic, TypeVar

import httpx
import numpy as np
from pydantic import ValidationError

from client.recovery import DEFAULT_REPLAY, Rebuild, Replay, SessionJournal, is_lost, new_session_id
from vgn_contract.schemas import (
    SESSION_ID_HEADER,
    FrameMeta,
    FrameResult,
    GraspQuery,
    GraspResult,
    GripperList,
    Intrinsics,
    ModelInfo,
    Pose,
    Readiness,
    SessionCreate,
    SessionInfo,
    SessionList,
    Workspace,
)
from vgn_contract.snapshot import MEDIA_TYPE as SNAPSHOT_MEDIA_TYPE
from vgn_contract.snapshot import meta_of

T = TypeVar("T")
DEFAULT_URL = "http://127.0.0.1:8000"


class VGNError(Exception):
    """The service answered with an error; ``status`` and ``detail`` say what and why.
    ``from_service`` is False for an answer without the service's JSON body: a proxy's own
    (a 502 or 503 while a replica is gone). ``ended`` says how a session this service held
    ended ("deleted", "expired", "evicted"), for a 404 about one."""

    def __init__(
        self,
        status: int,
        detail: Any,
        message: str | None = None,
        from_service: bool = True,
        ended: str | None = None,
    ) -> None:
        self.status, self.detail, self.from_service, self.ended = status, detail, from_service, ended
        super().__init__(f"HTTP {status}: {message or detail}")


class BadRequest(VGNError):
    """400/415/422: the request was malformed; nothing changed on the service."""


class InvalidRequest(BadRequest, ValueError):
    """Refused by the client before anything was sent, for what the service would refuse with
    422 (``status``); ``field`` names the bad argument. Also a ``ValueError``, which these errors
    were before they were typed."""

    def __init__(self, field: str, problem: str) -> None:
        super().__init__(422, f"{field}: {problem}")
        self.field = field
        self.args = (f"{field}: {problem}",)  # not "HTTP 422": nothing went over HTTP


def invalid_request(error: ValidationError, name: str, of_arguments: bool = False) -> InvalidRequest:
    """``InvalidRequest`` for a failed model check, named by where its first error lies: below
    ``name``, or alone when the model's fields are the call's own arguments (``of_arguments``);
    a rule of the whole model is named ``name``."""
    first = error.errors()[0]
    parts = first["loc"] if of_arguments else (name, *first["loc"])
    problem = first["msg"].removeprefix("Value error, ")
    if len(error.errors()) > 1:
        problem += f" (and {len(error.errors()) - 1} more)"
    return InvalidRequest(".".join(str(part) for part in parts) or name, problem)


@contextlib.contextmanager
def refused_as(name: str, of_arguments: bool = False) -> Iterator[None]:
    """Turn a ``ValueError`` from checking ``name`` into ``InvalidRequest`` (see ``invalid_request``)."""
    try:
        yield
    except InvalidRequest:
        raise
    except ValidationError as error:
        raise invalid_request(error, name, of_arguments) from None
    except ValueError as error:
        raise InvalidRequest(name, str(error)) from None


class Unauthorized(VGNError):
    """401: the API key is missing or wrong."""


class NotFound(VGNError):
    """404: unknown (or expired) session."""


class Conflict(VGNError):
    """409: a session with that id exists already."""


class PayloadTooLarge(VGNError):
    """413: the body exceeds the service's VGN_MAX_FRAME_BYTES."""


class ServiceUnavailable(VGNError):
    """503: no model loaded, or the session limit is reached with every session busy."""


_ERROR_TYPES = {
    400: BadRequest,
    401: Unauthorized,
    404: NotFound,
    409: Conflict,
    413: PayloadTooLarge,
    415: BadRequest,
    422: BadRequest,
    503: ServiceUnavailable,
}


def raise_for_error(response: httpx.Response) -> httpx.Response:
    if response.is_success:
        return response
    try:
        body = response.json()
        detail, message, from_service = body.get("detail", body), body.get("message"), "detail" in body
        ended = body.get("ended")
    except (ValueError, AttributeError):
        detail, message, from_service, ended = response.text, None, False, None
    kind = _ERROR_TYPES.get(response.status_code, VGNError)
    raise kind(response.status_code, detail, message, from_service, ended)


@dataclass
class Call(Generic[T]):
    """One API call: what to send and how to read the answer."""

    method: str
    path: str
    parse: Callable[[httpx.Response], T]
    kwargs: dict[str, Any] = field(default_factory=dict)

    def routed(self, session_id: str) -> Call[T]:
        """This call with the session's id in ``X-Session-Id``, which a proxy routes by."""
        headers = {**self.kwargs.get("headers", {}), SESSION_ID_HEADER: session_id}
        return Call(self.method, self.path, self.parse, {**self.kwargs, "headers": headers})


def _model(kind: type[T]) -> Callable[[httpx.Response], T]:
    return lambda response: kind.model_validate_json(response.content)  # type: ignore[attr-defined]


def _npy(response: httpx.Response) -> np.ndarray:
    return np.load(io.BytesIO(response.content), allow_pickle=False)


def as_pose(pose: Pose | np.ndarray | dict) -> Pose:
    """A ``Pose`` from a Pose, a 4×4 matrix or a dict (checked for rigidity and unit quaternions)."""
    if isinstance(pose, Pose):
        return pose
    if isinstance(pose, dict):
        return Pose.model_validate(pose)
    return Pose.from_matrix(np.asarray(pose))


def encode_depth(depth: np.ndarray | bytes) -> tuple[bytes, str, str]:
    """(body, filename, media type) of a depth image.

    float arrays (metres, NaN/0 = no reading) go raw as little-endian float32; uint16 arrays
    are PNG-encoded (needs Pillow); bytes are taken as an already encoded 16-bit PNG.
    """
    if isinstance(depth, bytes | bytearray):
        return bytes(depth), "depth.png", "image/png"
    array = np.asarray(depth)
    if array.ndim != 2:
        raise InvalidRequest("depth", f"must be a 2-D (H, W) array, got shape {array.shape}")
    if array.dtype == np.uint16:
        try:
            from PIL import Image
        except ImportError as error:
            raise ImportError("encoding uint16 depth as PNG needs Pillow (pip install pillow)") from error
        buffer = io.BytesIO()
        Image.fromarray(array).save(buffer, format="PNG", compress_level=1)  # 2x faster, still ~5 KB
        return buffer.getvalue(), "depth.png", "image/png"
    if not np.issubdtype(array.dtype, np.floating):
        raise InvalidRequest("depth", f"must be float metres or uint16 PNG units, got dtype {array.dtype}")
    return np.ascontiguousarray(array, dtype="<f4").tobytes(), "depth.raw", "application/octet-stream"


def frame_meta(
    camera_pose: Pose | np.ndarray | dict,
    intrinsics: Intrinsics | None,
    depth_scale: float,
    max_depth: float,
) -> FrameMeta:
    """A frame's meta, checked as the service checks it; ``InvalidRequest`` names what is wrong."""
    with refused_as("camera_pose"):
        pose = as_pose(camera_pose)
    with refused_as("frame", of_arguments=True):
        return FrameMeta(
            camera_pose=pose, intrinsics=intrinsics, depth_scale=depth_scale, max_depth=max_depth
        )


def grasp_query(options: dict[str, Any]) -> GraspQuery:
    """A grasp request's options, checked as the service checks them; ``InvalidRequest`` names
    the option that is wrong."""
    with refused_as("grasp query", of_arguments=True):
        return GraspQuery(**options)


#: Header carrying a frame's meta JSON when the body is the bare depth image.
FRAME_META_HEADER = "X-Frame-Meta"


class Calls:
    """Request builders for every endpoint; shared by the sync and async clients."""

    @staticmethod
    def create_session(spec: SessionCreate) -> Call[SessionInfo]:
        call = Call("POST", "/sessions", _model(SessionInfo), {"json": spec.model_dump(mode="json")})
        return call.routed(spec.session_id) if spec.session_id else call

    @staticmethod
    def import_session(snapshot: bytes, session_id: str) -> Call[SessionInfo]:
        kwargs = {"content": snapshot, "headers": {"Content-Type": SNAPSHOT_MEDIA_TYPE}}
        return Call("PUT", f"/sessions/{session_id}/snapshot", _model(SessionInfo), kwargs).routed(session_id)

    @staticmethod
    def snapshot(session_id: str) -> Call[bytes]:
        return Call("GET", f"/sessions/{session_id}/snapshot", lambda r: r.content).routed(session_id)

    @staticmethod
    def add_frame(
        session_id: str,
        depth: np.ndarray | bytes,
        camera_pose: Pose | np.ndarray,
        intrinsics: Intrinsics | None = None,
        depth_scale: float = 1000.0,
        max_depth: float = 2.0,
    ) -> Call[FrameResult]:
        meta = frame_meta(camera_pose, intrinsics, depth_scale, max_depth)
        body, _, media_type = encode_depth(depth)
        # The bare image as the body and the meta in a header: no multipart to build or parse.
        headers = {"Content-Type": media_type, FRAME_META_HEADER: meta.model_dump_json()}
        return Call(
            "POST",
            f"/sessions/{session_id}/frames",
            _model(FrameResult),
            {"content": body, "headers": headers},
        ).routed(session_id)

    @staticmethod
    def grasps(session_id: str, **options: Any) -> Call[GraspResult]:
        params = grasp_query(options).to_params()
        return Call("GET", f"/sessions/{session_id}/grasps", _model(GraspResult), {"params": params}).routed(
            session_id
        )

    @staticmethod
    def view_page(session_id: str, refresh: float = 0.0, **options: Any) -> Call[str]:
        params = {**grasp_query(options).to_params(), "refresh": refresh, "standalone": "true"}
        return Call("GET", f"/sessions/{session_id}/view", lambda r: r.text, {"params": params}).routed(
            session_id
        )

    @staticmethod
    def cloud(session_id: str) -> Call[np.ndarray]:
        return Call(
            "GET", f"/sessions/{session_id}/cloud", _npy, {"headers": {"Accept": "application/x-npy"}}
        ).routed(session_id)

    session = staticmethod(lambda sid: Call("GET", f"/sessions/{sid}", _model(SessionInfo)).routed(sid))
    sessions = staticmethod(lambda: Call("GET", "/sessions", _model(SessionList)))
    delete_session = staticmethod(lambda sid: Call("DELETE", f"/sessions/{sid}", lambda r: None).routed(sid))
    reset_session = staticmethod(
        lambda sid: Call("POST", f"/sessions/{sid}/reset", _model(SessionInfo)).routed(sid)
    )
    tsdf = staticmethod(lambda sid: Call("GET", f"/sessions/{sid}/tsdf", _npy).routed(sid))
    model = staticmethod(lambda: Call("GET", "/model", _model(ModelInfo)))
    grippers = staticmethod(lambda: Call("GET", "/grippers", _model(GripperList)))
    health = staticmethod(lambda: Call("GET", "/healthz", lambda r: r.json()))
    metrics = staticmethod(lambda: Call("GET", "/metrics", lambda r: r.text))


def session_spec(
    session_id: str | None,
    workspace: Workspace | None,
    intrinsics: Intrinsics | None,
    decay: float | None = None,
    gripper: str | None = None,
) -> SessionCreate:
    """A session's creation request, checked; its id the one given or one this client picks."""
    with refused_as("session", of_arguments=True):
        return SessionCreate(
            session_id=session_id or new_session_id(),
            workspace=workspace or Workspace(),
            intrinsics=intrinsics,
            decay=decay,
            **({} if gripper is None else {"gripper": gripper}),
        )


def import_plan(snapshot: bytes, session_id: str | None) -> Rebuild:
    """What opens a session from ``snapshot`` (under ``session_id`` or the snapshot's own id)."""
    with refused_as("snapshot"):
        meta = meta_of(snapshot)
    with refused_as("snapshot", of_arguments=True):
        spec = SessionCreate(
            session_id=session_id or meta.get("session_id"),
            workspace=meta.get("workspace"),
            intrinsics=meta.get("intrinsics"),
            **({"gripper": meta["gripper"]} if meta.get("gripper") is not None else {}),
        )
    return Rebuild(spec, snapshot, int(meta.get("frame_count") or 0), [])


class _Transport:
    """The calls that rebuild a lost session (``client.recovery``), over this client's ``run``."""

    def __init__(self, run: Callable[[Call[Any]], Any]) -> None:
        self._run = run

    def open(self, plan: Rebuild) -> SessionInfo:
        if plan.snapshot is not None:
            return self._run(Calls.import_session(plan.snapshot, plan.spec.session_id or ""))
        return self._run(Calls.create_session(plan.spec))

    def delete(self, session_id: str) -> None:
        self._run(Calls.delete_session(session_id))

    def replay(self, session_id: str, frame: Call[Any]) -> None:
        self._run(frame)


class _AsyncTransport:
    """``_Transport`` for the asyncio client."""

    def __init__(self, run: Callable[[Call[Any]], Awaitable[Any]]) -> None:
        self._run = run

    async def open(self, plan: Rebuild) -> SessionInfo:
        if plan.snapshot is not None:
            return await self._run(Calls.import_session(plan.snapshot, plan.spec.session_id or ""))
        return await self._run(Calls.create_session(plan.spec))

    async def delete(self, session_id: str) -> None:
        await self._run(Calls.delete_session(session_id))

    async def replay(self, session_id: str, frame: Call[Any]) -> None:
        await self._run(frame)


def _readiness(response: httpx.Response) -> Readiness:
    if response.status_code in (200, 503):
        return Readiness.model_validate_json(response.content)
    raise_for_error(response)
    raise AssertionError("unreachable")


def _headers(api_key: str | None) -> dict[str, str]:
    return {"X-API-Key": api_key} if api_key else {}


class VGNClient:
    """Blocking client. Use as a context manager, or call ``close()``.

    Sessions it opens survive a lost replica behind a proxy: it keeps each session's frames
    since its last reset, within ``replay``'s bounds, and rebuilds a session it finds gone
    (``client.recovery``); ``replay=None`` keeps nothing and raises as the service answers.
    """

    def __init__(
        self,
        url: str = DEFAULT_URL,
        api_key: str | None = None,
        timeout: float = 30.0,
        http: httpx.Client | None = None,
        replay: Replay | None = DEFAULT_REPLAY,
    ) -> None:
        self.url = url.rstrip("/")
        self._http = http or httpx.Client(base_url=self.url, headers=_headers(api_key), timeout=timeout)
        self._journal = SessionJournal(replay)
        self._transport = _Transport(self._run)

    def _run(self, call: Call[T]) -> T:
        return call.parse(raise_for_error(self._http.request(call.method, call.path, **call.kwargs)))

    @property
    def rebuilds(self) -> int:
        """Sessions this client rebuilt after finding them lost with their replica."""
        return self._journal.rebuilds

    def _on_session(self, session_id: str, call: Call[T]) -> T:
        """``call``, rebuilding the session first if it was lost with its replica."""
        return self._journal.call(session_id, lambda: self._run(call), self._transport)

    def health(self) -> dict:
        """The ``/healthz`` body: answers as soon as the process is up, model or not."""
        return self._run(Calls.health())

    def model(self) -> ModelInfo:
        """Which weights the service runs, on which device, and their operating threshold."""
        return self._run(Calls.model())

    def grippers(self) -> GripperList:
        """The hands the service knows, each with the network that plans for it (or none)."""
        return self._run(Calls.grippers())

    def metrics(self) -> str:
        """The Prometheus text exposition, for scraping by hand or in tests."""
        return self._run(Calls.metrics())

    def sessions(self) -> SessionList:
        """Every live session, with the service's session limit."""
        return self._run(Calls.sessions())

    def session(self, session_id: str) -> SessionInfo:
        """A session's workspace, intrinsics and frame count; ``NotFound`` once it expired."""
        return self._on_session(session_id, Calls.session(session_id))

    def delete_session(self, session_id: str) -> None:
        """Drop a session and free its volume; ``NotFound`` if it is already gone (unless this
        client opened it and it went with a lost replica: gone either way)."""
        kept = self._journal.forget(session_id)
        try:
            self._run(Calls.delete_session(session_id))
        except Exception as error:
            if not (kept and is_lost(error)):
                raise

    def reset_session(self, session_id: str) -> SessionInfo:
        """Empty a session's volume but keep its id and workspace, for a new scene."""
        info = self._on_session(session_id, Calls.reset_session(session_id))
        self._journal.reset(session_id)
        return info

    def tsdf(self, session_id: str) -> np.ndarray:
        """The fused (N, N, N) float32 grid the network reads, indexed [x, y, z] in the workspace frame."""
        return self._on_session(session_id, Calls.tsdf(session_id))

    def cloud(self, session_id: str) -> np.ndarray:
        """Surface points and outward normals, (M, 6) float32 in the world frame."""
        return self._on_session(session_id, Calls.cloud(session_id))

    def snapshot(self, session_id: str) -> bytes:
        """The session as one compact file (settings, frame count, fused volumes; ``vgn_contract.snapshot``),
        for ``import_session`` here or on another service."""
        return self._on_session(session_id, Calls.snapshot(session_id))

    def import_session(self, snapshot: bytes, session_id: str | None = None) -> SessionInfo:
        """Open a session from a ``snapshot()``, under its own id or ``session_id``; ``Conflict``
        when the id is taken, ``BadRequest`` for a damaged file."""
        return self._journal.open(self._transport, import_plan(snapshot, session_id))

    def ready(self) -> Readiness:
        """Readiness without raising on 503 (``ready`` is False then, with the reason)."""
        return _readiness(self._http.get("/readyz"))

    def create_session(
        self,
        session_id: str | None = None,
        workspace: Workspace | None = None,
        intrinsics: Intrinsics | None = None,
        decay: float | None = None,
        gripper: str | None = None,
    ) -> SessionInfo:
        """Open a session under ``session_id``, or under an id this client picks (a uuid4 hex);
        ``Conflict`` when the id is taken. With ``decay`` (0-1) the session follows a changing
        scene: each frame first weighs the evidence of earlier frames where it sees again by it.
        ``gripper`` names the hand it plans for (``grippers()`` lists them; default ``franka``)."""
        spec = session_spec(session_id, workspace, intrinsics, decay, gripper)
        return self._journal.open(self._transport, Rebuild(spec, None, 0, []))

    def add_frame(
        self,
        session_id: str,
        depth: np.ndarray | bytes,
        camera_pose: Pose | np.ndarray,
        intrinsics: Intrinsics | None = None,
        depth_scale: float = 1000.0,
        max_depth: float = 2.0,
    ) -> FrameResult:
        """Fuse a depth image: float (H, W) metres, uint16 PNG units, or PNG bytes;
        ``camera_pose`` camera→world (OpenCV optical frame)."""
        call = Calls.add_frame(session_id, depth, camera_pose, intrinsics, depth_scale, max_depth)
        result = self._on_session(session_id, call)
        self._journal.fused(session_id, call, len(call.kwargs["content"]))
        return result

    def grasps(self, session_id: str, **options: Any) -> GraspResult:
        """Ranked grasps; options are ``GraspQuery`` fields (threshold, max_grasps, ...)."""
        return self._on_session(session_id, Calls.grasps(session_id, **options))

    def view_page(self, session_id: str, refresh: float = 0.0, **options: Any) -> str:
        """The session viewer's self-contained HTML (3D surface, workspace and grasps); options are
        ``GraspQuery`` fields, ``refresh`` the seconds between its checks for new frames (0: a snapshot)."""
        return self._on_session(session_id, Calls.view_page(session_id, refresh, **options))

    def wait_until_up(self, timeout: float = 60.0) -> None:
        """Block until ``/healthz`` answers (for a service that is still starting)."""
        deadline = time.monotonic() + timeout
        while True:
            try:
                self.health()
                return
            except httpx.TransportError:
                if time.monotonic() > deadline:
                    raise TimeoutError(f"no service answered at {self.url} within {timeout:g} s") from None
                time.sleep(0.1)

    def close(self) -> None:
        """Close the connection pool, a passed-in ``http`` client included."""
        self._http.close()

    def __enter__(self) -> VGNClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class AsyncVGNClient:
    """Asyncio client with the same methods as ``VGNClient``, as coroutines (lost sessions included)."""

    def __init__(
        self,
        url: str = DEFAULT_URL,
        api_key: str | None = None,
        timeout: float = 30.0,
        http: httpx.AsyncClient | None = None,
        replay: Replay | None = DEFAULT_REPLAY,
    ) -> None:
        self.url = url.rstrip("/")
        self._http = http or httpx.AsyncClient(base_url=self.url, headers=_headers(api_key), timeout=timeout)
        self._journal = SessionJournal(replay)
        self._transport = _AsyncTransport(self._run)

    async def _run(self, call: Call[T]) -> T:
        return call.parse(raise_for_error(await self._http.request(call.method, call.path, **call.kwargs)))

    @property
    def rebuilds(self) -> int:
        """As ``VGNClient.rebuilds``."""
        return self._journal.rebuilds

    async def _on_session(self, session_id: str, call: Call[T]) -> T:
        return await self._journal.acall(session_id, lambda: self._run(call), self._transport)

    async def health(self) -> dict:
        """As ``VGNClient.health``."""
        return await self._run(Calls.health())

    async def model(self) -> ModelInfo:
        """As ``VGNClient.model``."""
        return await self._run(Calls.model())

    async def grippers(self) -> GripperList:
        """As ``VGNClient.grippers``."""
        return await self._run(Calls.grippers())

    async def metrics(self) -> str:
        """As ``VGNClient.metrics``."""
        return await self._run(Calls.metrics())

    async def sessions(self) -> SessionList:
        """As ``VGNClient.sessions``."""
        return await self._run(Calls.sessions())

    async def session(self, session_id: str) -> SessionInfo:
        """As ``VGNClient.session``."""
        return await self._on_session(session_id, Calls.session(session_id))

    async def delete_session(self, session_id: str) -> None:
        """As ``VGNClient.delete_session``."""
        kept = self._journal.forget(session_id)
        try:
            await self._run(Calls.delete_session(session_id))
        except Exception as error:
            if not (kept and is_lost(error)):
                raise

    async def reset_session(self, session_id: str) -> SessionInfo:
        """As ``VGNClient.reset_session``."""
        info = await self._on_session(session_id, Calls.reset_session(session_id))
        self._journal.reset(session_id)
        return info

    async def tsdf(self, session_id: str) -> np.ndarray:
        """As ``VGNClient.tsdf``."""
        return await self._on_session(session_id, Calls.tsdf(session_id))

    async def cloud(self, session_id: str) -> np.ndarray:
        """As ``VGNClient.cloud``."""
        return await self._on_session(session_id, Calls.cloud(session_id))

    async def snapshot(self, session_id: str) -> bytes:
        """As ``VGNClient.snapshot``."""
        return await self._on_session(session_id, Calls.snapshot(session_id))

    async def import_session(self, snapshot: bytes, session_id: str | None = None) -> SessionInfo:
        """As ``VGNClient.import_session``."""
        return await self._journal.aopen(self._transport, import_plan(snapshot, session_id))

    async def ready(self) -> Readiness:
        """As ``VGNClient.ready``: a 503 is an answer, not an error."""
        return _readiness(await self._http.get("/readyz"))

    async def create_session(
        self,
        session_id: str | None = None,
        workspace: Workspace | None = None,
        intrinsics: Intrinsics | None = None,
        decay: float | None = None,
        gripper: str | None = None,
    ) -> SessionInfo:
        """As ``VGNClient.create_session``."""
        spec = session_spec(session_id, workspace, intrinsics, decay, gripper)
        return await self._journal.aopen(self._transport, Rebuild(spec, None, 0, []))

    async def add_frame(
        self,
        session_id: str,
        depth: np.ndarray | bytes,
        camera_pose: Pose | np.ndarray,
        intrinsics: Intrinsics | None = None,
        depth_scale: float = 1000.0,
        max_depth: float = 2.0,
    ) -> FrameResult:
        """As ``VGNClient.add_frame``."""
        call = Calls.add_frame(session_id, depth, camera_pose, intrinsics, depth_scale, max_depth)
        result = await self._on_session(session_id, call)
        self._journal.fused(session_id, call, len(call.kwargs["content"]))
        return result

    async def grasps(self, session_id: str, **options: Any) -> GraspResult:
        """As ``VGNClient.grasps``."""
        return await self._on_session(session_id, Calls.grasps(session_id, **options))

    async def view_page(self, session_id: str, refresh: float = 0.0, **options: Any) -> str:
        """As ``VGNClient.view_page``."""
        return await self._on_session(session_id, Calls.view_page(session_id, refresh, **options))

    async def aclose(self) -> None:
        """Close the connection pool (the async counterpart of ``close``)."""
        await self._http.aclose()

    async def __aenter__(self) -> AsyncVGNClient:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.aclose()


__all__ = [
    "AsyncVGNClient",
    "BadRequest",
    "Conflict",
    "InvalidRequest",
    "NotFound",
    "PayloadTooLarge",
    "ServiceUnavailable",
    "Unauthorized",
    "VGNClient",
    "VGNError",
]
