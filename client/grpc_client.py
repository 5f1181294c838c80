"""A gRPC client with the methods and return types of ``VGNClient``: ``GRPCClient``.

Needs the ``grpc`` extra (``pip install "vgn-service[grpc]"``); the HTTP client does not.
Errors are the HTTP client's exception types with the same ``status`` as over HTTP, so code
written against ``VGNClient`` works unchanged.

    with GRPCClient("grpc://127.0.0.1:50051") as vgn:
        session = vgn.create_session(intrinsics=intrinsics)
        vgn.stream_frames(session.session_id, zip(depths, poses))   # many frames, one reply
        best = vgn.grasps(session.session_id).grasps[0]
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any, TypeVar
from urllib.parse import urlsplit

import grpc
import numpy as np
from grpc_health.v1 import health_pb2, health_pb2_grpc

from client.http import _ERROR_TYPES, VGNError, encode_depth, frame_meta, grasp_query, session_spec
from client.recovery import DEFAULT_REPLAY, Rebuild, Replay, SessionJournal, is_lost
from vgn_contract.grpc_api import convert
from vgn_contract.grpc_api import grasp_planning_pb2 as pb
from vgn_contract.grpc_api.grasp_planning_pb2_grpc import GraspPlanningStub
from vgn_contract.schemas import (
    SESSION_ID_HEADER,
    FrameResult,
    GraspResult,
    GripperList,
    Intrinsics,
    ModelInfo,
    Pose,
    Readiness,
    SessionInfo,
    SessionList,
    Workspace,
)

T = TypeVar("T")
DEFAULT_GRPC_URL = "grpc://127.0.0.1:50051"
HTTP_STATUS_KEY = "vgn-http-status"
SESSION_ENDED_KEY = "vgn-session-ended"
#: The HTTP status of a gRPC code, when the service did not name one (transport-level errors).
HTTP_STATUS_OF_CODE = {
    grpc.StatusCode.INVALID_ARGUMENT: 400,
    grpc.StatusCode.UNAUTHENTICATED: 401,
    grpc.StatusCode.NOT_FOUND: 404,
    grpc.StatusCode.ALREADY_EXISTS: 409,
    grpc.StatusCode.RESOURCE_EXHAUSTED: 413,
    grpc.StatusCode.UNAVAILABLE: 503,
}
CHANNEL_OPTIONS = [("grpc.max_receive_message_length", -1), ("grpc.max_send_message_length", -1)]
#: Metadata key of the session id on every call about a session (gRPC keys are lower case).
SESSION_ID_KEY = SESSION_ID_HEADER.lower()


@dataclass(frozen=True)
class StreamResult:
    """The one reply to a stream of frames."""

    session_id: str
    frames_received: int
    frame_count: int  # frames fused into the session so far
    integration_ms: float  # total integration time of the stream's frames


def grpc_target(url: str) -> tuple[str, bool]:
    """``host:port`` of a ``grpc://`` (plaintext) or ``grpcs://`` (TLS) URL, and whether TLS."""
    parts = urlsplit(url)
    if parts.scheme not in ("grpc", "grpcs") or not parts.hostname:
        raise ValueError(f"a gRPC URL looks like grpc://HOST:PORT, got {url!r}")
    port = parts.port or 50051
    host = f"[{parts.hostname}]" if ":" in parts.hostname else parts.hostname
    return f"{host}:{port}", parts.scheme == "grpcs"


def error_of(error: grpc.RpcError) -> Exception:
    """The exception the HTTP client would raise for the same failure."""
    code, detail = error.code(), error.details() or ""
    trailing = dict(error.trailing_metadata() or ())
    named = trailing.get(HTTP_STATUS_KEY)
    if code == grpc.StatusCode.DEADLINE_EXCEEDED:
        return TimeoutError(f"gRPC DEADLINE_EXCEEDED: {detail}")
    if code == grpc.StatusCode.UNAVAILABLE and named is None:
        return ConnectionError(f"gRPC UNAVAILABLE: {detail}")
    status = int(named) if named else HTTP_STATUS_OF_CODE.get(code, 500)
    result = _ERROR_TYPES.get(status, VGNError)(status, detail, from_service=named is not None,
                                                ended=trailing.get(SESSION_ENDED_KEY))  # fmt: skip
    result.args = (f"gRPC {code.name} (HTTP {status}): {detail}",)
    result.grpc_code = code  # type: ignore[attr-defined]
    return result


class GRPCClient:
    """Blocking gRPC client. Use as a context manager, or call ``close()``.

    Like ``VGNClient``, it sends the session id with every call about a session
    (``x-session-id`` metadata) and rebuilds a session lost with its replica (``replay``).
    """

    def __init__(
        self,
        url: str = DEFAULT_GRPC_URL,
        api_key: str | None = None,
        timeout: float = 30.0,
        replay: Replay | None = DEFAULT_REPLAY,
    ) -> None:
        self.url = url.rstrip("/")
        target, tls = grpc_target(self.url)
        credentials = grpc.ssl_channel_credentials() if tls else None
        self._channel = (
            grpc.secure_channel(target, credentials, options=CHANNEL_OPTIONS)
            if credentials
            else grpc.insecure_channel(target, options=CHANNEL_OPTIONS)
        )
        self._stub = GraspPlanningStub(self._channel)
        self._health = health_pb2_grpc.HealthStub(self._channel)
        self._metadata = (("x-api-key", api_key),) if api_key else ()
        self.timeout = timeout
        self._journal = SessionJournal(replay)
        self._transport = _Transport(self)

    def _call(
        self,
        method: Callable[..., Any],
        request: Any,
        parse: Callable[[Any], T],
        session_id: str | None = None,
    ) -> T:
        try:
            answer = method(request, timeout=self.timeout, metadata=self._routed(session_id))
        except grpc.RpcError as error:
            raise error_of(error) from None
        return parse(answer)

    @property
    def rebuilds(self) -> int:
        """As ``VGNClient.rebuilds``."""
        return self._journal.rebuilds

    def _routed(self, session_id: str | None) -> tuple[tuple[str, str], ...]:
        """The call's metadata: the API key, and the session id a proxy routes by."""
        return self._metadata + (((SESSION_ID_KEY, session_id),) if session_id else ())

    def _on_session(
        self, session_id: str, method: Callable[..., Any], request: Any, parse: Callable[[Any], T]
    ) -> T:
        """A call about a session, rebuilding the session first if it was lost with its replica."""
        return self._journal.call(
            session_id, lambda: self._call(method, request, parse, session_id), self._transport
        )

    # Service ------------------------------------------------------------------------------
    def health(self) -> dict:
        """``{"status": "ok"}`` once the process answers (no model needed)."""
        self._call(self._health.Check, health_pb2.HealthCheckRequest(), lambda answer: answer)
        return {"status": "ok"}

    def ready(self) -> Readiness:
        """Readiness from the standard health service: SERVING once a model is warm."""
        answer = self._call(self._health.Check, health_pb2.HealthCheckRequest(), lambda a: a)
        if answer.status == health_pb2.HealthCheckResponse.SERVING:
            return Readiness(ready=True, detail="serving (a model is loaded)")
        return Readiness(ready=False, detail="not serving: no model is loaded")

    def model(self) -> ModelInfo:
        """As ``VGNClient.model``."""
        return self._call(self._stub.GetModelInfo, pb.GetModelInfoRequest(), convert.model_info)

    def grippers(self) -> GripperList:
        """As ``VGNClient.grippers``."""
        return self._call(self._stub.ListGrippers, pb.ListGrippersRequest(), convert.gripper_list)

    def metrics(self) -> str:
        """Not over gRPC: metrics are Prometheus text, served by the HTTP front end only."""
        raise NotImplementedError("Prometheus metrics are served over HTTP only: GET /metrics")

    def wait_until_up(self, timeout: float = 60.0) -> None:
        """Block until the service answers (for a service that is still starting)."""
        deadline = time.monotonic() + timeout
        while True:
            try:
                self.health()
                return
            except (ConnectionError, TimeoutError):
                if time.monotonic() > deadline:
                    raise TimeoutError(f"no service answered at {self.url} within {timeout:g} s") from None
                time.sleep(0.1)

    # Sessions -----------------------------------------------------------------------------
    def create_session(
        self,
        session_id: str | None = None,
        workspace: Workspace | None = None,
        intrinsics: Intrinsics | None = None,
        decay: float | None = None,
        gripper: str | None = None,
    ) -> SessionInfo:
        """As ``VGNClient.create_session``."""
        spec = session_spec(session_id, workspace, intrinsics, decay, gripper)
        return self._journal.open(self._transport, Rebuild(spec, None, 0, []))

    def sessions(self) -> SessionList:
        """As ``VGNClient.sessions``."""
        return self._call(self._stub.ListSessions, pb.ListSessionsRequest(), convert.session_list)

    def session(self, session_id: str) -> SessionInfo:
        """As ``VGNClient.session``."""
        request = pb.GetSessionRequest(session_id=session_id)
        return self._on_session(session_id, self._stub.GetSession, request, convert.session_info)

    def delete_session(self, session_id: str) -> None:
        """As ``VGNClient.delete_session``."""
        kept = self._journal.forget(session_id)
        request = pb.DeleteSessionRequest(session_id=session_id)
        try:
            self._call(self._stub.DeleteSession, request, lambda a: None, session_id)
        except Exception as error:
            if not (kept and is_lost(error)):
                raise

    def reset_session(self, session_id: str) -> SessionInfo:
        """As ``VGNClient.reset_session``."""
        request = pb.ResetSessionRequest(session_id=session_id)
        info = self._on_session(session_id, self._stub.ResetSession, request, convert.session_info)
        self._journal.reset(session_id)
        return info

    def snapshot(self, session_id: str) -> bytes:
        """Not over gRPC: snapshots are served by the HTTP front end (``VGNClient.snapshot``)."""
        raise NotImplementedError("session snapshots are served over HTTP only: GET /sessions/{id}/snapshot")

    def import_session(self, snapshot: bytes, session_id: str | None = None) -> SessionInfo:
        """Not over gRPC: snapshots are imported by the HTTP front end (``VGNClient.import_session``)."""
        raise NotImplementedError(
            "session snapshots are imported over HTTP only: PUT /sessions/{id}/snapshot"
        )

    # Frames -------------------------------------------------------------------------------
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
        frame = frame_message(session_id, depth, camera_pose, intrinsics, depth_scale, max_depth)
        result = self._on_session(session_id, self._stub.AddFrame, frame, convert.frame_result)
        self._journal.fused(session_id, frame, frame.ByteSize())
        return result

    def stream_frames(
        self,
        session_id: str,
        frames: Iterable[tuple[np.ndarray | bytes, Pose | np.ndarray]],
        intrinsics: Intrinsics | None = None,
        depth_scale: float = 1000.0,
        max_depth: float = 2.0,
    ) -> StreamResult:
        """Fuse many ``(depth, camera_pose)`` frames in one call; they are encoded as they are
        sent, so ``frames`` may be a generator. The client's ``timeout`` covers the whole stream.
        A stream cut by a lost replica is sent again from its first frame, after the session is
        rebuilt, if its frames fit in the replay bounds."""

        def build(depth: np.ndarray | bytes, pose: Pose | np.ndarray) -> pb.Frame:
            return frame_message(session_id, depth, pose, intrinsics, depth_scale, max_depth)

        stream = _Stream(iter(frames), build, self._journal.replay, lambda: self._journal.give_up(session_id))

        def send() -> StreamResult:
            try:
                answer = self._stub.StreamFrames(
                    stream.messages(), timeout=self.timeout, metadata=self._routed(session_id)
                )
            except grpc.RpcError as error:
                if stream.local_errors:
                    raise stream.local_errors[0] from None
                raise error_of(error) from None
            return StreamResult(
                answer.session_id, answer.frames_received, answer.frame_count, answer.integration_ms
            )

        result = self._journal.call(session_id, send, self._transport)
        for message in stream.sent:
            self._journal.fused(session_id, message, message.ByteSize())
        return result

    def track(
        self,
        session_id: str,
        frames: Iterable[tuple[np.ndarray | bytes, Pose | np.ndarray]],
        plan_every: int = 1,
        intrinsics: Intrinsics | None = None,
        depth_scale: float = 1000.0,
        max_depth: float = 2.0,
        match_distance: float | None = None,
        match_angle: float | None = None,
        **options: Any,
    ) -> Iterator[GraspResult]:
        """Closed loop over one ``Track`` stream: each ``(depth, camera_pose)`` of ``frames`` is
        fused as it is sent and, after every ``plan_every``-th, the current grasps come back,
        each with a ``track_id`` that stays with the same grasp across re-plans (within
        ``match_distance`` m and ``match_angle`` degrees). ``options`` are ``GraspQuery`` fields.

        ``frames`` may be a generator that waits for the camera; the stream has no deadline (the
        client's ``timeout`` does not apply) and ends when ``frames`` does. Close the returned
        iterator to cancel it early. Frames fused by a stream are not kept for a rebuild: a stream
        cut by a lost replica raises, and the caller resets the session and streams anew.
        """
        query = convert.grasp_query_message(session_id, grasp_query(options))
        local_errors: list[Exception] = []

        def messages() -> Iterator[pb.TrackRequest]:
            first = True
            try:
                for depth, pose in frames:
                    frame = frame_message(session_id, depth, pose, intrinsics, depth_scale, max_depth)
                    if first:
                        yield pb.TrackRequest(
                            frame=frame, query=query, plan_every=plan_every,
                            match_distance=match_distance, match_angle=match_angle,
                        )  # fmt: skip
                        first = False
                    else:
                        yield pb.TrackRequest(frame=frame)
            except Exception as error:  # gRPC would report it as a bare CANCELLED
                local_errors.append(error)
                raise

        updates = self._stub.Track(messages(), metadata=self._routed(session_id))
        try:
            for update in updates:
                yield convert.grasp_result(update.result)
        except grpc.RpcError as error:
            if local_errors:
                raise local_errors[0] from None
            raise error_of(error) from None
        finally:
            updates.cancel()

    # Read-outs ----------------------------------------------------------------------------
    def grasps(self, session_id: str, **options: Any) -> GraspResult:
        """Ranked grasps; options are ``GraspQuery`` fields (threshold, max_grasps, planner, ...)."""
        request = convert.grasp_query_message(session_id, grasp_query(options))
        return self._on_session(session_id, self._stub.GetGrasps, request, convert.grasp_result)

    def tsdf(self, session_id: str) -> np.ndarray:
        """As ``VGNClient.tsdf``: the (N, N, N) float32 grid."""
        return self._on_session(
            session_id,
            self._stub.GetGrid,
            pb.GetGridRequest(session_id=session_id),
            lambda grid: convert.float_array(grid.data, tuple(grid.shape)),
        )

    def cloud(self, session_id: str) -> np.ndarray:
        """As ``VGNClient.cloud``: (M, 6) float32 points and normals."""
        return self._on_session(
            session_id,
            self._stub.GetCloud,
            pb.GetCloudRequest(session_id=session_id),
            lambda cloud: convert.float_array(cloud.data, (cloud.count, 6)),
        )

    def close(self) -> None:
        """Close the channel; calls after it fail."""
        self._channel.close()

    def __enter__(self) -> GRPCClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class _Transport:
    """The calls that rebuild a lost session (``client.recovery``), over a ``GRPCClient``."""

    def __init__(self, client: GRPCClient) -> None:
        self._client = client

    def open(self, plan: Rebuild) -> SessionInfo:
        spec, stub = plan.spec, self._client._stub
        request = pb.CreateSessionRequest(
            session_id=spec.session_id,
            workspace=convert.workspace_message(spec.workspace),
            intrinsics=convert.intrinsics_message(spec.intrinsics),
            decay=spec.decay,
            gripper=spec.gripper,
        )
        return self._client._call(stub.CreateSession, request, convert.session_info, spec.session_id)

    def delete(self, session_id: str) -> None:
        request = pb.DeleteSessionRequest(session_id=session_id)
        self._client._call(self._client._stub.DeleteSession, request, lambda a: None, session_id)

    def replay(self, session_id: str, frame: pb.Frame) -> None:
        self._client._call(self._client._stub.AddFrame, frame, lambda a: None, session_id)


class _Stream:
    """The frames of one ``StreamFrames`` call, encoded from the caller's iterable as they are
    sent and kept within the replay bounds, so that a try cut by a lost replica can send them
    again; past the bounds none are kept and ``give_up`` marks the session as not rebuildable."""

    def __init__(
        self,
        source: Iterator[tuple[Any, Any]],
        build: Callable[[Any, Any], pb.Frame],
        replay: Replay | None,
        give_up: Callable[[], None],
    ) -> None:
        self._source, self._build, self._replay, self._give_up = source, build, replay, give_up
        self.sent: list[pb.Frame] = []  # every frame sent so far, while they are kept
        self.kept = replay is not None
        self._nbytes = 0
        self.local_errors: list[Exception] = []

    def messages(self) -> Iterator[pb.Frame]:
        """The frames a try sent before (a retry), then the rest of the caller's."""
        yield from list(self.sent)
        try:
            for depth, pose in self._source:
                message = self._build(depth, pose)
                self._keep(message)
                yield message
        except Exception as error:  # gRPC would report it as a bare CANCELLED
            self.local_errors.append(error)
            raise

    def _keep(self, message: pb.Frame) -> None:
        if not self.kept:
            return
        assert self._replay is not None
        self._nbytes += message.ByteSize()
        if len(self.sent) + 1 > self._replay.max_frames or self._nbytes > self._replay.max_bytes:
            self.sent, self.kept = [], False
            self._give_up()
            return
        self.sent.append(message)


def frame_message(
    session_id: str,
    depth: np.ndarray | bytes,
    camera_pose: Pose | np.ndarray,
    intrinsics: Intrinsics | None,
    depth_scale: float,
    max_depth: float,
) -> pb.Frame:
    """A frame checked as the HTTP client checks its ``meta``, with the same depth encoding."""
    meta = frame_meta(camera_pose, intrinsics, depth_scale, max_depth)
    body, _, media_type = encode_depth(depth)
    return pb.Frame(
        session_id=session_id,
        depth=body,
        encoding=convert.ENCODING_OF_MEDIA_TYPE[media_type],
        camera_pose=convert.pose_message(meta.camera_pose),
        intrinsics=convert.intrinsics_message(meta.intrinsics),
        depth_scale=meta.depth_scale,
        max_depth=meta.max_depth,
    )
