"""``vgn.v1.GraspPlanning`` over a ``PlanningService``: parse, call the core, encode."""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import dataclass

import grpc
from pydantic import ValidationError

from service.api.metrics import ServiceMetrics
from service.core import PlanningService
from service.errors import InvalidInput, ServiceError, UnsupportedMediaType
from service.grpc.errors import PayloadTooLarge, rpc, streaming_rpc, validation_message
from service.grpc.handlers import MalformedRequest
from vgn_contract.grpc_api import convert
from vgn_contract.grpc_api import grasp_planning_pb2 as pb
from vgn_contract.grpc_api.grasp_planning_pb2_grpc import GraspPlanningServicer
from vgn_contract.schemas import FrameMeta, FrameResult, GraspQuery, SessionCreate
from vgn_contract.tracking import DEFAULT_MAX_ANGLE_DEG, DEFAULT_MAX_DISTANCE, GraspTracker


def check_one_session(index: int, session_id: str, named: str) -> None:
    """One stream carries one session's frames: a frame naming another is refused."""
    if named and session_id and named != session_id:
        raise InvalidInput(
            f"frame {index}: the stream is for session {session_id!r}, this frame names "
            f"{named!r}; one stream carries one session's frames"
        )


@dataclass(frozen=True)
class TrackOptions:
    """What the first message of a ``Track`` stream sets for the whole stream."""

    query: GraspQuery
    plan_every: int
    tracker: GraspTracker

    @classmethod
    def of(cls, first: pb.TrackRequest) -> TrackOptions:
        """The options of ``first``, checked (``InvalidInput`` names the one out of range)."""
        query = GraspQuery.model_validate(convert.grasp_query_dict(first.query))
        plan_every = first.plan_every if first.HasField("plan_every") else 1
        distance = first.match_distance if first.HasField("match_distance") else DEFAULT_MAX_DISTANCE
        angle = first.match_angle if first.HasField("match_angle") else DEFAULT_MAX_ANGLE_DEG
        if not 1 <= plan_every <= 1000:
            raise InvalidInput(f"plan_every is {plan_every}; plan after every 1 to 1000 frames")
        if not (0 < distance <= 1.0 and 0 < angle <= 180):
            raise InvalidInput(
                f"match_distance {distance:g} m and match_angle {angle:g} degrees: "
                "use 0 < match_distance <= 1 and 0 < match_angle <= 180"
            )
        return cls(query, plan_every, GraspTracker(distance, angle))


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
            check_one_session(index, session_id, frame.session_id)
            session_id = session_id or frame.session_id
            result = self._fuse_streamed(index, session_id, frame)
            received += 1
            integration_ms += result.integration_ms
        return pb.StreamFramesResult(
            session_id=session_id,
            frames_received=received,
            frame_count=result.frame_count if result else 0,
            integration_ms=round(integration_ms, 3),
        )

    @streaming_rpc
    def Track(
        self, request_iterator: Iterator[pb.TrackRequest], context: grpc.ServicerContext
    ) -> Iterator[pb.TrackUpdate]:
        """Closed loop: fuse each frame as ``StreamFrames`` does and, after every ``plan_every``-th,
        plan as ``GetGrasps`` does and send the grasps numbered by a ``GraspTracker``."""
        session_id, received, options = "", 0, None
        for index, message in enumerate(request_iterator):
            if not context.is_active():
                break
            if isinstance(message, MalformedRequest):
                raise InvalidInput(f"message {index}: {message.describe()}")
            if options is None:
                options = TrackOptions.of(message)
                session_id = message.frame.session_id or message.query.session_id
            check_one_session(index, session_id, message.frame.session_id)
            if not message.HasField("frame"):
                raise InvalidInput(f"message {index}: a Track message carries a frame")
            started = time.perf_counter()
            self._fuse_streamed(index, session_id, message.frame)
            received += 1
            if received % options.plan_every:
                continue
            result = self.core.plan(session_id, options.query)
            result = result.model_copy(update={"grasps": options.tracker.update(result.grasps)})
            if self.metrics is not None:
                self.metrics.planning.observe(result.planning_ms / 1e3)
                self.metrics.grasps.inc(len(result.grasps))
            cycle_ms = round((time.perf_counter() - started) * 1e3, 3)
            yield pb.TrackUpdate(
                result=convert.grasp_result_message(result), frames_received=received, cycle_ms=cycle_ms
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

    @rpc
    def ListGrippers(self, request: pb.ListGrippersRequest, context: grpc.ServicerContext) -> pb.GripperList:
        """``GET /grippers``."""
        return convert.gripper_list_message(self.core.grippers())

    def _fuse_streamed(self, index: int, session_id: str, frame: pb.Frame) -> FrameResult:
        """``_fuse`` for the ``index``-th frame of a stream: its errors name the frame."""
        try:
            return self._fuse(session_id, frame)
        except ValidationError as error:
            raise InvalidInput(f"frame {index}: {validation_message(error)}") from None
        except ServiceError as error:
            raise type(error)(f"frame {index}: {error}") from None

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
