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

from client.grpc_api import convert
from client.grpc_api import grasp_planning_pb2 as pb
from client.grpc_api.grasp_planning_pb2_grpc import GraspPlanningStub
from client.http import _ERROR_TYPES, VGNError, encode_depth, frame_meta, grasp_query
from client.schemas import (
    FrameResult,
    GraspResult,
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
    result = _ERROR_TYPES.get(status, VGNError)(status, detail)
    result.args = (f"gRPC {code.name} (HTTP {status}): {detail}",)
    result.grpc_code = code  # type: ignore[attr-defined]
    return result


class GRPCClient:
    """Blocking gRPC client. Use as a context manager, or call ``close()``."""

    def __init__(
        self, url: str = DEFAULT_GRPC_URL, api_key: str | None = None, timeout: float = 30.0
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

    def _call(self, method: Callable[..., Any], request: Any, parse: Callable[[Any], T]) -> T:
        try:
            answer = method(request, timeout=self.timeout, metadata=self._metadata)
        except grpc.RpcError as error:
            raise error_of(error) from None
        return parse(answer)

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
    ) -> SessionInfo:
        """As ``VGNClient.create_session``."""
        request = pb.CreateSessionRequest(
            session_id=session_id,
            workspace=convert.workspace_message(workspace or Workspace()),
            intrinsics=convert.intrinsics_message(intrinsics),
            decay=decay,
        )
        return self._call(self._stub.CreateSession, request, convert.session_info)

    def sessions(self) -> SessionList:
        """As ``VGNClient.sessions``."""
        return self._call(self._stub.ListSessions, pb.ListSessionsRequest(), convert.session_list)

    def session(self, session_id: str) -> SessionInfo:
        """As ``VGNClient.session``."""
        return self._call(
            self._stub.GetSession, pb.GetSessionRequest(session_id=session_id), convert.session_info
        )

    def delete_session(self, session_id: str) -> None:
        """As ``VGNClient.delete_session``."""
        self._call(self._stub.DeleteSession, pb.DeleteSessionRequest(session_id=session_id), lambda a: None)

    def reset_session(self, session_id: str) -> SessionInfo:
        """As ``VGNClient.reset_session``."""
        request = pb.ResetSessionRequest(session_id=session_id)
        return self._call(self._stub.ResetSession, request, convert.session_info)

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
        return self._call(self._stub.AddFrame, frame, convert.frame_result)

    def stream_frames(
        self,
        session_id: str,
        frames: Iterable[tuple[np.ndarray | bytes, Pose | np.ndarray]],
        intrinsics: Intrinsics | None = None,
        depth_scale: float = 1000.0,
        max_depth: float = 2.0,
    ) -> StreamResult:
        """Fuse many ``(depth, camera_pose)`` frames in one call; they are encoded as they are
        sent, so ``frames`` may be a generator. The client's ``timeout`` covers the whole stream."""
        local_errors: list[Exception] = []

        def messages() -> Iterator[pb.Frame]:
            try:
                for depth, pose in frames:
                    yield frame_message(session_id, depth, pose, intrinsics, depth_scale, max_depth)
            except Exception as error:  # gRPC would report it as a bare CANCELLED
                local_errors.append(error)
                raise

        try:
            answer = self._stub.StreamFrames(messages(), timeout=self.timeout, metadata=self._metadata)
        except grpc.RpcError as error:
            if local_errors:
                raise local_errors[0] from None
            raise error_of(error) from None
        return StreamResult(
            answer.session_id, answer.frames_received, answer.frame_count, answer.integration_ms
        )

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
        iterator to cancel it early.
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

        updates = self._stub.Track(messages(), metadata=self._metadata)
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
        return self._call(self._stub.GetGrasps, request, convert.grasp_result)

    def tsdf(self, session_id: str) -> np.ndarray:
        """As ``VGNClient.tsdf``: the (N, N, N) float32 grid."""
        return self._call(
            self._stub.GetGrid,
            pb.GetGridRequest(session_id=session_id),
            lambda grid: convert.float_array(grid.data, tuple(grid.shape)),
        )

    def cloud(self, session_id: str) -> np.ndarray:
        """As ``VGNClient.cloud``: (M, 6) float32 points and normals."""
        return self._call(
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
