"""What ``client`` offers a user directly: ``GRPCClient`` from the package (grpcio imported only
when it is asked for), and the client's typed errors for arguments it refuses before sending,
over HTTP (sync, async) and gRPC against real servers on loopback."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

import client
from client import AsyncVGNClient, BadRequest, InvalidRequest, VGNClient, VGNError
from service.launch.embedded import EmbeddedService
from tests.helpers.scenes import INTRINSICS

REPO = Path(__file__).resolve().parents[2]
DEPTH = np.full((INTRINSICS.height, INTRINSICS.width), 0.5, np.float32)


def nan_pose() -> np.ndarray:
    pose = np.eye(4)
    pose[1, 3] = np.nan
    return pose


@pytest.fixture(scope="module")
def service() -> Iterator[EmbeddedService]:
    env = {"VGN_API_KEY": "", "VGN_TORCH_THREADS": "1", "VGN_MODEL": "none"}
    with EmbeddedService(env=env, grpc=True) as running:
        yield running


@pytest.fixture
def session(service: EmbeddedService) -> Iterator[str]:
    with VGNClient(service.url) as vgn:
        session_id = vgn.create_session(intrinsics=INTRINSICS).session_id
        yield session_id
        vgn.delete_session(session_id)


def assert_refused(error: pytest.ExceptionInfo, field: str, *words: str) -> None:
    """Typed as the service's own 422 would be, still a ValueError, and naming the field."""
    assert isinstance(error.value, InvalidRequest) and isinstance(error.value, BadRequest)
    assert isinstance(error.value, VGNError) and isinstance(error.value, ValueError)
    assert error.value.status == 422 and error.value.field == field
    assert str(error.value).startswith(f"{field}: "), str(error.value)
    for word in words:
        assert word in str(error.value)


def frame_count(service: EmbeddedService, session_id: str) -> int:
    with VGNClient(service.url) as vgn:
        return vgn.session(session_id).frame_count


@pytest.mark.parametrize(
    ("pose", "field", "word"),
    [
        (nan_pose(), "camera_pose", "NaN"),
        ({"position": [0.0, float("nan"), 0.0]}, "camera_pose.position.1", "finite"),
        ({"matrix": nan_pose().tolist()}, "camera_pose", "NaN"),
    ],
    ids=["matrix", "position", "matrix-dict"],
)
def test_a_nan_camera_pose_is_a_typed_error_over_http(service, session, pose, field, word) -> None:
    with VGNClient(service.url) as vgn, pytest.raises(InvalidRequest) as error:
        vgn.add_frame(session, DEPTH, pose)
    assert_refused(error, field, word)
    assert frame_count(service, session) == 0, "nothing was sent"


async def test_a_nan_camera_pose_is_a_typed_error_over_async_http(service, session) -> None:
    async with AsyncVGNClient(service.url) as vgn:
        with pytest.raises(BadRequest) as error:
            await vgn.add_frame(session, DEPTH, nan_pose())
    assert_refused(error, "camera_pose", "NaN")


def test_a_nan_camera_pose_is_a_typed_error_over_grpc(service, session) -> None:
    from client import GRPCClient

    with GRPCClient(service.grpc_url) as vgn:
        with pytest.raises(InvalidRequest) as error:
            vgn.add_frame(session, DEPTH, nan_pose())
        assert_refused(error, "camera_pose", "NaN")
        frames = [(DEPTH, np.eye(4)), (DEPTH, nan_pose())]
        with pytest.raises(InvalidRequest) as error:
            vgn.stream_frames(session, iter(frames))
        assert_refused(error, "camera_pose", "NaN")


@pytest.mark.parametrize(
    ("call", "field"),
    [
        (lambda vgn, sid: vgn.add_frame(sid, DEPTH, np.eye(4), depth_scale=float("nan")), "depth_scale"),
        (lambda vgn, sid: vgn.add_frame(sid, DEPTH[0], np.eye(4)), "depth"),
        (lambda vgn, sid: vgn.grasps(sid, threshold=1.5), "threshold"),
        (lambda vgn, sid: vgn.grasps(sid, thresold=0.5), "thresold"),
        (lambda vgn, sid: vgn.grasps(sid, crop_min="0,0,0.2", crop_max="0.3,0.3,0.1"), "grasp query"),
    ],
    ids=["depth-scale", "depth-shape", "threshold", "unknown-option", "crop-box"],
)
def test_other_refused_arguments_name_their_field(service, session, call, field) -> None:
    with VGNClient(service.url) as vgn, pytest.raises(InvalidRequest) as error:
        call(vgn, session)
    assert_refused(error, field)


def test_the_cli_says_a_refused_option_is_refused_here(service, session) -> None:
    command = [
        sys.executable,
        "-m",
        "client.cli",
        "grasps",
        session,
        "--url",
        service.url,
        "--threshold",
        "2",
    ]
    result = subprocess.run(command, cwd=REPO, capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert result.stderr.strip() == "error: threshold: Input should be less than or equal to 1"


def test_grpc_client_comes_from_the_package(service) -> None:
    from client import GRPCClient
    from client.grpc_client import GRPCClient as Defined

    assert GRPCClient is Defined and client.GRPCClient is Defined and "GRPCClient" in dir(client)
    with GRPCClient(service.grpc_url) as vgn:
        assert vgn.health() == {"status": "ok"}
        assert vgn.sessions().max_sessions >= 1


# In a child: grpcio absent (imports of it fail as if not installed) or present.
IMPORTS = textwrap.dedent("""
    import json, sys
    BLOCKED = sys.argv[1:]

    class Blocker:
        def find_spec(self, name, path=None, target=None):
            if any(name == b or name.startswith(b + ".") for b in BLOCKED):
                raise ModuleNotFoundError(f"No module named {name!r} (blocked)", name=name)

    sys.meta_path.insert(0, Blocker())
    import client
    from client import *  # noqa: F403
    report = {"grpc_on_import": "grpc" in sys.modules}
    try:
        from client import GRPCClient
        report["grpc_client"] = GRPCClient.__module__
    except ImportError as error:
        report["error"] = str(error)
    print(json.dumps(report))
""")


@pytest.mark.parametrize("blocked", [[], ["grpc", "grpc_health", "google.protobuf"]], ids=["grpc", "no-grpc"])
def test_importing_client_needs_no_grpc(blocked: list[str]) -> None:
    result = subprocess.run(
        [sys.executable, "-c", IMPORTS, *blocked], cwd=REPO, capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["grpc_on_import"] is False
    if blocked:
        assert "GRPCClient needs the grpc extra" in report["error"] and "vgn-service[grpc]" in report["error"]
    else:
        assert report["grpc_client"] == "client.grpc_client"
