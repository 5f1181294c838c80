"""The gRPC contract under malformed input: every RPC of ``vgn.v1.GraspPlanning`` is sent
messages with missing fields, NaNs and infinities, absurd sizes, unknown enum values, garbage
depth bytes, zero quaternions and request bytes that are no message at all, against a real
gRPC server on loopback. The status must be one the contract names (never UNKNOWN or
INTERNAL), with a message and the HTTP status as ``vgn-http-status`` trailing metadata.

Hypothesis generates the messages, derandomized so every run sends the same ones;
``VGN_FUZZ_EXAMPLES=500 python3 -m pytest -m slow tests/service/test_grpc_contract.py`` sends more.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import grpc
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from service.core import PlanningService
from service.grpc.server import build_server
from service.settings import Settings
from vgn_contract.grpc_api import grasp_planning_pb2 as pb
from vgn_contract.grpc_api.grasp_planning_pb2_grpc import GraspPlanningStub

LIMIT = 256 * 1024
WIDTH, HEIGHT = 64, 48
SESSION = "fuzzed"
#: What the contract lets a call end with; UNKNOWN and INTERNAL would be server bugs.
CONTRACT_CODES = {
    grpc.StatusCode.OK,
    grpc.StatusCode.INVALID_ARGUMENT,
    grpc.StatusCode.NOT_FOUND,
    grpc.StatusCode.ALREADY_EXISTS,
    grpc.StatusCode.FAILED_PRECONDITION,  # a session for a hand no network of the service serves
    grpc.StatusCode.RESOURCE_EXHAUSTED,
    grpc.StatusCode.UNAVAILABLE,
}
SHORT_EXAMPLES = 50
SLOW_EXAMPLES = int(os.environ.get("VGN_FUZZ_EXAMPLES", "300"))
FUZZ_SETTINGS = {
    "derandomize": True,
    "database": None,
    "deadline": None,
    "suppress_health_check": list(HealthCheck),
}


@dataclass
class Channel:
    stub: GraspPlanningStub
    channel: grpc.Channel

    def raw(self, method: str) -> Callable[..., Any]:
        """The method called with request bytes as they are (no serializer)."""
        return self.channel.unary_unary(f"/vgn.v1.GraspPlanning/{method}")


@pytest.fixture(scope="module")
def rpc(random_checkpoint: Path) -> Iterator[Channel]:
    """A real gRPC server on loopback, with a session whose frames are 64x48."""
    settings = Settings(model=random_checkpoint, api_key=None, max_sessions=8, max_frame_bytes=LIMIT)
    core = PlanningService.from_settings(settings)
    server, port = build_server(core, "127.0.0.1", 0)
    try:
        with grpc.insecure_channel(f"127.0.0.1:{port}") as channel:
            yield Channel(GraspPlanningStub(channel), channel)
    finally:
        server.stop(None)


@pytest.fixture(autouse=True)
def fuzzed_session(rpc: Channel) -> None:
    """The session the fuzzed calls address, there before every test: fuzzed CreateSession calls
    fill the server's eight slots and evict it, whatever order the tests run in."""
    intrinsics = pb.Intrinsics(width=WIDTH, height=HEIGHT, fx=60, fy=60, cx=32, cy=24)
    code, message, _ = outcome(
        lambda: rpc.stub.CreateSession(pb.CreateSessionRequest(session_id=SESSION, intrinsics=intrinsics))
    )
    assert code in (grpc.StatusCode.OK, grpc.StatusCode.ALREADY_EXISTS), message


def outcome(call: Callable[[], Any]) -> tuple[grpc.StatusCode, str, dict[str, str]]:
    """(code, message, trailing metadata) of a call."""
    try:
        call()
    except grpc.RpcError as error:
        return error.code(), error.details() or "", dict(error.trailing_metadata() or ())
    return grpc.StatusCode.OK, "", {}


def assert_within_contract(call: Callable[[], Any]) -> tuple[grpc.StatusCode, str]:
    code, message, trailers = outcome(call)
    assert code in CONTRACT_CODES, f"{code.name}: {message}"
    if code != grpc.StatusCode.OK:
        assert message and "internal error" not in message, code
        assert trailers.get("vgn-http-status", "").isdigit(), trailers
    return code, message


# Strategies --------------------------------------------------------------------------------
ODD_FLOATS = st.sampled_from(
    [0.0, -0.0, -1.0, 1e-300, 1e300, -1e308, float("nan"), float("inf"), float("-inf")]
)
DOUBLES = st.floats(allow_nan=True, allow_infinity=True) | ODD_FLOATS
INT32 = st.integers(-(2**31), 2**31 - 1) | st.sampled_from([0, -1, 7, 8, 40, 8192, 8193])
ENUMS = st.integers(-3, 9)
TEXT = st.text(st.characters(exclude_categories=["Cs"]), max_size=80)
SESSION_IDS = st.sampled_from([SESSION, "", "ghost"]) | TEXT


def message(cls: Any, **fields: st.SearchStrategy) -> st.SearchStrategy:
    """Messages of ``cls`` with any subset of ``fields`` set: unset ones test the defaults and
    the required-field checks."""
    return st.fixed_dictionaries({}, optional=fields).map(lambda kwargs: cls(**kwargs))


VECTORS = message(pb.Vector3, x=DOUBLES, y=DOUBLES, z=DOUBLES)
QUATERNIONS = message(pb.Quaternion, x=DOUBLES, y=DOUBLES, z=DOUBLES, w=DOUBLES) | st.just(pb.Quaternion())
POSES = message(pb.Pose, position=VECTORS, orientation=QUATERNIONS)
INTRINSICS = message(pb.Intrinsics, width=INT32, height=INT32, fx=DOUBLES, fy=DOUBLES, cx=DOUBLES, cy=DOUBLES)
WORKSPACES = message(pb.Workspace, size=DOUBLES, resolution=INT32, pose=POSES)


def depth_bytes() -> st.SearchStrategy[bytes]:
    """Garbage, a PNG signature before garbage, the right size of NaNs or negatives, or too much."""
    right_size = WIDTH * HEIGHT
    return st.one_of(
        st.binary(max_size=2048),
        st.binary(max_size=256).map(lambda tail: b"\x89PNG\r\n\x1a\n" + tail),
        st.sampled_from([float("nan"), -1.0, float("inf"), 0.5]).map(
            lambda value: np.full(right_size, value, "<f4").tobytes()
        ),
        st.just(struct.pack("<f", 0.5) * (right_size - 1)),
        st.just(b"\0" * (LIMIT + 1)),
    )


FRAMES = message(
    pb.Frame,
    session_id=SESSION_IDS,
    depth=depth_bytes(),
    encoding=ENUMS,
    camera_pose=POSES,
    intrinsics=INTRINSICS,
    depth_scale=DOUBLES,
    max_depth=DOUBLES,
)
REQUESTS: dict[str, st.SearchStrategy] = {
    "CreateSession": message(
        pb.CreateSessionRequest,
        session_id=SESSION_IDS,
        workspace=WORKSPACES,
        intrinsics=INTRINSICS,
        decay=DOUBLES,
        gripper=st.sampled_from(["franka", "robotiq-2f85", "no-such-hand", ""]),
    ),
    "GetSession": message(pb.GetSessionRequest, session_id=SESSION_IDS),
    "ListSessions": st.just(pb.ListSessionsRequest()),
    "DeleteSession": message(pb.DeleteSessionRequest, session_id=st.sampled_from(["", "ghost"]) | TEXT),
    "ResetSession": message(pb.ResetSessionRequest, session_id=SESSION_IDS),
    "AddFrame": FRAMES,
    "GetGrasps": message(
        pb.GraspQuery,
        session_id=SESSION_IDS,
        planner=ENUMS,
        threshold=DOUBLES,
        max_grasps=INT32,
        nms_size=INT32,
        crop_min=VECTORS,
        crop_max=VECTORS,
        approach=VECTORS,
        max_approach_angle=DOUBLES,
    ),
    "GetGrid": message(pb.GetGridRequest, session_id=SESSION_IDS),
    "GetCloud": message(pb.GetCloudRequest, session_id=SESSION_IDS),
    "GetModelInfo": st.just(pb.GetModelInfoRequest()),
    "ListGrippers": st.just(pb.ListGrippersRequest()),
}
TRACK_MESSAGES = message(
    pb.TrackRequest,
    frame=FRAMES,
    query=REQUESTS["GetGrasps"],
    plan_every=INT32,
    match_distance=DOUBLES,
    match_angle=DOUBLES,
)
#: The client-streaming methods: a list of messages each, drained whether they answer once or often.
STREAMS = {"StreamFrames": FRAMES, "Track": TRACK_MESSAGES}
METHODS = sorted(REQUESTS) + sorted(STREAMS)


def test_every_rpc_is_fuzzed():
    served = {method.name for method in pb.DESCRIPTOR.services_by_name["GraspPlanning"].methods}
    assert set(METHODS) == served


def fuzz_unary(rpc: Channel, method: str, examples: int) -> None:
    @settings(max_examples=examples, **FUZZ_SETTINGS)
    @given(request=REQUESTS[method])
    def check(request: Any) -> None:
        assert_within_contract(lambda: getattr(rpc.stub, method)(request, timeout=10))

    check()


def drained(answer: Any) -> Any:
    """A unary answer as it is; every message of a streamed answer (errors surface here)."""
    return answer if not hasattr(answer, "__next__") else list(answer)


def fuzz_stream(rpc: Channel, method: str, examples: int) -> None:
    @settings(max_examples=examples, **FUZZ_SETTINGS)
    @given(messages=st.lists(STREAMS[method], max_size=3))
    def check(messages: list[Any]) -> None:
        assert_within_contract(lambda: drained(getattr(rpc.stub, method)(iter(messages), timeout=10)))

    check()


def fuzz_bytes(rpc: Channel, method: str, examples: int) -> None:
    """Request bytes that are no valid message of the method (or happen to be one)."""

    @settings(max_examples=examples, **FUZZ_SETTINGS)
    @given(data=st.binary(max_size=512))
    def check(data: bytes) -> None:
        if method in STREAMS:
            streaming = rpc.channel.stream_stream if method == "Track" else rpc.channel.stream_unary
            call = streaming(f"/vgn.v1.GraspPlanning/{method}")
            assert_within_contract(lambda: drained(call(iter([data]), timeout=10)))
        else:
            assert_within_contract(lambda: rpc.raw(method)(data, timeout=10))

    check()


@pytest.mark.parametrize("method", sorted(REQUESTS))
def test_malformed_messages_get_contract_statuses(rpc: Channel, method: str) -> None:
    fuzz_unary(rpc, method, SHORT_EXAMPLES)


@pytest.mark.parametrize("method", sorted(STREAMS))
def test_malformed_streams_get_contract_statuses(rpc: Channel, method: str) -> None:
    fuzz_stream(rpc, method, SHORT_EXAMPLES)


@pytest.mark.parametrize("method", METHODS)
def test_garbage_request_bytes_get_contract_statuses(rpc: Channel, method: str) -> None:
    fuzz_bytes(rpc, method, 10)


@pytest.mark.slow
@pytest.mark.parametrize("method", METHODS)
def test_malformed_messages_long(rpc: Channel, method: str) -> None:
    if method in STREAMS:
        fuzz_stream(rpc, method, SLOW_EXAMPLES)
    else:
        fuzz_unary(rpc, method, SLOW_EXAMPLES)
    fuzz_bytes(rpc, method, SLOW_EXAMPLES)


# Named cases: the message says what is wrong ----------------------------------------------
IDENTITY = pb.Pose(position=pb.Vector3(x=0.15, y=0.15, z=0.5), orientation=pb.Quaternion(x=1.0))


def frame(**changes: Any) -> pb.Frame:
    fields = {
        "session_id": SESSION,
        "depth": np.full(WIDTH * HEIGHT, 0.4, "<f4").tobytes(),
        "encoding": pb.DEPTH_ENCODING_RAW_FLOAT32,
        "camera_pose": IDENTITY,
        **changes,
    }
    return pb.Frame(**{name: value for name, value in fields.items() if value is not None})


NAN = float("nan")
CASES = [
    ("AddFrame", frame(camera_pose=None), grpc.StatusCode.INVALID_ARGUMENT, ("camera_pose", "required")),
    (
        "AddFrame",
        frame(encoding=pb.DEPTH_ENCODING_UNSPECIFIED),
        grpc.StatusCode.INVALID_ARGUMENT,
        ("encoding",),
    ),
    ("AddFrame", frame(encoding=42), grpc.StatusCode.INVALID_ARGUMENT, ("encoding is 42",)),
    (
        "AddFrame",
        frame(camera_pose=pb.Pose(orientation=pb.Quaternion())),
        grpc.StatusCode.INVALID_ARGUMENT,
        ("camera_pose.orientation", "unit length"),
    ),
    (
        "AddFrame",
        frame(camera_pose=pb.Pose(position=pb.Vector3(x=NAN), orientation=pb.Quaternion(w=1))),
        grpc.StatusCode.INVALID_ARGUMENT,
        ("camera_pose.position", "finite"),
    ),
    ("AddFrame", frame(depth=b"\x01\x02\x03"), grpc.StatusCode.INVALID_ARGUMENT, ("bytes",)),
    (
        "AddFrame",
        frame(depth=b"\x89PNG\r\n\x1a\ngarbage", encoding=pb.DEPTH_ENCODING_PNG16),
        grpc.StatusCode.INVALID_ARGUMENT,
        ("PNG",),
    ),
    (
        "AddFrame",
        frame(depth=b"\0" * (LIMIT + 1)),
        grpc.StatusCode.RESOURCE_EXHAUSTED,
        ("exceeds the limit",),
    ),
    ("AddFrame", frame(max_depth=NAN), grpc.StatusCode.INVALID_ARGUMENT, ("max_depth", "finite")),
    ("AddFrame", frame(session_id="ghost"), grpc.StatusCode.NOT_FOUND, ("ghost",)),
    (
        "CreateSession",
        pb.CreateSessionRequest(workspace=pb.Workspace(resolution=7)),
        grpc.StatusCode.INVALID_ARGUMENT,
        ("workspace.resolution",),
    ),
    (
        "CreateSession",
        pb.CreateSessionRequest(intrinsics=pb.Intrinsics(width=-1, height=48, fx=1, fy=1, cx=1, cy=1)),
        grpc.StatusCode.INVALID_ARGUMENT,
        ("intrinsics.width",),
    ),
    (
        "CreateSession",
        pb.CreateSessionRequest(session_id="no spaces"),
        grpc.StatusCode.INVALID_ARGUMENT,
        ("session_id",),
    ),
    (
        "CreateSession",
        pb.CreateSessionRequest(session_id=SESSION),
        grpc.StatusCode.ALREADY_EXISTS,
        ("already exists",),
    ),
    (
        "GetGrasps",
        pb.GraspQuery(session_id=SESSION, planner=7),
        grpc.StatusCode.INVALID_ARGUMENT,
        ("planner",),
    ),
    (
        "GetGrasps",
        pb.GraspQuery(session_id=SESSION, threshold=NAN),
        grpc.StatusCode.INVALID_ARGUMENT,
        ("threshold",),
    ),
    (
        "GetGrasps",
        pb.GraspQuery(session_id=SESSION, crop_min=pb.Vector3(x=NAN), crop_max=pb.Vector3(x=1, y=1, z=1)),
        grpc.StatusCode.INVALID_ARGUMENT,
        ("crop_min",),
    ),
    (
        "GetGrasps",
        pb.GraspQuery(session_id=SESSION, approach=pb.Vector3(x=float("inf")), max_approach_angle=30),
        grpc.StatusCode.INVALID_ARGUMENT,
        ("approach",),
    ),
    (
        "GetGrasps",
        pb.GraspQuery(session_id=SESSION, max_grasps=-1),
        grpc.StatusCode.INVALID_ARGUMENT,
        ("max_grasps",),
    ),
    ("GetGrid", pb.GetGridRequest(), grpc.StatusCode.NOT_FOUND, ("session",)),
]


@pytest.mark.parametrize(
    ("method", "request_message", "code", "needles"), CASES, ids=lambda v: getattr(v, "name", None)
)
def test_malformed_message_is_refused_naming_the_problem(
    rpc: Channel, method, request_message, code, needles
) -> None:
    got, message = assert_within_contract(lambda: getattr(rpc.stub, method)(request_message, timeout=10))
    assert got == code, message
    for needle in needles:
        assert needle in message, (needle, message)


def test_bytes_that_are_no_message_are_invalid_argument_naming_the_type(rpc: Channel) -> None:
    code, message = assert_within_contract(lambda: rpc.raw("AddFrame")(b"\xff\xff\xff\xff", timeout=10))
    assert code == grpc.StatusCode.INVALID_ARGUMENT and "vgn.v1.Frame" in message


def test_a_bad_frame_in_a_stream_is_named_by_its_index(rpc: Channel) -> None:
    frames = [frame(), frame(session_id="", camera_pose=pb.Pose(orientation=pb.Quaternion()))]
    code, message = assert_within_contract(lambda: rpc.stub.StreamFrames(iter(frames), timeout=10))
    assert code == grpc.StatusCode.INVALID_ARGUMENT and message.startswith("frame 1:"), message
    call = rpc.channel.stream_unary("/vgn.v1.GraspPlanning/StreamFrames")
    code, message = assert_within_contract(
        lambda: call(iter([frame().SerializeToString(), b"\xff\xff"]), timeout=10)
    )
    assert code == grpc.StatusCode.INVALID_ARGUMENT and message.startswith("frame 1:"), message
