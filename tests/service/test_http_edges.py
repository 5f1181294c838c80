"""Edges users hit over HTTP, against real uvicorn servers: non-finite depth, the API key (raw
headers, the client's ``api_key`` and the CLI's ``--api-key``), expiry and the session limit,
planning while frames arrive, and every typed error the client defines.

Non-finite depth is a reading the sensor did not make: NaN, +inf and -inf fuse exactly like 0
(no reading), over the raw float32 encoding (a 16-bit PNG cannot hold them).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
import threading
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor

import httpx
import numpy as np
import pytest

from client.http import (
    BadRequest,
    Conflict,
    NotFound,
    PayloadTooLarge,
    ServiceUnavailable,
    Unauthorized,
    VGNClient,
    VGNError,
    raise_for_error,
)
from service.launch.embedded import EmbeddedService
from tests.helpers.scenes import INTRINSICS, BoxScene, circle_views
from vgn_contract.schemas import Intrinsics

KEY = "s3cret-key"
TTL_S = 1.0
POSES = circle_views(4)
DEPTHS = [BoxScene().depth(pose) for pose in POSES]


@pytest.fixture(scope="module")
def strict_server() -> Iterator[EmbeddedService]:
    """No model (the antipodal planner holds a session long enough to see it busy), an API
    key, one session at most and a one-second TTL."""
    env = {"VGN_MODEL": "none", "VGN_API_KEY": KEY, "VGN_MAX_SESSIONS": "1", "VGN_SESSION_TTL_S": str(TTL_S),
           "VGN_TORCH_THREADS": "1"}  # fmt: skip
    with EmbeddedService(env=env) as service:
        yield service


@pytest.fixture
def keyed(strict_server: EmbeddedService) -> Iterator[VGNClient]:
    with VGNClient(strict_server.url, api_key=KEY) as client:
        yield client


def fused_grid(vgn: VGNClient, frames: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    session = vgn.create_session(intrinsics=INTRINSICS)
    for depth, pose in frames:
        vgn.add_frame(session.session_id, depth, pose)
    return vgn.tsdf(session.session_id)


# Non-finite depth ---------------------------------------------------------------------------


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf], ids=["nan", "inf", "-inf"])
def test_non_finite_depth_fuses_as_no_reading(vgn: VGNClient, value: float):
    """A frame with a band of non-finite readings gives the grid that the same frame with zeros
    there gives, and differs from the full frame's: the readings are dropped, not clamped."""
    band = np.zeros(DEPTHS[0].shape, bool)
    band[:, 200:440] = True  # across the box
    holes, zeros = DEPTHS[0].copy(), DEPTHS[0].copy()
    holes[band], zeros[band] = value, 0.0
    with_holes = fused_grid(vgn, [(holes, POSES[0])])
    with_zeros = fused_grid(vgn, [(zeros, POSES[0])])
    full = fused_grid(vgn, [(DEPTHS[0], POSES[0])])
    assert np.array_equal(with_holes, with_zeros)
    assert not np.array_equal(with_holes, full), "the band held surface the full frame sees"


def test_a_frame_of_only_non_finite_depth_changes_nothing_but_the_count(vgn: VGNClient):
    session = vgn.create_session(intrinsics=INTRINSICS)
    vgn.add_frame(session.session_id, DEPTHS[0], POSES[0])
    before = vgn.tsdf(session.session_id)
    result = vgn.add_frame(session.session_id, np.full(DEPTHS[0].shape, np.nan, np.float32), POSES[1])
    assert result.frame_count == 2
    assert np.array_equal(vgn.tsdf(session.session_id), before)


def test_rejected_frames_leave_the_volume_as_it_was(vgn: VGNClient, server: EmbeddedService):
    """Negative depth (400) and a NaN pose (422, sent raw past the client's own check)."""
    session = vgn.create_session(intrinsics=INTRINSICS)
    vgn.add_frame(session.session_id, DEPTHS[0], POSES[0])
    before = vgn.tsdf(session.session_id)
    negative = DEPTHS[1].copy()
    negative[10, 10] = -0.5
    with pytest.raises(BadRequest, match="negative"):
        vgn.add_frame(session.session_id, negative, POSES[1])
    meta = '{"camera_pose": {"position": [NaN, 0, 0.5], "orientation": [0, 0, 0, 1]}}'
    response = httpx.post(f"{server.url}/sessions/{session.session_id}/frames", content=DEPTHS[1].tobytes(),
                          headers={"Content-Type": "application/octet-stream", "X-Frame-Meta": meta})  # fmt: skip
    assert response.status_code == 422, response.text
    assert vgn.session(session.session_id).frame_count == 1
    assert np.array_equal(vgn.tsdf(session.session_id), before)


# API key ------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("headers", "accepted"),
    [
        ({"X-API-Key": KEY}, True),
        ({"x-api-key": KEY}, True),
        ({"Authorization": f"Bearer {KEY}"}, True),
        ({"authorization": f"bearer {KEY}"}, True),
        ({}, False),
        ({"X-API-Key": KEY[:-1]}, False),
        ({"X-API-Key": KEY + "x"}, False),
        ({"Authorization": f"Bearer {KEY.upper()}"}, False),
        ({"Authorization": KEY}, False),
        ({"Authorization": "Basic czNjcmV0LWtleQ=="}, False),
    ],
    ids=[
        "x-api-key",
        "lowercase-name",
        "bearer",
        "lowercase-bearer",
        "none",
        "prefix",
        "longer",
        "other-case",
        "no-scheme",
        "basic",
    ],  # fmt: skip
)
def test_api_key_headers_on_a_real_server(strict_server: EmbeddedService, headers: dict, accepted: bool):
    response = httpx.get(f"{strict_server.url}/sessions", headers=headers)
    if accepted:
        assert response.status_code == 200, response.text
        assert "sessions" in response.json()
    else:
        assert response.status_code == 401
        assert "API key" in response.json()["detail"] and response.headers["www-authenticate"] == "Bearer"


def test_health_checks_need_no_key_on_a_real_server(strict_server: EmbeddedService):
    assert httpx.get(f"{strict_server.url}/healthz").status_code == 200
    assert httpx.get(f"{strict_server.url}/model").status_code == 401


def test_the_client_sends_its_api_key(strict_server: EmbeddedService):
    with VGNClient(strict_server.url, api_key=KEY) as right:
        session = right.create_session(intrinsics=INTRINSICS)
        assert right.add_frame(session.session_id, DEPTHS[0], POSES[0]).frame_count == 1
        right.delete_session(session.session_id)
    for key in (None, "wrong"):
        with VGNClient(strict_server.url, api_key=key) as wrong, pytest.raises(Unauthorized) as refused:
            wrong.sessions()
        assert refused.value.status == 401 and "API key" in str(refused.value)


def vgn_client(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    path = shutil.which("vgn-client")
    assert path, "vgn-client is not installed: run `pip install -e .` (install.sh does)"
    environment = {k: v for k, v in os.environ.items() if k != "VGN_API_KEY"} | (env or {})
    return subprocess.run([path, *args], capture_output=True, text=True, timeout=120, env=environment)


def test_the_cli_sends_its_api_key(strict_server: EmbeddedService):
    url = ["--url", strict_server.url]
    assert vgn_client("sessions", *url, "--api-key", KEY).returncode == 0
    from_env = vgn_client("sessions", *url, env={"VGN_API_KEY": KEY})
    assert from_env.returncode == 0, from_env.stderr
    for refused in (vgn_client("sessions", *url, "--api-key", "wrong"), vgn_client("sessions", *url)):
        assert refused.returncode == 1
        assert "401" in refused.stderr and "API key" in refused.stderr


# Expiry and the session limit ---------------------------------------------------------------


def test_an_expired_session_is_404_over_http(keyed: VGNClient):
    session = keyed.create_session(intrinsics=INTRINSICS)
    keyed.add_frame(session.session_id, DEPTHS[0], POSES[0])
    time.sleep(TTL_S + 0.5)
    for call in (keyed.session, keyed.tsdf, lambda sid: keyed.add_frame(sid, DEPTHS[1], POSES[1])):
        with pytest.raises(NotFound, match="expired") as gone:
            call(session.session_id)
        assert gone.value.status == 404 and session.session_id in str(gone.value)


def plan_unless_evicted(vgn: VGNClient, session_id: str) -> None:
    """Plan with the slow antipodal planner; a create that came first evicts the session."""
    with contextlib.suppress(NotFound):
        vgn.grasps(session_id, planner="antipodal")


def test_all_sessions_busy_is_503_over_http(keyed: VGNClient):
    """With VGN_MAX_SESSIONS=1 and its session planning, a new session cannot evict it: 503
    with the reason; once the plan is done, the idle session is evicted for the new one."""
    session = keyed.create_session(intrinsics=INTRINSICS)
    for depth, pose in zip(DEPTHS, POSES, strict=True):
        keyed.add_frame(session.session_id, depth, pose)
    refused: list[ServiceUnavailable] = []
    # The antipodal planner holds the session for a second or more, but the create may still
    # reach the server before the plan does: each try waits a different head start for the plan.
    for head_start_s in (0.0, 0.2, 0.05, 0.5, 0.1, 0.3, 0.8, 0.02):
        planning = threading.Thread(target=plan_unless_evicted, args=(keyed, session.session_id))
        planning.start()
        time.sleep(head_start_s)
        while planning.is_alive() and not refused:
            try:
                keyed.delete_session(keyed.create_session(intrinsics=INTRINSICS).session_id)
                break  # created before the plan held the session: it was evicted; try again
            except ServiceUnavailable as error:
                refused.append(error)
        planning.join()
        if refused:
            break
        session = keyed.create_session(intrinsics=INTRINSICS)
        for depth, pose in zip(DEPTHS, POSES, strict=True):
            keyed.add_frame(session.session_id, depth, pose)
    assert refused, "no create request met the session busy"
    assert refused[0].status == 503 and "session limit (1)" in str(refused[0]) and "in use" in str(refused[0])
    replacement = keyed.create_session(intrinsics=INTRINSICS)  # the idle session is evicted now
    assert [s.session_id for s in keyed.sessions().sessions] == [replacement.session_id]


# Planning while frames arrive ---------------------------------------------------------------


def test_planning_and_uploads_at_once_lose_no_frame(vgn: VGNClient, server: EmbeddedService):
    """Four threads post 24 frames to one session while two others plan on it: every answer is
    valid, every frame is counted, and the grid equals the same frames fused one by one (to
    float rounding: the running TSDF average depends on the order frames arrive in)."""
    frames = [(DEPTHS[i % 4], POSES[i % 4]) for i in range(24)]
    session = vgn.create_session(intrinsics=INTRINSICS).session_id
    vgn.add_frame(session, *frames[0])
    uploads_done = threading.Event()

    def upload(share: list[tuple[np.ndarray, np.ndarray]]) -> list[int]:
        with VGNClient(server.url) as client:
            return [client.add_frame(session, depth, pose).frame_count for depth, pose in share]

    def plan() -> list[int]:
        counts = []
        with VGNClient(server.url) as client:
            while not uploads_done.is_set() or not counts:
                result = client.grasps(session, threshold=0.0, max_grasps=5)
                assert 1 <= result.frame_count <= len(frames) and len(result.grasps) <= 5
                assert all(0.0 <= g.quality <= 1.0 for g in result.grasps)
                counts.append(result.frame_count)
        return counts

    with ThreadPoolExecutor(6) as pool:
        planners = [pool.submit(plan) for _ in range(2)]
        uploaders = [pool.submit(upload, frames[1 + k :: 4]) for k in range(4)]
        counts = sorted(c for u in uploaders for c in u.result())
        uploads_done.set()
        plans = [p.result() for p in planners]
    assert counts == list(range(2, len(frames) + 1)), "each upload got its own frame count"
    assert all(p == sorted(p) for p in plans), "a planner never saw the volume go back"
    assert vgn.session(session).frame_count == len(frames)
    sequential = fused_grid(vgn, frames)
    assert np.allclose(vgn.tsdf(session), sequential, atol=1e-5)


# Typed errors -------------------------------------------------------------------------------


def test_each_typed_error_matches_its_server_answer(vgn: VGNClient, server: EmbeddedService, keyed):
    session = vgn.create_session(intrinsics=INTRINSICS).session_id
    with pytest.raises(BadRequest) as bad:  # 400: unreadable PNG bytes
        vgn.add_frame(session, b"\x89PNG not really", POSES[0])
    assert bad.value.status == 400
    raw = httpx.post(f"{server.url}/sessions/{session}/frames", content=b"{}",
                     headers={"Content-Type": "text/plain"})  # fmt: skip
    with pytest.raises(BadRequest) as unsupported:  # 415: a media type frames never come in
        raise_for_error(raw)
    assert unsupported.value.status == 415
    with pytest.raises(BadRequest) as invalid:  # 422: the service's schema check
        raise_for_error(httpx.get(f"{server.url}/sessions/{session}/grasps", params={"threshold": 7}))
    assert invalid.value.status == 422 and "threshold" in str(invalid.value)
    with pytest.raises(Conflict) as conflict:  # 409
        vgn.create_session(session_id=session)
    assert conflict.value.status == 409 and session in str(conflict.value)
    large = Intrinsics(width=1280, height=960, fx=1080.0, fy=1080.0, cx=639.5, cy=479.5)
    with pytest.raises(PayloadTooLarge) as too_large:  # 413: 4.9 MB over the server's 4 MiB
        vgn.add_frame(session, np.full((960, 1280), 0.5, np.float32), POSES[0], intrinsics=large)
    assert too_large.value.status == 413
    with pytest.raises(ServiceUnavailable) as no_model:  # 503: the strict server has no model
        keyed.grasps(keyed.create_session(intrinsics=INTRINSICS).session_id)
    assert no_model.value.status == 503 and "no model" in str(no_model.value)
    with pytest.raises(Unauthorized):  # 401
        VGNClient(keyed.url).sessions()
    with pytest.raises(NotFound):  # 404
        vgn.session("no-such-session")
    cloud_as_html = httpx.get(f"{server.url}/sessions/{session}/cloud", headers={"Accept": "text/html"})
    with pytest.raises(VGNError) as unmapped:  # 406 has no class of its own: the base one
        raise_for_error(cloud_as_html)
    assert type(unmapped.value) is VGNError and unmapped.value.status == 406
    for error in (bad, unsupported, invalid, conflict, too_large, no_model):
        assert isinstance(error.value, VGNError) and error.value.detail, "each carries the service's reason"
    assert vgn.session(session).frame_count == 0, "no refused frame was fused"
