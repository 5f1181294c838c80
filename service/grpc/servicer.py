"""``vgn.v1.GraspPlanning`` over a ``PlanningService``: parse, call the core, encode."""

from __future__ import annotations

from collections.abc import Iterator

import grpc
from pydantic import ValidationError

from client.grpc_api import convert
from client.grpc_api import grasp_planning_pb2 as pb
from client.grpc_api.grasp_planning_pb2_grpc import GraspPlanningServicer
from client.schemas import FrameMeta, FrameResult, GraspQuery, SessionCreate
from service.api.metrics import ServiceMetrics
from service.core import PlanningService
from service.errors import InvalidInput, ServiceError, UnsupportedMediaType
from service.grpc.errors import PayloadTooLarge, rpc, validation_message
from service.grpc.handlers import MalformedRequest


class GraspPlanning(GraspPlanningServicer):
    """The gRPC twin of the HTTP routes; ``metrics`` (the HTTP app's) also counts its work."""

    def __init__(self, core: PlanningService, metrics: ServiceMetrics | None = None) -> None:
        self.core = core
        self.settings = core.settings
        self.metrics = metrics

    @rpc
    def CreateSession(self, request: pb.CreateSessionRequest, context: grpc.ServicerContext) -> pb.Session:
        """``POST /sessions``: the request validated by the same schema as over HTTP."""
        spec = SessionCreate.model_validate(convert.session_create_dict(request))
        return convert.session_message(self.core.create_session(spec))

    @rpc
    def GetSession(self, request: pb.GetSessionRequest, context: grpc.ServicerContext) -> pb.Session:
        """``GET /sessions/{id}``."""
        return convert.session_message(self.core.session_info(request.session_id))

    @rpc
    def ListSessions(
        self, request: pb.ListSessionsRequest, context: grpc.ServicerContext
    ) -> pb.ListSessionsResponse:
        """``GET /sessions``."""
        sessions = [convert.session_message(info) for info in self.core.list_sessions()]
        return pb.ListSessionsResponse(sessions=sessions, max_sessions=self.core.sessions.max_sessions)

    @rpc
    def DeleteSession(
        self, request: pb.DeleteSessionRequest, context: grpc.ServicerContext
    ) -> pb.DeleteSessionResponse:
        """``DELETE /sessions/{id}``."""
        self.core.delete_session(request.session_id)
        return pb.DeleteSessionResponse()

    @rpc
    def ResetSession(self, request: pb.ResetSessionRequest, context: grpc.ServicerContext) -> pb.Session:
        """``POST /sessions/{id}/reset``."""
        return convert.session_message(self.core.reset_session(request.session_id))

    @rpc
    def AddFrame(self, request: pb.Frame, context: grpc.ServicerContext) -> pb.FrameResult:
        """``POST /sessions/{id}/frames``, one frame with its meta in the message."""
        return convert.frame_result_message(self._fuse(request.session_id, request))

    @rpc
    def StreamFrames(
        self, request_iterator: Iterator[pb.Frame], context: grpc.ServicerContext
    ) -> pb.StreamFramesResult:
        """Fuse a stream of one session's frames, each checked as an upload; the first bad frame ends the
        call with its index in the message. A cancelled stream stops at the frame it reached."""
        session_id, received, integration_ms, result = "", 0, 0.0, None
        for index, frame in enumerate(request_iterator):
            if not context.is_active():  # cancelled, or past its deadline
                break
            if isinstance(frame, MalformedRequest):
                raise InvalidInput(f"frame {index}: {frame.describe()}")
            if frame.session_id and session_id and frame.session_id != session_id:
                raise InvalidInput(
                    f"frame {index}: the stream is for session {session_id!r}, this frame names "
                    f"{frame.session_id!r}; one stream carries one session's frames"
                )
            session_id = session_id or frame.session_id
            try:
                result = self._fuse(session_id, frame)
            except ValidationError as error:
                raise InvalidInput(f"frame {index}: {validation_message(error)}") from None
            except ServiceError as error:
                raise type(error)(f"frame {index}: {error}") from None
            received += 1
            integration_ms += result.integration_ms
        return pb.StreamFramesResult(
            session_id=session_id,
            frames_received=received,
            frame_count=result.frame_count if result else 0,
            integration_ms=round(integration_ms, 3),
        )

    @rpc
    def GetGrasps(self, request: pb.GraspQuery, context: grpc.ServicerContext) -> pb.GraspResult:
        """``GET /sessions/{id}/grasps``, counted in the same planning metrics."""
        query = GraspQuery.model_validate(convert.grasp_query_dict(request))
        result = self.core.plan(request.session_id, query)
        if self.metrics is not None:
            self.metrics.planning.observe(result.planning_ms / 1e3)
            self.metrics.grasps.inc(len(result.grasps))
        return convert.grasp_result_message(result)

    @rpc
    def GetGrid(self, request: pb.GetGridRequest, context: grpc.ServicerContext) -> pb.Grid:
        """``GET /sessions/{id}/tsdf``: the grid as little-endian float32 bytes with its shape."""
        grid = self.core.grid(request.session_id)
        return pb.Grid(shape=grid.shape, data=convert.array_bytes(grid))

    @rpc
    def GetCloud(self, request: pb.GetCloudRequest, context: grpc.ServicerContext) -> pb.Cloud:
        """``GET /sessions/{id}/cloud``: (count, 6) little-endian float32 points and normals."""
        cloud = self.core.cloud(request.session_id)
        return pb.Cloud(count=len(cloud), data=convert.array_bytes(cloud))

    @rpc
    def GetModelInfo(self, request: pb.GetModelInfoRequest, context: grpc.ServicerContext) -> pb.ModelInfo:
        """``GET /model``; card and runtime as JSON text."""
        return convert.model_info_message(self.core.model_info())

    def _fuse(self, session_id: str, frame: pb.Frame) -> FrameResult:
        """One frame through the same checks as an HTTP upload, in the same order."""
        limit = self.settings.max_frame_bytes
        if len(frame.depth) > limit:
            raise PayloadTooLarge(
                f"depth image of {len(frame.depth)} bytes exceeds the limit of {limit} bytes (VGN_MAX_FRAME_BYTES)"
            )
        meta = FrameMeta.model_validate(convert.frame_meta_dict(frame))
        media_type = convert.MEDIA_TYPE_OF_ENCODING.get(frame.encoding)
        if media_type is None:
            known = frame.encoding in pb.DepthEncoding.values()
            name = pb.DepthEncoding.Name(frame.encoding) if known else str(frame.encoding)
            raise UnsupportedMediaType(
                f"frame encoding is {name}; "
                "send DEPTH_ENCODING_RAW_FLOAT32 (float32 metres) or DEPTH_ENCODING_PNG16 (16-bit PNG)"
            )
        result = self.core.add_encoded_frame(session_id, frame.depth, media_type, meta)
        if self.metrics is not None:
            self.metrics.integration.observe(result.integration_ms / 1e3)
        return result
