"""Conversions between the protobuf messages and the wire schemas of ``vgn_contract.schemas``.

Incoming messages become plain dicts that are validated by the same pydantic models as the
HTTP API, so both front ends accept and reject exactly the same input with the same messages.
"""

from __future__ import annotations

import json
from typing import Any, TypeVar

import numpy as np
from google.protobuf.message import Message

from vgn_contract.grpc_api import grasp_planning_pb2 as pb
from vgn_contract.schemas import (
    FrameResult,
    GraspDefaults,
    GraspQuery,
    GraspResult,
    GripperInfo,
    GripperList,
    HandModel,
    Intrinsics,
    ModelInfo,
    OneViewModel,
    Pose,
    RuntimeInfo,
    SessionInfo,
    SessionList,
    Workspace,
)

#: The networks a ``ModelInfo`` lists besides the main one.
Network = TypeVar("Network", OneViewModel, HandModel)
RAW_MEDIA_TYPE = "application/octet-stream"
PNG_MEDIA_TYPE = "image/png"
MEDIA_TYPE_OF_ENCODING = {
    pb.DEPTH_ENCODING_RAW_FLOAT32: RAW_MEDIA_TYPE,
    pb.DEPTH_ENCODING_PNG16: PNG_MEDIA_TYPE,
}
ENCODING_OF_MEDIA_TYPE = {media: encoding for encoding, media in MEDIA_TYPE_OF_ENCODING.items()}
PLANNER_NAMES = {pb.PLANNER_UNSPECIFIED: "vgn", pb.PLANNER_VGN: "vgn", pb.PLANNER_ANTIPODAL: "antipodal"}
PLANNERS = {"vgn": pb.PLANNER_VGN, "antipodal": pb.PLANNER_ANTIPODAL}
#: How the grasp query's options travel, read off its declaration and the message: the 'x,y,z'
#: options as vectors, the planner as its enum, every other one as an optional scalar.
_QUERY_FIELDS = pb.GraspQuery.DESCRIPTOR.fields_by_name
QUERY_VECTORS = tuple(
    name for name in GraspQuery.model_fields if _QUERY_FIELDS[name].message_type is not None
)
QUERY_SCALARS = tuple(
    name for name in GraspQuery.model_fields if name != "planner" and name not in QUERY_VECTORS
)


# protobuf -> dicts the schemas validate ------------------------------------------------------
def vector(message: pb.Vector3) -> list[float]:
    """``[x, y, z]`` of a message vector."""
    return [message.x, message.y, message.z]


def vector_text(message: pb.Vector3) -> str:
    """The 'x,y,z' form of the HTTP query parameters; ``repr`` keeps every bit of a double."""
    return ",".join(repr(value) for value in vector(message))


def pose_dict(message: pb.Pose) -> dict[str, Any]:
    """A ``Pose`` dict holding only the parts the message sets, so missing ones take the schema defaults."""
    data: dict[str, Any] = {}
    if message.HasField("position"):
        data["position"] = vector(message.position)
    if message.HasField("orientation"):
        q = message.orientation
        data["orientation"] = [q.x, q.y, q.z, q.w]
    return data


def intrinsics_dict(message: pb.Intrinsics) -> dict[str, Any]:
    """An ``Intrinsics`` dict; the schema refuses the zeros of fields left unset."""
    return {name: getattr(message, name) for name in ("width", "height", "fx", "fy", "cx", "cy")}


def optional_fields(message: Any, names: tuple[str, ...]) -> dict[str, Any]:
    """The explicitly set ``optional`` fields of ``message``; unset ones take the schema defaults."""
    return {name: getattr(message, name) for name in names if message.HasField(name)}


def workspace_dict(message: pb.Workspace) -> dict[str, Any]:
    """A ``Workspace`` dict of the fields the message sets."""
    data = optional_fields(message, ("size", "resolution"))
    if message.HasField("pose"):
        data["pose"] = pose_dict(message.pose)
    return data


def session_create_dict(message: pb.CreateSessionRequest) -> dict[str, Any]:
    """A ``SessionCreate`` dict of the fields the request sets."""
    data = optional_fields(message, ("session_id", "decay", "gripper"))
    if message.HasField("workspace"):
        data["workspace"] = workspace_dict(message.workspace)
    if message.HasField("intrinsics"):
        data["intrinsics"] = intrinsics_dict(message.intrinsics)
    return data


def frame_meta_dict(message: pb.Frame) -> dict[str, Any]:
    """A ``FrameMeta`` dict of the fields the frame sets (the depth bytes travel apart)."""
    data = optional_fields(message, ("depth_scale", "max_depth"))
    if message.HasField("camera_pose"):
        data["camera_pose"] = pose_dict(message.camera_pose)
    if message.HasField("intrinsics"):
        data["intrinsics"] = intrinsics_dict(message.intrinsics)
    return data


def grasp_query_dict(message: pb.GraspQuery) -> dict[str, Any]:
    """A ``GraspQuery`` dict with vectors as 'x,y,z' text, so the HTTP rules apply; an unknown planner is
    passed on for the schema to refuse."""
    data = optional_fields(message, QUERY_SCALARS)
    data["planner"] = PLANNER_NAMES.get(message.planner, f"unknown planner {message.planner}")
    for name in QUERY_VECTORS:
        if message.HasField(name):
            data[name] = vector_text(getattr(message, name))
    return data


# schemas -> protobuf ------------------------------------------------------------------------
def vector3(values: list[float] | tuple[float, ...]) -> pb.Vector3:
    """A message vector of three numbers."""
    x, y, z = values
    return pb.Vector3(x=x, y=y, z=z)


def quaternion(values: list[float]) -> pb.Quaternion:
    """A message quaternion of ``[x, y, z, w]``."""
    x, y, z, w = values
    return pb.Quaternion(x=x, y=y, z=z, w=w)


def pose_message(pose: Pose) -> pb.Pose:
    """A validated ``Pose`` as a message."""
    return pb.Pose(position=vector3(pose.position), orientation=quaternion(pose.orientation))


def intrinsics_message(intrinsics: Intrinsics | None) -> pb.Intrinsics | None:
    """``Intrinsics`` as a message; ``None`` leaves the field unset."""
    return None if intrinsics is None else pb.Intrinsics(**intrinsics.model_dump())


def workspace_message(workspace: Workspace) -> pb.Workspace:
    """A ``Workspace`` as a message, every field set."""
    return pb.Workspace(
        size=workspace.size, resolution=workspace.resolution, pose=pose_message(workspace.pose)
    )


def session_message(info: SessionInfo) -> pb.Session:
    """The service's ``SessionInfo`` as a reply."""
    return pb.Session(
        session_id=info.session_id,
        workspace=workspace_message(info.workspace),
        intrinsics=intrinsics_message(info.intrinsics),
        frame_count=info.frame_count,
        integration_ms=info.integration_ms,
        created_at=info.created_at,
        last_used_at=info.last_used_at,
        expires_at=info.expires_at,
        decay=info.decay,
        gripper=info.gripper,
    )


def frame_result_message(result: FrameResult) -> pb.FrameResult:
    """The service's ``FrameResult`` as a reply."""
    return pb.FrameResult(**result.model_dump())


def grasp_result_message(result: GraspResult) -> pb.GraspResult:
    """The service's ``GraspResult`` as a reply."""
    grasps = [
        pb.Grasp(
            position=vector3(g.position),
            orientation=quaternion(g.orientation),
            approach=vector3(g.approach),
            width=g.width,
            quality=g.quality,
            track_id=g.track_id or 0,
        )
        for g in result.grasps
    ]
    return pb.GraspResult(grasps=grasps, **result.model_dump(exclude={"grasps"}, exclude_none=True))


def grasp_query_message(session_id: str, query: GraspQuery) -> pb.GraspQuery:
    """A validated ``GraspQuery`` as the request for ``session_id``; unset options stay unset."""
    message = pb.GraspQuery(session_id=session_id, planner=PLANNERS[query.planner])
    for name in QUERY_SCALARS:  # a switch that is off is sent too: unset is the service's default
        if getattr(query, name) is not None:
            setattr(message, name, getattr(query, name))
    for name in QUERY_VECTORS:
        values = query.vector(name)
        if values is not None:
            getattr(message, name).CopyFrom(vector3(values))
    return message


def gripper_list_message(hands: GripperList) -> pb.GripperList:
    """The service's ``GripperList`` as a reply."""
    return pb.GripperList(
        grippers=[pb.GripperInfo(**g.model_dump()) for g in hands.grippers], default=hands.default
    )


def model_info_message(info: ModelInfo) -> pb.ModelInfo:
    """The service's ``ModelInfo`` as a reply; the free-form card and the runtime travel as JSON text."""
    data = info.model_dump(
        exclude={"card", "runtime", "defaults", "one_view", "hand_models"}, exclude_none=True
    )
    runtime_json = None if info.runtime is None else info.runtime.model_dump_json()
    defaults = None if info.defaults is None else pb.GraspDefaults(**info.defaults.model_dump())
    one_view = None if info.one_view is None else network_message(info.one_view, pb.OneViewModel)
    hand_models = [network_message(network, pb.HandModel) for network in info.hand_models]
    return pb.ModelInfo(card_json=_card_json(info.card), runtime_json=runtime_json, defaults=defaults,
                        one_view=one_view, hand_models=hand_models, **data)  # fmt: skip


def network_message(network: OneViewModel | HandModel, message_type: type[Message]) -> Message:
    """A network of a ``ModelInfo`` besides the main one as its message (``pb.OneViewModel`` or
    ``pb.HandModel``, field for field), the card as JSON text as the main one's."""
    return message_type(card_json=_card_json(network.card), **network.model_dump(exclude={"card"}))


def _card_json(card: dict[str, Any] | None) -> str | None:
    return None if card is None else json.dumps(card)


def array_bytes(array: np.ndarray) -> bytes:
    """An array as little-endian float32 bytes, the encoding of grids and clouds."""
    return np.ascontiguousarray(array, dtype="<f4").tobytes()


# protobuf -> schemas (the client's answers) -------------------------------------------------
def session_info(message: pb.Session) -> SessionInfo:
    """A ``Session`` reply as the client's ``SessionInfo``."""
    return SessionInfo(
        session_id=message.session_id,
        workspace=Workspace.model_validate(workspace_dict(message.workspace)),
        intrinsics=intrinsics_dict(message.intrinsics) if message.HasField("intrinsics") else None,
        frame_count=message.frame_count,
        integration_ms=message.integration_ms,
        created_at=message.created_at,
        last_used_at=message.last_used_at,
        expires_at=message.expires_at,
        decay=message.decay if message.HasField("decay") else None,
        **({"gripper": message.gripper} if message.gripper else {}),
    )


def session_list(message: pb.ListSessionsResponse) -> SessionList:
    """A ``ListSessions`` reply as the client's ``SessionList``."""
    return SessionList(
        sessions=[session_info(s) for s in message.sessions], max_sessions=message.max_sessions
    )


def frame_result(message: pb.FrameResult) -> FrameResult:
    """A ``FrameResult`` reply as the client's model."""
    return FrameResult(
        session_id=message.session_id, frame_count=message.frame_count, integration_ms=message.integration_ms
    )


def grasp_result(message: pb.GraspResult) -> GraspResult:
    """A ``GraspResult`` reply as the client's model, validated like an HTTP answer."""
    grasps = [
        {
            "position": vector(g.position),
            "orientation": [g.orientation.x, g.orientation.y, g.orientation.z, g.orientation.w],
            "approach": vector(g.approach),
            "width": g.width,
            "quality": g.quality,
            "track_id": g.track_id or None,
        }
        for g in message.grasps
    ]
    return GraspResult(
        grasps=grasps,
        planning_ms=message.planning_ms,
        integration_ms=message.integration_ms,
        frame_count=message.frame_count,
        model=message.model,
        threshold=message.threshold,
        **optional_fields(
            message,
            (
                "clearance_dropped",
                "grip_dropped",
                "workspace_dropped",
                "turn_average",
                "clearance",
                "grip",
                "fallback",
                "clearance_margin",
            ),
        ),
    )


def gripper_list(message: pb.GripperList) -> GripperList:
    """A ``ListGrippers`` reply as the client's ``GripperList``."""
    hands = [
        GripperInfo(
            name=g.name,
            version=g.version,
            description=g.description,
            max_opening=g.max_opening,
            finger_depth=g.finger_depth,
            network=g.network if g.HasField("network") else None,
            threshold=g.threshold if g.HasField("threshold") else None,
        )  # fmt: skip
        for g in message.grippers
    ]
    return GripperList(grippers=hands, default=message.default)


def model_info(message: pb.ModelInfo) -> ModelInfo:
    """A ``ModelInfo`` reply as the client's model, card and runtime decoded from JSON; the deprecated
    ``threshold`` is taken from the reply only where it has no defaults to repeat."""
    data = optional_fields(message, ("model_id", "source", "detail"))
    if not message.HasField("defaults"):
        data["threshold"] = message.threshold
    return ModelInfo(
        loaded=message.loaded,
        model_id=data.get("model_id"),
        source=data.get("source"),
        architecture=message.architecture,
        parameters=message.parameters,
        device=message.device,
        detail=data.get("detail"),
        conventions=dict(message.conventions),
        threshold=data.get("threshold"),
        card=json.loads(message.card_json) if message.HasField("card_json") else None,
        defaults=grasp_defaults(message.defaults) if message.HasField("defaults") else None,
        runtime=RuntimeInfo.model_validate_json(message.runtime_json)
        if message.HasField("runtime_json")
        else None,
        one_view=network(message.one_view, OneViewModel) if message.HasField("one_view") else None,
        hand_models=[network(hand, HandModel) for hand in message.hand_models],
    )


def network(message: pb.OneViewModel | pb.HandModel, model: type[Network]) -> Network:
    """A ``OneViewModel`` or ``HandModel`` message as the client's ``model``, its card decoded from JSON."""
    card = json.loads(message.card_json) if message.HasField("card_json") else None
    fields = {name: getattr(message, name) for name in model.model_fields if name != "card"}
    return model(card=card, **fields)


def grasp_defaults(message: pb.GraspDefaults) -> GraspDefaults:
    """A ``GraspDefaults`` message as the client's model: field for field, as the model declares them."""
    return GraspDefaults(**{name: getattr(message, name) for name in GraspDefaults.model_fields})


def float_array(data: bytes, shape: tuple[int, ...]) -> np.ndarray:
    """A writable float32 array of little-endian ``data``."""
    return np.frombuffer(data, dtype="<f4").reshape(shape).astype(np.float32)
