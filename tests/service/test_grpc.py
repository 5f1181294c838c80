"""The gRPC front end against real servers on loopback: parity with HTTP, errors, streaming,
health, reflection, the API key, and clear-scene over gRPC."""

from __future__ import annotations

import contextlib
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import grpc
import httpx
import numpy as np
import pytest
from grpc_health.v1 import health_pb2, health_pb2_grpc
from grpc_reflection.v1alpha.proto_reflection_descriptor_database import ProtoReflectionDescriptorDatabase

from client import BadRequest, Conflict, NotFound, PayloadTooLarge, ServiceUnavailable, Unauthorized
from client.connect import connect
from client.grpc_client import GRPCClient, frame_message
from client.http import VGNClient
from service.core import PlanningService
from service.grpc.server import SERVICE_NAME, GRPCPortError, build_server
from service.http_app import create_app
from service.launch.embedded import EmbeddedService
from service.settings import Settings
from service.tsdf import SceneVolume
from tests.helpers.scenes import INTRINSICS, BoxScene, circle_views
from vgn_contract.grpc_api import grasp_planning_pb2 as pb
from vgn_contract.grpc_api.grasp_planning_pb2_grpc import GraspPlanningStub

SCENE = BoxScene()
LIMIT = 4 * 1024 * 1024
POSES = circle_views(6)
DEPTHS = [SCENE.depth(pose) for pose in POSES]


@pytest.fixture(scope="module")
def service(random_checkpoint: Path) -> Iterator[EmbeddedService]:
    """One uvicorn process serving HTTP and gRPC on one core."""
    env = {"VGN_MAX_FRAME_BYTES": str(LIMIT), "VGN_API_KEY": "", "VGN_TORCH_THREADS": "1"}
    with EmbeddedService(model=random_checkpoint, env=env, grpc=True) as running:
        yield running


@pytest.fixture
def stub(service: EmbeddedService) -> Iterator[GraspPlanningStub]:
    with grpc.insecure_channel(service.grpc_url.removeprefix("grpc://")) as channel:
        yield GraspPlanningStub(channel)


@contextlib.contextmanager
def in_process(random_checkpoint: Path, **overrides) -> Iterator[tuple[PlanningService, str]]:
    """A gRPC server in this process on a free port, over a core with ``overrides``."""
    settings = Settings(**{"model": random_checkpoint, "api_key": None, **overrides})
    core = PlanningService.from_settings(settings)
    server, port = build_server(core, "127.0.0.1", 0)
    try:
        yield core, f"grpc://127.0.0.1:{port}"
    finally:
        server.stop(None)


def fuse(client, session_id: str) -> None:
    for depth, pose in zip(DEPTHS[:3], POSES[:3], strict=True):
        client.add_frame(session_id, depth, pose)


# Parity ---------------------------------------------------------------------------------------
def test_same_frames_give_identical_grasps_over_http_and_grpc(clients):
    http, rpc = clients
    over_http = http.create_session(intrinsics=INTRINSICS).session_id
    over_grpc = rpc.create_session(intrinsics=INTRINSICS).session_id
    fuse(http, over_http)
    fuse(rpc, over_grpc)
    np.testing.assert_array_equal(http.tsdf(over_http), rpc.tsdf(over_grpc))
    # Without the clearance check (it drops every grasp of the random weights here), then with it.
    for options in ({"threshold": 0.0, "max_grasps": 30, "clearance": False, "grip": False},
                    {"threshold": 0.0, "crop_min": "0.05,0.05,0.0", "crop_max": "0.25,0.25,0.3", "nms_size": 3,
                     "clearance": False, "grip": False, "turn_average": False},
                    {"threshold": 0.0, "approach": "0,0,-1", "max_approach_angle": 120.0, "clearance": False, "grip": False},
                    {"planner": "antipodal", "max_grasps": 10, "clearance": False, "grip": False},
                    {"threshold": 0.0}):  # fmt: skip
        a, b = http.grasps(over_http, **options), rpc.grasps(over_grpc, **options)
        assert a.grasps or options == {"threshold": 0.0}, options
        assert a.grasps == b.grasps and a.threshold == b.threshold and a.model == b.model, options
        assert (a.turn_average, a.clearance_dropped) == (b.turn_average, b.clearance_dropped), options
    assert http.model() == rpc.model()


def test_a_session_is_shared_between_the_front_ends(clients):
    http, rpc = clients
    created_over_http = http.create_session(session_id="shared-http", intrinsics=INTRINSICS)
    rpc.add_frame(created_over_http.session_id, DEPTHS[0], POSES[0])
    assert http.session("shared-http").frame_count == 1
    assert rpc.session("shared-http") == http.session("shared-http")
    created_over_grpc = rpc.create_session(session_id="shared-grpc", intrinsics=INTRINSICS)
    http.add_frame(created_over_grpc.session_id, DEPTHS[1], POSES[1])
    np.testing.assert_array_equal(rpc.cloud("shared-grpc"), http.cloud("shared-grpc"))
    listed = {s.session_id for s in rpc.sessions().sessions}
    assert {"shared-http", "shared-grpc"} <= listed
    assert rpc.reset_session("shared-grpc").frame_count == 0
    rpc.delete_session("shared-http")
    http.delete_session("shared-grpc")
    with pytest.raises(NotFound):
        http.session("shared-http")


def test_png_depth_over_grpc_fuses_like_raw_over_http(clients):
    http, rpc = clients
    millimetres = np.round(DEPTHS[0] * 1000).astype(np.uint16)
    png, raw = rpc.create_session(intrinsics=INTRINSICS), http.create_session(intrinsics=INTRINSICS)
    rpc.add_frame(png.session_id, millimetres, POSES[0])  # encoded as a 16-bit PNG
    http.add_frame(raw.session_id, millimetres.astype(np.float32) / 1000, POSES[0])
    np.testing.assert_allclose(rpc.tsdf(png.session_id), http.tsdf(raw.session_id), atol=1e-5)


# Errors ---------------------------------------------------------------------------------------
def rpc_error(call, *args, **kwargs) -> grpc.RpcError:
    with pytest.raises(grpc.RpcError) as caught:
        call(*args, **kwargs)
    return caught.value


def test_invalid_input_is_invalid_argument_with_the_http_message(service, stub):
    bad = {"width": 640, "height": 480, "fx": 540.0, "fy": 540.0, "cx": 900.0, "cy": 240.0}
    over_http = httpx.post(f"{service.url}/sessions", json={"intrinsics": bad})
    error = rpc_error(stub.CreateSession, pb.CreateSessionRequest(intrinsics=pb.Intrinsics(**bad)))
    assert over_http.status_code == 422
    assert error.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert over_http.json()["message"] == f"body.{error.details()}"  # the message is the body
    assert "principal point" in error.details()
    error = rpc_error(stub.GetGrasps, pb.GraspQuery(session_id="x", threshold=2.0))
    assert error.code() == grpc.StatusCode.INVALID_ARGUMENT and "threshold" in error.details()


def test_rejected_frames_are_invalid_argument_and_change_nothing(clients, stub):
    _, rpc = clients
    session_id = rpc.create_session(intrinsics=INTRINSICS).session_id
    rpc.add_frame(session_id, DEPTHS[0], POSES[0])
    before = rpc.tsdf(session_id)
    good = frame_message(session_id, DEPTHS[1], POSES[1], None, 1000.0, 2.0)
    cases = {
        "raw depth must be 640x480 float32": changed(good, depth=b"\0" * 100),
        "frame encoding is DEPTH_ENCODING_UNSPECIFIED": changed(good, encoding=0),
        "depth PNG cannot be read": changed(good, encoding=pb.DEPTH_ENCODING_PNG16),
        "camera_pose: Field required": changed(good, camera_pose=None),
        "negative values": changed(good, depth=(-DEPTHS[1]).astype("<f4").tobytes()),
    }
    for needle, frame in cases.items():
        error = rpc_error(stub.AddFrame, frame)
        assert error.code() == grpc.StatusCode.INVALID_ARGUMENT, needle
        assert needle in error.details(), (needle, error.details())
    assert rpc.session(session_id).frame_count == 1
    np.testing.assert_array_equal(rpc.tsdf(session_id), before)
    np.testing.assert_allclose(rpc.cloud(session_id), cloud_of([0]), atol=1e-5)  # nor the cloud volume
    with pytest.raises(BadRequest, match="INVALID_ARGUMENT"):
        rpc.add_frame(session_id, DEPTHS[1][:100], POSES[1])


def changed(frame: pb.Frame, **changes) -> pb.Frame:
    """A copy of ``frame`` with fields set, or cleared where the value is None."""
    copy = pb.Frame()
    copy.CopyFrom(frame)
    for name, value in changes.items():
        if value is None:
            copy.ClearField(name)
        else:
            setattr(copy, name, value)
    return copy


def test_unknown_session_is_not_found_and_duplicate_is_already_exists(clients, stub):
    _, rpc = clients
    for call, request in ((stub.GetSession, pb.GetSessionRequest(session_id="ghost")),
                          (stub.GetGrasps, pb.GraspQuery(session_id="ghost")),
                          (stub.GetGrid, pb.GetGridRequest(session_id="ghost")),
                          (stub.DeleteSession, pb.DeleteSessionRequest(session_id="ghost"))):  # fmt: skip
        error = rpc_error(call, request)
        assert error.code() == grpc.StatusCode.NOT_FOUND and "'ghost'" in error.details()
    rpc.create_session(session_id="twice")
    error = rpc_error(stub.CreateSession, pb.CreateSessionRequest(session_id="twice"))
    assert error.code() == grpc.StatusCode.ALREADY_EXISTS
    with pytest.raises(Conflict, match="already exists"):
        rpc.create_session(session_id="twice")
    with pytest.raises(NotFound):
        rpc.grasps("ghost")


def test_oversize_frames_are_resource_exhausted(clients):
    _, rpc = clients
    session_id = rpc.create_session(intrinsics=INTRINSICS).session_id
    just_over = np.zeros(LIMIT // 2 + 1, dtype=np.uint16).tobytes()  # over the limit, within the message room
    far_over = b"\0" * (LIMIT + 256 * 1024)  # refused by gRPC before it is parsed
    messages = []
    for body in (just_over, far_over):
        with pytest.raises(PayloadTooLarge) as caught:
            rpc.add_frame(session_id, body, POSES[0])
        assert caught.value.grpc_code == grpc.StatusCode.RESOURCE_EXHAUSTED
        messages.append(caught.value.detail)
    assert f"exceeds the limit of {LIMIT} bytes (VGN_MAX_FRAME_BYTES)" in messages[0]
    assert rpc.session(session_id).frame_count == 0


def test_exceeded_deadline_is_a_timeout(service):
    with (
        GRPCClient(service.grpc_url, timeout=0.001) as hurried,
        pytest.raises(TimeoutError, match="DEADLINE"),
    ):
        session_id = "deadline"
        hurried.create_session(session_id=session_id)
        for _ in range(20):
            hurried.grasps(session_id, threshold=0.0)


def test_no_model_is_unavailable_and_not_serving(random_checkpoint):
    with in_process(random_checkpoint, model="none") as (_, url), GRPCClient(url) as rpc:
        assert rpc.health() == {"status": "ok"} and not rpc.ready().ready
        session_id = rpc.create_session(intrinsics=INTRINSICS).session_id
        fuse(rpc, session_id)
        with pytest.raises(ServiceUnavailable) as caught:
            rpc.grasps(session_id)
        assert caught.value.grpc_code == grpc.StatusCode.UNAVAILABLE
        assert rpc.grasps(session_id, planner="antipodal").model == "antipodal"


def test_no_free_session_is_resource_exhausted(random_checkpoint):
    with in_process(random_checkpoint, max_sessions=1) as (core, url), GRPCClient(url) as rpc:
        busy = rpc.create_session().session_id
        # A request holds the only session, so none can be evicted.
        with core.sessions.use(busy), pytest.raises(ServiceUnavailable, match="session limit") as caught:
            rpc.create_session()
        assert caught.value.grpc_code == grpc.StatusCode.RESOURCE_EXHAUSTED
        assert rpc.create_session().session_id != busy  # idle now: evicted for the new one


def test_api_key_from_either_metadata(random_checkpoint):
    with in_process(random_checkpoint, api_key="s3cret") as (_, url):
        with GRPCClient(url) as anonymous:
            assert anonymous.ready().ready  # health checks need no key
            with pytest.raises(Unauthorized) as caught:
                anonymous.sessions()
            assert caught.value.grpc_code == grpc.StatusCode.UNAUTHENTICATED
        with GRPCClient(url, api_key="wrong") as wrong, pytest.raises(Unauthorized):
            wrong.model()
        with GRPCClient(url, api_key="s3cret") as keyed:
            assert keyed.sessions().sessions == []
        with grpc.insecure_channel(url.removeprefix("grpc://")) as channel:
            answer = GraspPlanningStub(channel).ListSessions(
                pb.ListSessionsRequest(), metadata=(("authorization", "Bearer s3cret"),)
            )
            assert answer.max_sessions == 64


# Streaming --------------------------------------------------------------------------------------
def test_a_stream_of_100_frames_fuses_them_all(clients):
    http, rpc = clients
    session_id = rpc.create_session(intrinsics=INTRINSICS).session_id
    frames = [(DEPTHS[i % 6], POSES[i % 6]) for i in range(100)]
    result = rpc.stream_frames(session_id, frames)
    assert (result.session_id, result.frames_received, result.frame_count) == (session_id, 100, 100)
    assert result.integration_ms > 0
    reference = SceneVolume(0.3, 40, np.eye(4), cloud_resolution=40)
    for depth, pose in frames:
        reference.integrate(depth, INTRINSICS, pose, 2.0)
    np.testing.assert_allclose(http.tsdf(session_id), reference.grid(), atol=1e-5)


def test_the_cloud_right_after_a_stream_holds_every_frame(clients):
    """The stream only queues frames for the cloud volume; reading the cloud fuses them all."""
    _, rpc = clients
    session_id = rpc.create_session(intrinsics=INTRINSICS).session_id
    order = [i % 6 for i in range(40)]
    rpc.stream_frames(session_id, [(DEPTHS[i], POSES[i]) for i in order])
    np.testing.assert_allclose(rpc.cloud(session_id), cloud_of(order), atol=1e-5)


def cloud_of(indices: list[int]) -> np.ndarray:
    """The service's cloud of these frames, fused here in process."""
    volume = SceneVolume(0.3, 40, np.eye(4), cloud_resolution=120, max_pending=len(indices))
    for i in indices:
        volume.integrate(DEPTHS[i], INTRINSICS, POSES[i], 2.0)
    return volume.cloud()


def test_a_bad_frame_ends_the_stream_naming_it(clients):
    _, rpc = clients
    session_id = rpc.create_session(intrinsics=INTRINSICS).session_id
    frames = [(DEPTHS[0], POSES[0]), (DEPTHS[1], POSES[1]), (DEPTHS[2][:10], POSES[2]), (DEPTHS[3], POSES[3])]
    with pytest.raises(BadRequest, match="frame 2: raw depth must be"):
        rpc.stream_frames(session_id, frames)
    assert rpc.session(session_id).frame_count == 2
    np.testing.assert_allclose(rpc.cloud(session_id), cloud_of([0, 1]), atol=1e-5)  # the frames taken
    with pytest.raises(ValueError, match="2-D"):  # raised here while encoding, not a bare CANCELLED
        rpc.stream_frames(session_id, [(DEPTHS[0], POSES[0]), (DEPTHS[0][None], POSES[0])])


# Health, reflection, start-up ---------------------------------------------------------------------
def test_health_and_reflection(service):
    with grpc.insecure_channel(service.grpc_url.removeprefix("grpc://")) as channel:
        health = health_pb2_grpc.HealthStub(channel)
        for name in ("", SERVICE_NAME):
            status = health.Check(health_pb2.HealthCheckRequest(service=name)).status
            assert status == health_pb2.HealthCheckResponse.SERVING
        database = ProtoReflectionDescriptorDatabase(channel)
        assert {SERVICE_NAME, "grpc.health.v1.Health"} <= set(database.get_services())
        methods = {m.name for m in database.FindFileContainingSymbol(SERVICE_NAME).service[0].method}
        assert {
            "CreateSession",
            "AddFrame",
            "StreamFrames",
            "GetGrasps",
            "GetGrid",
            "GetModelInfo",
        } <= methods


def test_grpc_calls_are_counted_in_the_metrics(clients):
    http, rpc = clients
    with pytest.raises(NotFound):
        rpc.session("counted-ghost")
    rpc.sessions()
    text = http.metrics()
    route = f"/{SERVICE_NAME}"
    assert f'vgn_requests_total{{method="GRPC",route="{route}/GetSession",status="NOT_FOUND"}}' in text
    assert f'vgn_requests_total{{method="GRPC",route="{route}/ListSessions",status="OK"}}' in text


def test_a_taken_port_stops_the_start_up_clearly(random_checkpoint):
    from fastapi.testclient import TestClient

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        core = PlanningService.from_settings(Settings(model=random_checkpoint))
        with pytest.raises(GRPCPortError, match=f"127.0.0.1:{port}.*VGN_GRPC_PORT"):
            build_server(core, "127.0.0.1", port)
        settings = Settings(model=random_checkpoint, grpc_port=port)
        with pytest.raises(GRPCPortError, match="VGN_GRPC_PORT=0"), TestClient(create_app(settings, core)):
            pass


# Clients and CLI over gRPC ------------------------------------------------------------------------
def test_connect_picks_the_transport_by_scheme(service):
    with connect(service.url) as http, connect(service.grpc_url) as rpc:
        assert isinstance(http, VGNClient) and isinstance(rpc, GRPCClient)
    from client.cli import main

    assert main(["status", "--url", service.grpc_url]) == 0


def test_the_viewer_over_a_grpc_url_is_a_clear_error(service, tmp_path: Path, capsys):
    from client.cli import main

    with GRPCClient(service.grpc_url) as rpc:
        session_id = rpc.create_session(intrinsics=INTRINSICS).session_id
    out = tmp_path / "view.html"
    assert main(["view", session_id, "--url", service.grpc_url, "--out", str(out)]) == 2
    assert "HTTP only" in capsys.readouterr().err and not out.exists()


def test_clear_scene_episode_over_grpc(service, tmp_path: Path):
    results = tmp_path / "grpc-run"
    command = [sys.executable, "-m", "client.cli", "clear-scene", "--sim", "--renderer", "tiny",
               "--url", service.grpc_url, "--object-count", "2", "--threshold", "0.5", "--rounds", "1",
               "--results", str(results)]  # fmt: skip
    run = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert "success rate" in run.stdout
    assert (results / "summary.json").exists() and (results / "rounds.csv").read_text().count("\n") == 2


def test_generate_data_over_grpc(service, tmp_path: Path):
    from vgn_data.dataset import RawDataset

    out = tmp_path / "data"
    command = [sys.executable, "-m", "client.cli", "generate-data", "--sim", "--url", service.grpc_url,
               "--scene", "pile", "--objects", "blocks", "--scenes", "1", "--points", "4", "--renderer", "tiny",
               "--out", str(out)]  # fmt: skip
    run = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    ids, grasps = RawDataset(out).grasps()
    assert ids == ["s0-0000000"] * 4 and grasps.shape == (4, 9)
