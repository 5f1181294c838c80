"""The wire schemas of the grasp-planning API, defined once for the service and the client.

The service validates requests with these models and builds its responses from them; the
client builds requests and parses responses with the same models, so the two cannot drift.
Frames and units follow docs/conventions.md: metres, radians (degrees only where a field says so),
quaternions ``[x, y, z, w]``, camera poses camera→world in the OpenCV optical frame.
"""

from __future__ import annotations

import math
import re
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, FiniteFloat, field_validator, model_validator

from vgn_contract.geometry import (
    UNIT_QUATERNION_TOLERANCE,
    check_rigid_matrix,
    check_unit_quaternion,
    pose_from_matrix,
)
from vgn_contract.gripper_description import DEFAULT_GRIPPER, NAME_PATTERN

Vector3 = Annotated[list[FiniteFloat], Field(min_length=3, max_length=3)]
Quaternion = Annotated[list[FiniteFloat], Field(min_length=4, max_length=4)]
SESSION_ID_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$"
#: Carries the session id on every request about a session, its creation included, so that a
#: proxy in front of several replicas routes all of a session's requests to one (docs/fleet.md).
#: gRPC metadata keys are lower case: ``x-session-id``.
SESSION_ID_HEADER = "X-Session-Id"
MAX_IMAGE_SIDE = 8192
#: Largest image area: every frame is decoded to float32 and buffered, so this bounds memory.
MAX_IMAGE_PIXELS = 16_000_000
#: VGN's detection threshold: the default for weights whose card names no operating threshold.
VGN_DEFAULT_THRESHOLD = 0.9
#: The antipodal baseline's default: its scores are geometric (a clean top-down antipodal grasp
#: scores ~0.95, a side grasp ~0.85), and everything it returns already passed its antipodal and
#: collision checks, so the threshold only drops poorly opposed contacts.
ANTIPODAL_DEFAULT_THRESHOLD = 0.5
#: What each of the grasp query's on/off options does when on, and why, said once: the query's
#: field, the service's default for it (service/settings.py) and the command line's flag
#: (client/cli.py) are all worded from this. No figures: what a check costs is on the Performance page.
SWITCH_EFFECTS: dict[str, str] = {
    "clearance": "drop grasps whose open hand (the session's hand: its fingers at their maximum opening, "
    "0.08 m for franka, and its palm) would touch the observed surface while approaching from its "
    "pregrasp distance back along the approach (5 cm for franka), so that fewer grasps fail on contact; "
    "applies to both planners, to every grasp before max_grasps, and adds a little planning time (see "
    "Performance)",
    "grip": "drop grasps whose closing fingers would not both meet the observed surface squarely, so that "
    "fewer grasps slip out while lifting: from each pad, rays along the closing axis must reach the fused "
    "surface and meet normals on average within 60 degrees of the closing direction (service/grip.py); "
    "where some grasps meet normals within about 45 degrees (VGN_GRIP_PREFERRED_ALIGNMENT), only those are "
    "kept; applies to both planners, before max_grasps, and adds a little planning time (see Performance); "
    "not applied to a volume fused from a single frame, which misleads it",
    "turn_average": "vgn only: score each grasp by the network's quality averaged over the grid turned by 0, "
    "90, 180 and 270 degrees about the workspace z axis (the turns VGN trains with), and each grasp's "
    "orientation by the mean of the four, so that more grasps succeed; widths stay those of the unturned "
    "grid; the four grids share one forward pass, which lengthens planning (see Performance)",
}
#: The grasp query's on/off options; unset, each is the service's default (on unless its operator
#: turned it off), so a client that sets one sends it either way.
SWITCHES = tuple(SWITCH_EFFECTS)


class _Model(BaseModel):
    # NaN and infinity are refused as "a finite number" before any bound names a limit they break.
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class Pose(_Model):
    """A rigid transform child→parent: ``position`` in metres and a unit ``orientation``.

    Also accepts ``{"matrix": [[...4x4...]]}``, which is checked for rigidity and stored as
    position + quaternion.
    """

    position: Vector3 = Field(default_factory=lambda: [0.0, 0.0, 0.0])
    orientation: Quaternion = Field(
        default_factory=lambda: [0.0, 0.0, 0.0, 1.0],
        description="unit quaternion [x, y, z, w]: 4 finite numbers whose norm must be 1 "
        f"(within {UNIT_QUATERNION_TOLERANCE:g}); a zero or non-unit quaternion is refused with 422",
    )

    @model_validator(mode="before")
    @classmethod
    def _from_matrix(cls, data: Any) -> Any:
        if isinstance(data, dict) and "matrix" in data:
            if set(data) != {"matrix"}:
                raise ValueError("give either 'matrix' or 'position'/'orientation', not both")
            return _checked_pose_fields(data["matrix"])
        return data

    @field_validator("orientation")
    @classmethod
    def _unit_quaternion(cls, value: list[float]) -> list[float]:
        check_unit_quaternion(np.asarray(value))
        return value

    @classmethod
    def from_matrix(cls, matrix: np.ndarray) -> Pose:
        """Pose of a 4×4 rigid transform; ``ValueError`` unless it is one.

        Built without validating the fields again: the checks leave a finite position and a
        unit quaternion, and every frame upload with a matrix pose pays for this call."""
        return cls.model_construct(**_checked_pose_fields(matrix))

    def as_matrix(self) -> np.ndarray:
        """The 4×4 homogeneous matrix child→parent."""
        from vgn_contract.geometry import matrix_from_pose

        return matrix_from_pose(np.asarray(self.position), np.asarray(self.orientation))


def _checked_pose_fields(values: Any) -> dict[str, list[float]]:
    """``position`` and ``orientation`` of a 4×4 matrix, once it is checked to be rigid."""
    try:
        matrix = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise ValueError(f"pose matrix must be a 4x4 array of numbers: {error}") from None
    check_rigid_matrix(matrix)
    position, quaternion = pose_from_matrix(matrix, checked=True)
    return {"position": position.tolist(), "orientation": quaternion.tolist()}


class Intrinsics(_Model):
    """Pinhole intrinsics of a depth camera, in pixels; width × height at most 16,000,000."""

    width: int = Field(gt=0, le=MAX_IMAGE_SIDE)
    height: int = Field(gt=0, le=MAX_IMAGE_SIDE)
    fx: FiniteFloat = Field(gt=0)
    fy: FiniteFloat = Field(gt=0)
    cx: FiniteFloat = Field(description="principal point x, inside the image: 0 < cx < width")
    cy: FiniteFloat = Field(description="principal point y, inside the image: 0 < cy < height")

    @model_validator(mode="after")
    def _principal_point_inside(self) -> Intrinsics:
        if self.width * self.height > MAX_IMAGE_PIXELS:
            raise ValueError(
                f"{self.width}x{self.height} exceeds the largest image of {MAX_IMAGE_PIXELS:,} pixels"
            )
        if not (0 < self.cx < self.width and 0 < self.cy < self.height):
            raise ValueError(
                f"principal point ({self.cx}, {self.cy}) must lie inside the {self.width}x{self.height} image"
            )
        return self


class Workspace(_Model):
    """The cube that is fused and searched for grasps: side ``size`` metres, ``resolution``
    voxels a side, its corner at ``pose`` in the world (docs/conventions.md)."""

    size: FiniteFloat = Field(default=0.30, gt=0.01, le=5.0, description="side length in metres")
    resolution: int = Field(
        default=40,
        ge=16,
        le=160,
        description="voxels per side; a multiple of 8 (network strides)",
        json_schema_extra={"multipleOf": 8},
    )
    pose: Pose = Field(default_factory=Pose, description="workspace corner → world")

    @field_validator("resolution")
    @classmethod
    def _multiple_of_eight(cls, value: int) -> int:
        if value % 8:
            raise ValueError(f"resolution must be a multiple of 8 (the network downsamples 8x), got {value}")
        return value

    @property
    def voxel_size(self) -> float:
        """Edge length of one voxel in metres."""
        return self.size / self.resolution


class SessionCreate(_Model):
    """Body of ``POST /sessions``: every field is optional."""

    session_id: str | None = Field(
        default=None, pattern=SESSION_ID_PATTERN, description="chosen id; generated when absent"
    )
    workspace: Workspace = Field(default_factory=Workspace)
    intrinsics: Intrinsics | None = Field(
        default=None, description="default intrinsics for this session's frames"
    )
    decay: float | None = Field(
        default=None,
        gt=0.0,
        lt=1.0,
        description="follow a changing scene: each frame first weighs the evidence of earlier frames "
        "in the voxels it sees again by this factor (what it does not see keeps its evidence); "
        "unset: every frame counts for ever (a static scene)",
    )
    gripper: str = Field(
        default=DEFAULT_GRIPPER,
        pattern=NAME_PATTERN,
        description="the hand this session plans for (GET /grippers lists them): its clearance and grip "
        "checks measure this hand; a hand the service does not know, or that no network serves, is refused",
    )


class SessionInfo(_Model):
    """A session's state: its workspace, default intrinsics, fused frames and expiry."""

    session_id: str
    workspace: Workspace
    intrinsics: Intrinsics | None
    frame_count: int
    integration_ms: float = Field(description="total integration time of this session's frames")
    created_at: float = Field(description="unix time")
    last_used_at: float = Field(description="unix time")
    expires_at: float = Field(description="unix time at which an idle session is dropped")
    decay: float | None = Field(default=None, description="the session's forgetting factor, if it forgets")
    gripper: str = Field(default=DEFAULT_GRIPPER, description="the hand the session plans for")


class SessionList(_Model):
    """The live sessions and how many the service keeps at most."""

    sessions: list[SessionInfo]
    max_sessions: int


class FrameMeta(_Model):
    """The ``meta`` part of a frame upload."""

    camera_pose: Pose = Field(description="camera → world, OpenCV optical frame")
    intrinsics: Intrinsics | None = Field(default=None, description="required unless the session has them")
    depth_scale: FiniteFloat = Field(default=1000.0, gt=0, description="PNG units per metre")
    max_depth: FiniteFloat = Field(default=2.0, gt=0, description="readings beyond this (m) are ignored")


class FrameResult(_Model):
    """What fusing one frame did: the session's frame count and the time it took."""

    session_id: str
    frame_count: int
    integration_ms: float = Field(description="time to integrate this frame")


#: A decimal number as the grasp query's vectors take it; one that overflows a double is refused
#: by the rule that the numbers be finite.
_NUMBER = r"[-+]?(?:[0-9]{1,20}(?:\.[0-9]{0,20})?|\.[0-9]{1,20})(?:[eE][-+]?[0-9]{1,3})?"
#: ``x,y,z`` (spaces around the numbers allowed), or empty: an empty query value means "not
#: given", as a blank form field does.
VECTOR3_PATTERN = rf"^(?: *{_NUMBER} *, *{_NUMBER} *, *{_NUMBER} *)?$"


def _vector3_field(description: str) -> Any:
    return Field(
        default=None,
        description=f"'x,y,z': {description}; empty is the same as not given",
        json_schema_extra={"pattern": VECTOR3_PATTERN},
    )


def _switch_field(name: str, off: str) -> Any:
    """An on/off option of the grasp query, described by its effect; unset, the service's default."""
    return Field(
        default=None,
        description=f"{SWITCH_EFFECTS[name]}. Unset: the service's default (VGN_{name.upper()}, on unless "
        f"the operator turned it off; /model defaults says); false gives {off}",
    )


def _checked_vector3_text(name: str, text: str | None) -> str | None:
    """``None`` for an absent or empty value; else the text, refused unless it is three numbers."""
    if text is None or text == "":
        return None
    if not re.fullmatch(VECTOR3_PATTERN, text):
        raise ValueError(f"{name} must be three comma-separated numbers 'x,y,z', got {text!r}")
    return text


def _parse_vector3(name: str, text: str | None) -> tuple[float, float, float] | None:
    if text is None:
        return None
    parts = text.split(",")
    try:
        values = tuple(float(part) for part in parts)
    except ValueError:
        raise ValueError(f"{name} must be three comma-separated numbers, got {text!r}") from None
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise ValueError(f"{name} must be three finite comma-separated numbers, got {text!r}")
    return values  # type: ignore[return-value]


class GraspQuery(_Model):
    """Options of one grasp request (query parameters of ``GET /sessions/{id}/grasps``)."""

    planner: Literal["vgn", "antipodal"] = Field(
        default="vgn",
        description="'vgn': the network; 'antipodal': a geometric sampling baseline on the fused "
        "point cloud (needs no model; nms_size does not apply to it)",
    )
    threshold: float | None = Field(
        default=None,
        ge=0.0,
        le=1.0,
        description="minimum grasp quality; default: for vgn the model's operating threshold (its card; "
        f"{VGN_DEFAULT_THRESHOLD} without one, VGN's), for antipodal {ANTIPODAL_DEFAULT_THRESHOLD}",
    )
    max_grasps: int | None = Field(default=None, ge=1, le=10000, description="return at most this many")
    nms_size: int = Field(default=4, ge=1, le=15, description="non-maximum suppression window (voxels)")
    crop_min: str | None = _vector3_field(
        "lower corner of a crop box, workspace frame, metres; below crop_max on every axis"
    )
    crop_max: str | None = _vector3_field("upper corner of a crop box, workspace frame, metres")
    approach: str | None = _vector3_field(
        "preferred approach direction, world frame; non-zero, and only with max_approach_angle"
    )
    max_approach_angle: float | None = Field(
        default=None,
        gt=0.0,
        le=180.0,
        description="degrees between a grasp's approach and `approach`; only with approach",
    )
    clearance: bool | None = _switch_field("clearance", off="the planner's unchecked grasps")
    grip: bool | None = _switch_field("grip", off="the planner's unchecked grasps")
    turn_average: bool | None = _switch_field("turn_average", off="VGN's plain answer")

    @field_validator("crop_min", "crop_max", "approach", mode="before")
    @classmethod
    def _vector3_text(cls, value: Any, info: Any) -> Any:
        return _checked_vector3_text(info.field_name, value) if isinstance(value, str) else value

    @model_validator(mode="after")
    def _consistent(self) -> GraspQuery:
        crop_min, crop_max = self.crop_box or (None, None)
        if (
            crop_min is not None
            and crop_max is not None
            and any(lo >= hi for lo, hi in zip(crop_min, crop_max, strict=True))
        ):
            raise ValueError(f"crop_min {crop_min} must be below crop_max {crop_max} on every axis")
        direction = self.approach_direction
        if (direction is None) != (self.max_approach_angle is None):
            raise ValueError("approach and max_approach_angle must be given together")
        if direction is not None and np.linalg.norm(direction) < 1e-9:
            raise ValueError("approach must be a non-zero direction")
        return self

    @property
    def crop_box(self) -> tuple[tuple[float, ...] | None, tuple[float, ...] | None] | None:
        """``crop_min`` and ``crop_max`` as numbers (either may be ``None``), or ``None`` without a crop."""
        if self.crop_min is None and self.crop_max is None:
            return None
        return self.vector("crop_min"), self.vector("crop_max")

    @property
    def approach_direction(self) -> tuple[float, float, float] | None:
        """``approach`` as numbers, or ``None`` when not given."""
        return self.vector("approach")

    def vector(self, name: str) -> tuple[float, float, float] | None:
        """The 'x,y,z' option ``name`` as numbers, or ``None`` when not given."""
        return _parse_vector3(name, getattr(self, name))

    def to_params(self) -> dict[str, Any]:
        """Query parameters for the request, the options left unset omitted; a switch that is set
        is sent on or off, since unset means the service's default."""
        params = self.model_dump(exclude_none=True)
        for switch in SWITCHES:
            if switch in params:
                params[switch] = "true" if params[switch] else "false"
        return params


class Grasp(_Model):
    """A parallel-jaw grasp in the world frame (grasp frame: docs/conventions.md)."""

    position: Vector3 = Field(description="centre between the finger bases, metres")
    orientation: Quaternion = Field(description="grasp frame → world, [x, y, z, w]")
    approach: Vector3 = Field(description="unit approach direction (grasp z axis)")
    width: float = Field(description="opening width, metres")
    quality: float = Field(ge=0.0, le=1.0)
    track_id: int | None = Field(
        default=None,
        description="the same grasp across re-plans of a tracking stream (gRPC Track); null elsewhere",
    )

    def as_matrix(self) -> np.ndarray:
        """The 4×4 grasp frame → world matrix."""
        from vgn_contract.geometry import matrix_from_pose

        return matrix_from_pose(np.asarray(self.position), np.asarray(self.orientation))


class GraspResult(_Model):
    """The grasps of one request, with the timings, and the model, threshold and options behind them:
    what the request asked for or, where it left an option unset, what the service chose."""

    grasps: list[Grasp] = Field(description="best first")
    planning_ms: float = Field(description="grid read-out + network + detection on the service")
    integration_ms: float = Field(description="total integration time of the fused frames")
    frame_count: int
    model: str = Field(
        description="id of the weights that planned these grasps (on a volume fused from one frame, the one-view "
        "network's where the service has one: /model's one_view), or 'antipodal'"
    )
    threshold: float = Field(description="the quality threshold these grasps passed")
    clearance_dropped: int | None = Field(
        default=None,
        description="grasps the clearance check dropped because the open hand's approach hits the observed "
        "surface; null when it did not run",
    )
    grip_dropped: int | None = Field(
        default=None,
        description="grasps the grip check dropped (after the clearance check); null when it did not run",
    )
    workspace_dropped: int | None = Field(
        default=None,
        description="grasps dropped because the open fingers reach outside the workspace cube, where the "
        "volume shows nothing (checked with the clearance check, counted apart from clearance_dropped); "
        "null when the clearance check did not run, or from a service older than this field",
    )
    turn_average: bool | None = Field(
        default=None, description="vgn: whether the request was turn-averaged; null for antipodal"
    )
    clearance: bool | None = Field(
        default=None,
        description="whether the clearance check was on for this request (asked for, or the service's "
        "default); null only from a service older than this field",
    )
    grip: bool | None = Field(
        default=None,
        description="whether the grip check was on for this request (asked for, or the service's default); "
        "on, it still does not run on a volume fused from a single frame (grip_dropped is null then); null "
        "only from a service older than this field",
    )
    fallback: bool | None = Field(
        default=None,
        description="whether nothing passed the checks at the default threshold, so that these grasps passed "
        "the lower fallback threshold (threshold says which; vgn requests that name no threshold only); "
        "null only from a service older than this field",
    )
    clearance_margin: float | None = Field(
        default=None,
        description="metres the clearance check grew the hand by on every side for these grasps: the "
        "service's margin, or its narrower fallback margin where the wider hand left nothing clear; null "
        "when the check did not run, or from a service older than this field",
    )


class GripperInfo(_Model):
    """A hand the service knows (its description: docs/your-gripper.md) and the network that serves it."""

    name: str
    version: str = Field(description="the label of data made with this hand")
    description: str
    max_opening: float = Field(description="fully open width between the pads (m)")
    finger_depth: float = Field(
        description="from the grasp frame's origin to the fingertips along the approach (m)"
    )
    network: str | None = Field(
        description="id of the network that plans for this hand: its own (VGN_HAND_MODELS) where it has one, "
        "else the main one; null: none, and a session for it is refused"
    )
    threshold: float | None = Field(
        default=None,
        description="that network's operating threshold, which a vgn request that gives none gets; null: no "
        "network, or a service older than this field",
    )


class GripperList(_Model):
    """The hands the service knows, and the one a session that names none plans for."""

    grippers: list[GripperInfo]
    default: str


class GraspDefaults(_Model):
    """What a grasp request gets for each option it leaves unset: the operator's switches and the
    thresholds. Each answer says what it used; a client that must know before it asks reads this."""

    turn_average: bool = Field(description="vgn requests are turn-averaged (VGN_TURN_AVERAGE)")
    clearance: bool = Field(description="requests of both planners are clearance-checked (VGN_CLEARANCE)")
    grip: bool = Field(
        description="requests of both planners are grip-checked (VGN_GRIP); never on a volume fused from a "
        "single frame"
    )
    threshold: float = Field(
        description="vgn's quality threshold: the model card's operating threshold, "
        f"else {VGN_DEFAULT_THRESHOLD} (VGN's)"
    )
    antipodal_threshold: float = Field(description="the antipodal baseline's score threshold")
    fallback_threshold: float = Field(
        description="the quality a vgn request that names no threshold and runs a check falls back to when "
        "nothing passes the checks at threshold (VGN_FALLBACK_THRESHOLD); only where it is below threshold"
    )


class BatchCounts(_Model):
    """The forward passes the network ran since the service started and the grids they carried."""

    batches: int = Field(description="forward passes run")
    grids: int = Field(description="grids they carried")
    largest: int = Field(description="most grids in one forward pass")
    mean: float = Field(description="grids per forward pass")


class MallocSettings(_Model):
    """Whether the service tuned glibc's allocator, and to what (bytes), or why not."""

    set_by_service: bool = Field(description="whether the service set any of them")
    reason: str | None = Field(default=None, description="why the service did not, when it did not")
    mmap_threshold: int | None = Field(default=None, description="freed blocks up to this size are kept")
    trim_threshold: int | None = Field(default=None, description="the heap top is trimmed beyond this")


def _moved_to_defaults(name: str) -> Any:
    """A request default that ``ModelInfo`` or its ``RuntimeInfo`` still repeats for clients that read
    it there, for one release: ``ModelInfo.defaults`` holds it now."""
    return Field(
        default=None,
        deprecated=f"read ModelInfo.defaults.{name}",
        description=f"deprecated, and left out from the next release: read defaults.{name}",
    )


class RuntimeInfo(_Model):
    """How the network runs: threads and cores, the OpenMP and allocator settings the service chose,
    the inference form, its precision and micro-batching."""

    torch_threads: int = Field(description="torch intra-op threads")
    usable_cores: int = Field(description="CPU cores this process may run on")
    omp_wait_policy: str | None = Field(description="OMP_WAIT_POLICY as the process has it")
    omp_set_by_service: list[str] = Field(description="the OpenMP variables the service set")
    omp_applied_before_torch: bool = Field(description="whether they were set before torch loaded OpenMP")
    malloc: MallocSettings
    torch: str = Field(description="torch's version")
    inference: str = Field(description="'fast' (folded for inference) or 'reference' (VGN as trained)")
    precision: str = Field(description="of the network's weights and activations: bfloat16 or float32")
    heads: str = Field(description="where rotation and width are computed: 'on-demand' or 'whole'")
    batch_window_ms: float = Field(description="how long a grasp request waits for others to share its pass")
    max_batch: int = Field(description="most grids in one forward pass")
    lanes: int = Field(description="threads that share the grids of one forward pass")
    batches: BatchCounts
    turn_average: bool | None = _moved_to_defaults("turn_average")
    clearance: bool | None = _moved_to_defaults("clearance")
    grip: bool | None = _moved_to_defaults("grip")
    fallback_threshold: float | None = _moved_to_defaults("fallback_threshold")


def _network_card() -> Any:
    """The ``card`` field of a network besides the main one."""
    return Field(default=None, description="from its model card, as ModelInfo's card, when there is one")


class _OtherNetwork(_Model):
    """A network the service loads besides the main one (``VGN_MODEL``)."""

    model_id: str = Field(description="sha256 prefix of its weights file: the model its answers name")
    source: str = Field(description="where its weights were loaded from")
    threshold: float = Field(
        description="threshold of its requests that give none: its card's operating threshold, "
        f"else {VGN_DEFAULT_THRESHOLD} (VGN's)"
    )


class OneViewModel(_OtherNetwork):
    """The network that answers vgn requests on volumes fused from one frame in place of the main one: from
    one fixed camera the fused surface is a single noisy side view, which a network trained on such
    views reads better."""

    gripper: str = Field(description="the hand whose sessions it answers; other hands' get the main network")
    card: dict[str, Any] | None = _network_card()


class HandModel(_OtherNetwork):
    """A hand's own network (VGN_HAND_MODELS): it answers every vgn request on that hand's sessions, in place
    of the main and the one-view network, since a network's grasps are what the hand it was trained for can
    do."""

    gripper: str = Field(description="the hand whose sessions it answers, whatever their frame count")
    card: dict[str, Any] | None = _network_card()


class ModelInfo(_Model):
    """The loaded weights (or why none are), where they run, and how they are used."""

    loaded: bool
    model_id: str | None = Field(description="sha256 prefix of the weights file")
    source: str | None = Field(description="where the weights were loaded from")
    architecture: str
    parameters: int
    device: str
    detail: str | None = Field(default=None, description="why no model is loaded, if none is")
    conventions: dict[str, str]
    threshold: float | None = _moved_to_defaults("threshold")
    card: dict[str, Any] | None = Field(
        default=None,
        description="from the model card beside the weights (<name>.card.json), when there is one: "
        "training date, scenes and grasps, the version of the hand that labelled them (gripper; null: not "
        "recorded), epochs, the shipped epoch with its optimizer steps and validation "
        "figures, the executed-grasp result of a clear-scene run, the command that reproduces them",
    )
    defaults: GraspDefaults | None = Field(
        default=None,
        description="what a grasp request gets for each option it leaves unset; null only from a service "
        "older than this field",
    )
    runtime: RuntimeInfo | None = Field(
        default=None,
        description="how the network runs: torch threads, OpenMP wait policy (and whether the service "
        "set it before torch loaded), allocator settings, inference form, precision, micro-batching window "
        "and counts; its turn_average, clearance, grip and fallback_threshold are deprecated (read defaults)",
    )
    one_view: OneViewModel | None = Field(
        default=None,
        description="the network that answers vgn requests on volumes fused from one frame "
        "(VGN_ONE_VIEW_MODEL); null: the main network answers those too, or a service older than this field",
    )
    hand_models: list[HandModel] = Field(
        default_factory=list,
        description="the hands' own networks (VGN_HAND_MODELS), by hand name; empty: none, or a service older "
        "than this field",
    )

    def hand_model(self, gripper: str) -> HandModel | None:
        """The network of ``gripper``'s own, which answers every session of that hand; ``None``
        when it has none (the main network, or no network, serves it)."""
        return next((network for network in self.hand_models if network.gripper == gripper), None)

    @model_validator(mode="after")
    def _repeat_the_threshold(self) -> ModelInfo:
        """The deprecated ``threshold`` is ``defaults.threshold`` again, never a value of its own;
        only an answer from a service older than ``defaults`` brings its own."""
        if self.defaults is not None:
            self.__dict__["threshold"] = self.defaults.threshold  # no warning: this is no reader
        return self


class Health(_Model):
    """Liveness: ``status`` is "ok" whenever the process answers."""

    status: str


class Readiness(_Model):
    """Whether grasps can be planned now, and why not when they cannot."""

    ready: bool
    detail: str


class ErrorResponse(BaseModel):
    """Every 4xx/5xx answer: ``detail`` says what is wrong (a list of field errors for 422)."""

    detail: str | list[dict[str, Any]]
    message: str | None = Field(default=None, description="one-line summary of a 422's field errors")
    ended: str | None = Field(
        default=None,
        description="a 404 for a session this service held: how it ended (deleted, expired, evicted); absent "
        "for an id it never held, which behind a proxy means a session of a lost replica",
    )
