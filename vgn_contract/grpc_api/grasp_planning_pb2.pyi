from google.protobuf.internal import containers as _containers
from google.protobuf.internal import enum_type_wrapper as _enum_type_wrapper
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class DepthEncoding(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    DEPTH_ENCODING_UNSPECIFIED: _ClassVar[DepthEncoding]
    DEPTH_ENCODING_RAW_FLOAT32: _ClassVar[DepthEncoding]
    DEPTH_ENCODING_PNG16: _ClassVar[DepthEncoding]

class Planner(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    PLANNER_UNSPECIFIED: _ClassVar[Planner]
    PLANNER_VGN: _ClassVar[Planner]
    PLANNER_ANTIPODAL: _ClassVar[Planner]
DEPTH_ENCODING_UNSPECIFIED: DepthEncoding
DEPTH_ENCODING_RAW_FLOAT32: DepthEncoding
DEPTH_ENCODING_PNG16: DepthEncoding
PLANNER_UNSPECIFIED: Planner
PLANNER_VGN: Planner
PLANNER_ANTIPODAL: Planner

class Vector3(_message.Message):
    __slots__ = ("x", "y", "z")
    X_FIELD_NUMBER: _ClassVar[int]
    Y_FIELD_NUMBER: _ClassVar[int]
    Z_FIELD_NUMBER: _ClassVar[int]
    x: float
    y: float
    z: float
    def __init__(self, x: _Optional[float] = ..., y: _Optional[float] = ..., z: _Optional[float] = ...) -> None: ...

class Quaternion(_message.Message):
    __slots__ = ("x", "y", "z", "w")
    X_FIELD_NUMBER: _ClassVar[int]
    Y_FIELD_NUMBER: _ClassVar[int]
    Z_FIELD_NUMBER: _ClassVar[int]
    W_FIELD_NUMBER: _ClassVar[int]
    x: float
    y: float
    z: float
    w: float
    def __init__(self, x: _Optional[float] = ..., y: _Optional[float] = ..., z: _Optional[float] = ..., w: _Optional[float] = ...) -> None: ...

class Pose(_message.Message):
    __slots__ = ("position", "orientation")
    POSITION_FIELD_NUMBER: _ClassVar[int]
    ORIENTATION_FIELD_NUMBER: _ClassVar[int]
    position: Vector3
    orientation: Quaternion
    def __init__(self, position: _Optional[_Union[Vector3, _Mapping]] = ..., orientation: _Optional[_Union[Quaternion, _Mapping]] = ...) -> None: ...

class Intrinsics(_message.Message):
    __slots__ = ("width", "height", "fx", "fy", "cx", "cy")
    WIDTH_FIELD_NUMBER: _ClassVar[int]
    HEIGHT_FIELD_NUMBER: _ClassVar[int]
    FX_FIELD_NUMBER: _ClassVar[int]
    FY_FIELD_NUMBER: _ClassVar[int]
    CX_FIELD_NUMBER: _ClassVar[int]
    CY_FIELD_NUMBER: _ClassVar[int]
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    def __init__(self, width: _Optional[int] = ..., height: _Optional[int] = ..., fx: _Optional[float] = ..., fy: _Optional[float] = ..., cx: _Optional[float] = ..., cy: _Optional[float] = ...) -> None: ...

class Workspace(_message.Message):
    __slots__ = ("size", "resolution", "pose")
    SIZE_FIELD_NUMBER: _ClassVar[int]
    RESOLUTION_FIELD_NUMBER: _ClassVar[int]
    POSE_FIELD_NUMBER: _ClassVar[int]
    size: float
    resolution: int
    pose: Pose
    def __init__(self, size: _Optional[float] = ..., resolution: _Optional[int] = ..., pose: _Optional[_Union[Pose, _Mapping]] = ...) -> None: ...

class CreateSessionRequest(_message.Message):
    __slots__ = ("session_id", "workspace", "intrinsics", "decay", "gripper")
    SESSION_ID_FIELD_NUMBER: _ClassVar[int]
    WORKSPACE_FIELD_NUMBER: _ClassVar[int]
    INTRINSICS_FIELD_NUMBER: _ClassVar[int]
    DECAY_FIELD_NUMBER: _ClassVar[int]
    GRIPPER_FIELD_NUMBER: _ClassVar[int]
    session_id: str
    workspace: Workspace
    intrinsics: Intrinsics
    decay: float
    gripper: str
    def __init__(self, session_id: _Optional[str] = ..., workspace: _Optional[_Union[Workspace, _Mapping]] = ..., intrinsics: _Optional[_Union[Intrinsics, _Mapping]] = ..., decay: _Optional[float] = ..., gripper: _Optional[str] = ...) -> None: ...

class Session(_message.Message):
    __slots__ = ("session_id", "workspace", "intrinsics", "frame_count", "integration_ms", "created_at", "last_used_at", "expires_at", "decay", "gripper")
    SESSION_ID_FIELD_NUMBER: _ClassVar[int]
    WORKSPACE_FIELD_NUMBER: _ClassVar[int]
    INTRINSICS_FIELD_NUMBER: _ClassVar[int]
    FRAME_COUNT_FIELD_NUMBER: _ClassVar[int]
    INTEGRATION_MS_FIELD_NUMBER: _ClassVar[int]
    CREATED_AT_FIELD_NUMBER: _ClassVar[int]
    LAST_USED_AT_FIELD_NUMBER: _ClassVar[int]
    EXPIRES_AT_FIELD_NUMBER: _ClassVar[int]
    DECAY_FIELD_NUMBER: _ClassVar[int]
    GRIPPER_FIELD_NUMBER: _ClassVar[int]
    session_id: str
    workspace: Workspace
    intrinsics: Intrinsics
    frame_count: int
    integration_ms: float
    created_at: float
    last_used_at: float
    expires_at: float
    decay: float
    gripper: str
    def __init__(self, session_id: _Optional[str] = ..., workspace: _Optional[_Union[Workspace, _Mapping]] = ..., intrinsics: _Optional[_Union[Intrinsics, _Mapping]] = ..., frame_count: _Optional[int] = ..., integration_ms: _Optional[float] = ..., created_at: _Optional[float] = ..., last_used_at: _Optional[float] = ..., expires_at: _Optional[float] = ..., decay: _Optional[float] = ..., gripper: _Optional[str] = ...) -> None: ...

class GetSessionRequest(_message.Message):
    __slots__ = ("session_id",)
    SESSION_ID_FIELD_NUMBER: _ClassVar[int]
    session_id: str
    def __init__(self, session_id: _Optional[str] = ...) -> None: ...

class ListSessionsRequest(_message.Message):
    __slots__ = ()
    def __init__(self) -> None: ...

class ListSessionsResponse(_message.Message):
    __slots__ = ("sessions", "max_sessions")
    SESSIONS_FIELD_NUMBER: _ClassVar[int]
    MAX_SESSIONS_FIELD_NUMBER: _ClassVar[int]
    sessions: _containers.RepeatedCompositeFieldContainer[Session]
    max_sessions: int
    def __init__(self, sessions: _Optional[_Iterable[_Union[Session, _Mapping]]] = ..., max_sessions: _Optional[int] = ...) -> None: ...

class DeleteSessionRequest(_message.Message):
    __slots__ = ("session_id",)
    SESSION_ID_FIELD_NUMBER: _ClassVar[int]
    session_id: str
    def __init__(self, session_id: _Optional[str] = ...) -> None: ...

class DeleteSessionResponse(_message.Message):
    __slots__ = ()
    def __init__(self) -> None: ...

class ResetSessionRequest(_message.Message):
    __slots__ = ("session_id",)
    SESSION_ID_FIELD_NUMBER: _ClassVar[int]
    session_id: str
    def __init__(self, session_id: _Optional[str] = ...) -> None: ...

class Frame(_message.Message):
    __slots__ = ("session_id", "depth", "encoding", "camera_pose", "intrinsics", "depth_scale", "max_depth")
    SESSION_ID_FIELD_NUMBER: _ClassVar[int]
    DEPTH_FIELD_NUMBER: _ClassVar[int]
    ENCODING_FIELD_NUMBER: _ClassVar[int]
    CAMERA_POSE_FIELD_NUMBER: _ClassVar[int]
    INTRINSICS_FIELD_NUMBER: _ClassVar[int]
    DEPTH_SCALE_FIELD_NUMBER: _ClassVar[int]
    MAX_DEPTH_FIELD_NUMBER: _ClassVar[int]
    session_id: str
    depth: bytes
    encoding: DepthEncoding
    camera_pose: Pose
    intrinsics: Intrinsics
    depth_scale: float
    max_depth: float
    def __init__(self, session_id: _Optional[str] = ..., depth: _Optional[bytes] = ..., encoding: _Optional[_Union[DepthEncoding, str]] = ..., camera_pose: _Optional[_Union[Pose, _Mapping]] = ..., intrinsics: _Optional[_Union[Intrinsics, _Mapping]] = ..., depth_scale: _Optional[float] = ..., max_depth: _Optional[float] = ...) -> None: ...

class FrameResult(_message.Message):
    __slots__ = ("session_id", "frame_count", "integration_ms")
    SESSION_ID_FIELD_NUMBER: _ClassVar[int]
    FRAME_COUNT_FIELD_NUMBER: _ClassVar[int]
    INTEGRATION_MS_FIELD_NUMBER: _ClassVar[int]
    session_id: str
    frame_count: int
    integration_ms: float
    def __init__(self, session_id: _Optional[str] = ..., frame_count: _Optional[int] = ..., integration_ms: _Optional[float] = ...) -> None: ...

class StreamFramesResult(_message.Message):
    __slots__ = ("session_id", "frames_received", "frame_count", "integration_ms")
    SESSION_ID_FIELD_NUMBER: _ClassVar[int]
    FRAMES_RECEIVED_FIELD_NUMBER: _ClassVar[int]
    FRAME_COUNT_FIELD_NUMBER: _ClassVar[int]
    INTEGRATION_MS_FIELD_NUMBER: _ClassVar[int]
    session_id: str
    frames_received: int
    frame_count: int
    integration_ms: float
    def __init__(self, session_id: _Optional[str] = ..., frames_received: _Optional[int] = ..., frame_count: _Optional[int] = ..., integration_ms: _Optional[float] = ...) -> None: ...

class GraspQuery(_message.Message):
    __slots__ = ("session_id", "planner", "threshold", "max_grasps", "nms_size", "crop_min", "crop_max", "approach", "max_approach_angle", "clearance", "turn_average", "grip")
    SESSION_ID_FIELD_NUMBER: _ClassVar[int]
    PLANNER_FIELD_NUMBER: _ClassVar[int]
    THRESHOLD_FIELD_NUMBER: _ClassVar[int]
    MAX_GRASPS_FIELD_NUMBER: _ClassVar[int]
    NMS_SIZE_FIELD_NUMBER: _ClassVar[int]
    CROP_MIN_FIELD_NUMBER: _ClassVar[int]
    CROP_MAX_FIELD_NUMBER: _ClassVar[int]
    APPROACH_FIELD_NUMBER: _ClassVar[int]
    MAX_APPROACH_ANGLE_FIELD_NUMBER: _ClassVar[int]
    CLEARANCE_FIELD_NUMBER: _ClassVar[int]
    TURN_AVERAGE_FIELD_NUMBER: _ClassVar[int]
    GRIP_FIELD_NUMBER: _ClassVar[int]
    session_id: str
    planner: Planner
    threshold: float
    max_grasps: int
    nms_size: int
    crop_min: Vector3
    crop_max: Vector3
    approach: Vector3
    max_approach_angle: float
    clearance: bool
    turn_average: bool
    grip: bool
    def __init__(self, session_id: _Optional[str] = ..., planner: _Optional[_Union[Planner, str]] = ..., threshold: _Optional[float] = ..., max_grasps: _Optional[int] = ..., nms_size: _Optional[int] = ..., crop_min: _Optional[_Union[Vector3, _Mapping]] = ..., crop_max: _Optional[_Union[Vector3, _Mapping]] = ..., approach: _Optional[_Union[Vector3, _Mapping]] = ..., max_approach_angle: _Optional[float] = ..., clearance: _Optional[bool] = ..., turn_average: _Optional[bool] = ..., grip: _Optional[bool] = ...) -> None: ...

class Grasp(_message.Message):
    __slots__ = ("position", "orientation", "approach", "width", "quality", "track_id")
    POSITION_FIELD_NUMBER: _ClassVar[int]
    ORIENTATION_FIELD_NUMBER: _ClassVar[int]
    APPROACH_FIELD_NUMBER: _ClassVar[int]
    WIDTH_FIELD_NUMBER: _ClassVar[int]
    QUALITY_FIELD_NUMBER: _ClassVar[int]
    TRACK_ID_FIELD_NUMBER: _ClassVar[int]
    position: Vector3
    orientation: Quaternion
    approach: Vector3
    width: float
    quality: float
    track_id: int
    def __init__(self, position: _Optional[_Union[Vector3, _Mapping]] = ..., orientation: _Optional[_Union[Quaternion, _Mapping]] = ..., approach: _Optional[_Union[Vector3, _Mapping]] = ..., width: _Optional[float] = ..., quality: _Optional[float] = ..., track_id: _Optional[int] = ...) -> None: ...

class GraspResult(_message.Message):
    __slots__ = ("grasps", "planning_ms", "integration_ms", "frame_count", "model", "threshold", "clearance_dropped", "turn_average", "grip_dropped", "clearance", "grip", "fallback", "workspace_dropped", "clearance_margin")
    GRASPS_FIELD_NUMBER: _ClassVar[int]
    PLANNING_MS_FIELD_NUMBER: _ClassVar[int]
    INTEGRATION_MS_FIELD_NUMBER: _ClassVar[int]
    FRAME_COUNT_FIELD_NUMBER: _ClassVar[int]
    MODEL_FIELD_NUMBER: _ClassVar[int]
    THRESHOLD_FIELD_NUMBER: _ClassVar[int]
    CLEARANCE_DROPPED_FIELD_NUMBER: _ClassVar[int]
    TURN_AVERAGE_FIELD_NUMBER: _ClassVar[int]
    GRIP_DROPPED_FIELD_NUMBER: _ClassVar[int]
    CLEARANCE_FIELD_NUMBER: _ClassVar[int]
    GRIP_FIELD_NUMBER: _ClassVar[int]
    FALLBACK_FIELD_NUMBER: _ClassVar[int]
    WORKSPACE_DROPPED_FIELD_NUMBER: _ClassVar[int]
    CLEARANCE_MARGIN_FIELD_NUMBER: _ClassVar[int]
    grasps: _containers.RepeatedCompositeFieldContainer[Grasp]
    planning_ms: float
    integration_ms: float
    frame_count: int
    model: str
    threshold: float
    clearance_dropped: int
    turn_average: bool
    grip_dropped: int
    clearance: bool
    grip: bool
    fallback: bool
    workspace_dropped: int
    clearance_margin: float
    def __init__(self, grasps: _Optional[_Iterable[_Union[Grasp, _Mapping]]] = ..., planning_ms: _Optional[float] = ..., integration_ms: _Optional[float] = ..., frame_count: _Optional[int] = ..., model: _Optional[str] = ..., threshold: _Optional[float] = ..., clearance_dropped: _Optional[int] = ..., turn_average: _Optional[bool] = ..., grip_dropped: _Optional[int] = ..., clearance: _Optional[bool] = ..., grip: _Optional[bool] = ..., fallback: _Optional[bool] = ..., workspace_dropped: _Optional[int] = ..., clearance_margin: _Optional[float] = ...) -> None: ...

class GetGridRequest(_message.Message):
    __slots__ = ("session_id",)
    SESSION_ID_FIELD_NUMBER: _ClassVar[int]
    session_id: str
    def __init__(self, session_id: _Optional[str] = ...) -> None: ...

class Grid(_message.Message):
    __slots__ = ("shape", "data")
    SHAPE_FIELD_NUMBER: _ClassVar[int]
    DATA_FIELD_NUMBER: _ClassVar[int]
    shape: _containers.RepeatedScalarFieldContainer[int]
    data: bytes
    def __init__(self, shape: _Optional[_Iterable[int]] = ..., data: _Optional[bytes] = ...) -> None: ...

class GetCloudRequest(_message.Message):
    __slots__ = ("session_id",)
    SESSION_ID_FIELD_NUMBER: _ClassVar[int]
    session_id: str
    def __init__(self, session_id: _Optional[str] = ...) -> None: ...

class Cloud(_message.Message):
    __slots__ = ("count", "data")
    COUNT_FIELD_NUMBER: _ClassVar[int]
    DATA_FIELD_NUMBER: _ClassVar[int]
    count: int
    data: bytes
    def __init__(self, count: _Optional[int] = ..., data: _Optional[bytes] = ...) -> None: ...

class GetModelInfoRequest(_message.Message):
    __slots__ = ()
    def __init__(self) -> None: ...

class ListGrippersRequest(_message.Message):
    __slots__ = ()
    def __init__(self) -> None: ...

class GripperInfo(_message.Message):
    __slots__ = ("name", "version", "description", "max_opening", "finger_depth", "network", "threshold")
    NAME_FIELD_NUMBER: _ClassVar[int]
    VERSION_FIELD_NUMBER: _ClassVar[int]
    DESCRIPTION_FIELD_NUMBER: _ClassVar[int]
    MAX_OPENING_FIELD_NUMBER: _ClassVar[int]
    FINGER_DEPTH_FIELD_NUMBER: _ClassVar[int]
    NETWORK_FIELD_NUMBER: _ClassVar[int]
    THRESHOLD_FIELD_NUMBER: _ClassVar[int]
    name: str
    version: str
    description: str
    max_opening: float
    finger_depth: float
    network: str
    threshold: float
    def __init__(self, name: _Optional[str] = ..., version: _Optional[str] = ..., description: _Optional[str] = ..., max_opening: _Optional[float] = ..., finger_depth: _Optional[float] = ..., network: _Optional[str] = ..., threshold: _Optional[float] = ...) -> None: ...

class GripperList(_message.Message):
    __slots__ = ("grippers", "default")
    GRIPPERS_FIELD_NUMBER: _ClassVar[int]
    DEFAULT_FIELD_NUMBER: _ClassVar[int]
    grippers: _containers.RepeatedCompositeFieldContainer[GripperInfo]
    default: str
    def __init__(self, grippers: _Optional[_Iterable[_Union[GripperInfo, _Mapping]]] = ..., default: _Optional[str] = ...) -> None: ...

class ModelInfo(_message.Message):
    __slots__ = ("loaded", "model_id", "source", "architecture", "parameters", "device", "detail", "conventions", "threshold", "card_json", "runtime_json", "defaults", "one_view", "hand_models")
    class ConventionsEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: str
        def __init__(self, key: _Optional[str] = ..., value: _Optional[str] = ...) -> None: ...
    LOADED_FIELD_NUMBER: _ClassVar[int]
    MODEL_ID_FIELD_NUMBER: _ClassVar[int]
    SOURCE_FIELD_NUMBER: _ClassVar[int]
    ARCHITECTURE_FIELD_NUMBER: _ClassVar[int]
    PARAMETERS_FIELD_NUMBER: _ClassVar[int]
    DEVICE_FIELD_NUMBER: _ClassVar[int]
    DETAIL_FIELD_NUMBER: _ClassVar[int]
    CONVENTIONS_FIELD_NUMBER: _ClassVar[int]
    THRESHOLD_FIELD_NUMBER: _ClassVar[int]
    CARD_JSON_FIELD_NUMBER: _ClassVar[int]
    RUNTIME_JSON_FIELD_NUMBER: _ClassVar[int]
    DEFAULTS_FIELD_NUMBER: _ClassVar[int]
    ONE_VIEW_FIELD_NUMBER: _ClassVar[int]
    HAND_MODELS_FIELD_NUMBER: _ClassVar[int]
    loaded: bool
    model_id: str
    source: str
    architecture: str
    parameters: int
    device: str
    detail: str
    conventions: _containers.ScalarMap[str, str]
    threshold: float
    card_json: str
    runtime_json: str
    defaults: GraspDefaults
    one_view: OneViewModel
    hand_models: _containers.RepeatedCompositeFieldContainer[HandModel]
    def __init__(self, loaded: _Optional[bool] = ..., model_id: _Optional[str] = ..., source: _Optional[str] = ..., architecture: _Optional[str] = ..., parameters: _Optional[int] = ..., device: _Optional[str] = ..., detail: _Optional[str] = ..., conventions: _Optional[_Mapping[str, str]] = ..., threshold: _Optional[float] = ..., card_json: _Optional[str] = ..., runtime_json: _Optional[str] = ..., defaults: _Optional[_Union[GraspDefaults, _Mapping]] = ..., one_view: _Optional[_Union[OneViewModel, _Mapping]] = ..., hand_models: _Optional[_Iterable[_Union[HandModel, _Mapping]]] = ...) -> None: ...

class OneViewModel(_message.Message):
    __slots__ = ("model_id", "source", "threshold", "gripper", "card_json")
    MODEL_ID_FIELD_NUMBER: _ClassVar[int]
    SOURCE_FIELD_NUMBER: _ClassVar[int]
    THRESHOLD_FIELD_NUMBER: _ClassVar[int]
    GRIPPER_FIELD_NUMBER: _ClassVar[int]
    CARD_JSON_FIELD_NUMBER: _ClassVar[int]
    model_id: str
    source: str
    threshold: float
    gripper: str
    card_json: str
    def __init__(self, model_id: _Optional[str] = ..., source: _Optional[str] = ..., threshold: _Optional[float] = ..., gripper: _Optional[str] = ..., card_json: _Optional[str] = ...) -> None: ...

class HandModel(_message.Message):
    __slots__ = ("model_id", "source", "threshold", "gripper", "card_json")
    MODEL_ID_FIELD_NUMBER: _ClassVar[int]
    SOURCE_FIELD_NUMBER: _ClassVar[int]
    THRESHOLD_FIELD_NUMBER: _ClassVar[int]
    GRIPPER_FIELD_NUMBER: _ClassVar[int]
    CARD_JSON_FIELD_NUMBER: _ClassVar[int]
    model_id: str
    source: str
    threshold: float
    gripper: str
    card_json: str
    def __init__(self, model_id: _Optional[str] = ..., source: _Optional[str] = ..., threshold: _Optional[float] = ..., gripper: _Optional[str] = ..., card_json: _Optional[str] = ...) -> None: ...

class GraspDefaults(_message.Message):
    __slots__ = ("turn_average", "clearance", "grip", "threshold", "antipodal_threshold", "fallback_threshold")
    TURN_AVERAGE_FIELD_NUMBER: _ClassVar[int]
    CLEARANCE_FIELD_NUMBER: _ClassVar[int]
    GRIP_FIELD_NUMBER: _ClassVar[int]
    THRESHOLD_FIELD_NUMBER: _ClassVar[int]
    ANTIPODAL_THRESHOLD_FIELD_NUMBER: _ClassVar[int]
    FALLBACK_THRESHOLD_FIELD_NUMBER: _ClassVar[int]
    turn_average: bool
    clearance: bool
    grip: bool
    threshold: float
    antipodal_threshold: float
    fallback_threshold: float
    def __init__(self, turn_average: _Optional[bool] = ..., clearance: _Optional[bool] = ..., grip: _Optional[bool] = ..., threshold: _Optional[float] = ..., antipodal_threshold: _Optional[float] = ..., fallback_threshold: _Optional[float] = ...) -> None: ...

class TrackRequest(_message.Message):
    __slots__ = ("frame", "query", "plan_every", "match_distance", "match_angle")
    FRAME_FIELD_NUMBER: _ClassVar[int]
    QUERY_FIELD_NUMBER: _ClassVar[int]
    PLAN_EVERY_FIELD_NUMBER: _ClassVar[int]
    MATCH_DISTANCE_FIELD_NUMBER: _ClassVar[int]
    MATCH_ANGLE_FIELD_NUMBER: _ClassVar[int]
    frame: Frame
    query: GraspQuery
    plan_every: int
    match_distance: float
    match_angle: float
    def __init__(self, frame: _Optional[_Union[Frame, _Mapping]] = ..., query: _Optional[_Union[GraspQuery, _Mapping]] = ..., plan_every: _Optional[int] = ..., match_distance: _Optional[float] = ..., match_angle: _Optional[float] = ...) -> None: ...

class TrackUpdate(_message.Message):
    __slots__ = ("result", "frames_received", "cycle_ms")
    RESULT_FIELD_NUMBER: _ClassVar[int]
    FRAMES_RECEIVED_FIELD_NUMBER: _ClassVar[int]
    CYCLE_MS_FIELD_NUMBER: _ClassVar[int]
    result: GraspResult
    frames_received: int
    cycle_ms: float
    def __init__(self, result: _Optional[_Union[GraspResult, _Mapping]] = ..., frames_received: _Optional[int] = ..., cycle_ms: _Optional[float] = ...) -> None: ...
