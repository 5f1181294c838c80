"""Every endpoint refuses bad input with a 4xx JSON error that names the problem, never a 500.

Frames are checked hardest: whatever is wrong with an upload (pose, intrinsics, depth encoding,
multipart framing, size), the answer says what, and the session's volume and frame count stay
exactly as they were. Sessions, grasp queries, the cloud's content negotiation, a service with
no model and the API key are covered too. Everything runs against the real app (random
weights), in-process or behind a real uvicorn.
"""

from __future__ import annotations

import io
import json
import struct
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from fastapi.testclient import TestClient
from PIL import Image

from client.http import VGNClient
from service.core import PlanningService
from service.http_app import MULTIPART_OVERHEAD, create_app
from service.launch.embedded import EmbeddedService
from service.settings import Settings
from tests.helpers.frames import (
    DEPTH,
    DEPTH_MM,
    INTRINSICS_JSON,
    PNG,
    POSE,
    RAW,
    frame_files,
    meta_json,
    open_fused_session,
    png,
    snapshot,
    valid_frame,
)
from tests.helpers.scenes import INTRINSICS, BoxScene

MEGA = 1024 * 1024


# Building uploads ------------------------------------------------------------------------
def png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def huge_png_header(side: int = 20000) -> bytes:
    """A tiny PNG that declares a ``side``×``side`` 16-bit image (a decompression bomb)."""
    header = struct.pack(">IIBBBBB", side, side, 16, 0, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + png_chunk(b"IHDR", header)
        + png_chunk(b"IDAT", zlib.compress(b""))
        + png_chunk(b"IEND", b"")
    )


def encoded_multipart(files: dict[str, tuple]) -> tuple[bytes, str]:
    """The body and content type httpx would send for ``files``, to stream by hand."""
    request = httpx.Request("POST", "http://encoder.invalid/", files=files)
    return request.read(), request.headers["content-type"]


def chunks(body: bytes, size: int = 64 * 1024) -> Iterator[bytes]:
    """Body as a generator, so httpx sends it chunked, without ``Content-Length``."""
    for start in range(0, len(body), size):
        yield body[start : start + size]


# Reading answers -------------------------------------------------------------------------
def error_text(response: httpx.Response, status: int) -> str:
    """Check a JSON error of ``status``; its human-readable text (``message`` for a 422)."""
    assert response.status_code == status, response.text
    assert response.headers["content-type"].startswith("application/json"), response.headers
    body = response.json()
    if status == 422:
        assert isinstance(body["detail"], list) and body["detail"], body
        return body["message"]
    assert isinstance(body["detail"], str), body
    return body["detail"]


def assert_names(text: str, *needles: str) -> None:
    for needle in needles:
        assert needle in text, f"{needle!r} not in {text!r}"


def grid_of(client: httpx.Client | TestClient, session_id: str) -> np.ndarray:
    return np.load(io.BytesIO(client.get(f"/sessions/{session_id}/tsdf").content), allow_pickle=False)


def app_client(**settings: Any) -> TestClient:
    """A client of an app over ``Settings(**settings)`` (use as a context manager)."""
    return TestClient(create_app(core=PlanningService.from_settings(Settings(**settings))))


@pytest.fixture(scope="module")
def shared_http(random_checkpoint: Path) -> Iterator[TestClient]:
    """One app (the ``http`` fixture's settings) for the parametrised batteries, whose cases
    change nothing: a fresh app per case would spend ~0.5 s each loading the weights."""
    with app_client(model=random_checkpoint, max_sessions=8, session_ttl_s=600, api_key=None) as client:
        yield client


@pytest.fixture(scope="module")
def fused(shared_http: TestClient) -> str:
    return open_fused_session(shared_http)


# Frames ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class BadFrame:
    """A rejected upload: ``request()`` gives the ``client.post`` keyword arguments."""

    request: Callable[[], dict[str, Any]]
    status: int
    needles: tuple[str, ...]


def files_of(
    meta: str | bytes | None = None,
    depth: bytes | None = None,
    media_type: str = RAW,
    filename: str | None = "d.raw",
) -> Callable[[], dict[str, Any]]:
    """A lazy request with these parts; ``meta``/``depth`` default to the valid ones."""
    return lambda: {
        "files": frame_files(
            meta_json() if meta is None else meta,
            DEPTH.tobytes() if depth is None else depth,
            media_type,
            filename,
        )
    }


def pose_meta(**camera_pose: Any) -> str:
    return meta_json(camera_pose=camera_pose)


def matrix_meta(matrix: np.ndarray | list) -> str:
    return meta_json(camera_pose={"matrix": np.asarray(matrix).tolist()})


def intrinsics_meta(**changes: Any) -> str:
    return meta_json(intrinsics={**INTRINSICS_JSON, **changes})


SCALED = np.diag([2.0, 2.0, 2.0, 1.0]) @ POSE
REFLECTED = POSE @ np.diag([1.0, 1.0, -1.0, 1.0])
BAD_LAST_ROW = np.vstack([POSE[:3], [0.0, 0.0, 1.0, 1.0]])
NAN_QUATERNION = (
    '{"camera_pose": {"position": [0.1, 0.2, 0.6], "orientation": [NaN, 0.0, 0.0, 1.0]}, '
    f'"intrinsics": {INTRINSICS.model_dump_json()}}}'
)
NEGATIVE_DEPTH = np.where(np.arange(DEPTH.size).reshape(DEPTH.shape) % 97 == 0, -0.5, DEPTH).astype(
    np.float32
)

BAD_FRAMES = [
    # Camera pose.
    pytest.param(
        BadFrame(
            files_of(pose_meta(position=[0.1, 0.2, 0.6], orientation=[0, 0, 0, 2])),
            422,
            ("orientation", "unit length"),
        ),
        id="non-unit-quaternion",
    ),
    pytest.param(BadFrame(files_of(NAN_QUATERNION), 422, ("orientation", "finite")), id="nan-quaternion"),
    pytest.param(
        BadFrame(
            files_of(meta_json(camera_pose={"position": [0.1, 1e400, 0.6]})),
            422,
            ("camera_pose.position", "finite"),
        ),
        id="infinite-position",
    ),
    pytest.param(
        BadFrame(files_of(matrix_meta(SCALED)), 422, ("camera_pose", "not orthonormal")),
        id="matrix-scaled-rotation",
    ),
    pytest.param(
        BadFrame(files_of(matrix_meta(REFLECTED)), 422, ("camera_pose", "reflection")), id="matrix-reflection"
    ),
    pytest.param(
        BadFrame(files_of(matrix_meta(BAD_LAST_ROW)), 422, ("camera_pose", "last row")),
        id="matrix-bad-last-row",
    ),
    pytest.param(BadFrame(files_of(matrix_meta(POSE[:3, :3])), 422, ("camera_pose", "4x4")), id="matrix-3x3"),
    pytest.param(
        BadFrame(
            files_of(meta_json(camera_pose={"matrix": POSE.tolist(), "position": [0, 0, 0]})),
            422,
            ("camera_pose", "not both"),
        ),
        id="matrix-and-position",
    ),
    # Intrinsics.
    pytest.param(
        BadFrame(files_of(intrinsics_meta(fx=0.0)), 422, ("intrinsics.fx", "greater than 0")), id="fx-zero"
    ),
    pytest.param(BadFrame(files_of(intrinsics_meta(fy=-540.0)), 422, ("intrinsics.fy",)), id="fy-negative"),
    pytest.param(
        BadFrame(files_of(intrinsics_meta(cx=700.0)), 422, ("intrinsics", "principal point")),
        id="cx-outside-image",
    ),
    pytest.param(BadFrame(files_of(intrinsics_meta(width=0)), 422, ("intrinsics.width",)), id="width-zero"),
    pytest.param(
        BadFrame(files_of(meta_json(intrinsics=None)), 400, ("no intrinsics",)), id="no-intrinsics-anywhere"
    ),
    # Other meta fields and the meta part itself.
    pytest.param(BadFrame(files_of(meta_json(depth_scale=0)), 422, ("depth_scale",)), id="depth-scale-zero"),
    pytest.param(BadFrame(files_of(meta_json(max_depth=-1.0)), 422, ("max_depth",)), id="max-depth-negative"),
    pytest.param(
        BadFrame(files_of(meta_json(colour="red")), 422, ("colour", "Extra inputs")), id="meta-unknown-field"
    ),
    pytest.param(BadFrame(files_of("camera_pose=identity"), 422, ("meta", "JSON")), id="meta-not-json"),
    pytest.param(BadFrame(files_of("[1, 2]"), 422, ("meta", "object")), id="meta-not-an-object"),
    # Raw float32 depth.
    pytest.param(
        BadFrame(files_of(depth=DEPTH[:, :320].tobytes()), 400, ("614400 bytes", "1228800 bytes")),
        id="raw-wrong-byte-count",
    ),
    pytest.param(BadFrame(files_of(depth=NEGATIVE_DEPTH.tobytes()), 400, ("negative",)), id="raw-negative"),
    # PNG depth.
    pytest.param(
        BadFrame(
            files_of(depth=b"this is not a PNG at all", media_type=PNG),
            400,
            ("PNG cannot be read: 24 bytes with no image header",),
        ),  # fmt: skip
        id="png-garbage",
    ),
    pytest.param(
        BadFrame(files_of(depth=png(DEPTH_MM)[:2000], media_type=PNG), 400, ("PNG cannot be read",)),
        id="png-truncated",
    ),
    pytest.param(
        BadFrame(files_of(depth=png((DEPTH * 100).astype(np.uint8)), media_type=PNG), 400, ("16-bit", "'L'")),
        id="png-8-bit",
    ),
    pytest.param(
        BadFrame(files_of(depth=png(Image.new("RGB", (640, 480))), media_type=PNG), 400, ("16-bit", "'RGB'")),
        id="png-rgb",
    ),
    pytest.param(
        BadFrame(files_of(depth=png(DEPTH_MM[::2, ::2].copy()), media_type=PNG), 400, ("320x240", "640x480")),
        id="png-16-bit-wrong-size",
    ),
    pytest.param(
        BadFrame(files_of(depth=huge_png_header(), media_type=PNG), 400, ("PNG",)),
        id="png-decompression-bomb",
    ),
    # Media types and multipart framing.
    pytest.param(
        BadFrame(files_of(depth=DEPTH.tobytes(), media_type="text/plain"), 415, ("text/plain", PNG, RAW)),
        id="depth-text-plain",
    ),
    pytest.param(
        BadFrame(lambda: {"json": json.loads(meta_json())}, 415, ("multipart/form-data", "application/json")),
        id="json-body",
    ),
    pytest.param(
        BadFrame(lambda: {"files": frame_files(depth=DEPTH.tobytes())}, 400, ("lacks", "meta")),
        id="missing-meta",
    ),
    pytest.param(
        BadFrame(lambda: {"files": frame_files(meta=meta_json())}, 400, ("lacks", "depth")),
        id="missing-depth",
    ),
    pytest.param(
        BadFrame(
            lambda: {"files": frame_files(meta_json(), DEPTH.tobytes(), filename=None)},
            400,
            ("depth", "file part"),
        ),
        id="depth-not-a-file-part",
    ),
    pytest.param(
        BadFrame(
            lambda: {"content": b"--x\r\n", "headers": {"content-type": "multipart/form-data"}},
            400,
            ("boundary",),
        ),
        id="multipart-without-boundary",
    ),
]


@pytest.mark.parametrize("bad", BAD_FRAMES)
def test_rejected_frame_is_named_and_leaves_the_session_unchanged(
    shared_http: TestClient, fused: str, bad: BadFrame
) -> None:
    before = snapshot(shared_http, fused)
    response = shared_http.post(f"/sessions/{fused}/frames", **bad.request())
    assert_names(error_text(response, bad.status), *bad.needles)
    assert snapshot(shared_http, fused) == before


def test_fused_session_is_not_empty(shared_http: TestClient, fused: str) -> None:
    """Guards the test above: an unchanged grid must be a grid with something in it."""
    assert np.count_nonzero(grid_of(shared_http, fused)) > 1000


def test_frame_for_unknown_session_is_404_and_creates_nothing(http: TestClient) -> None:
    response = http.post("/sessions/nosuch/frames", files=valid_frame())
    assert_names(error_text(response, 404), "'nosuch'", "does not exist")
    assert http.get("/sessions/nosuch").status_code == 404


@pytest.mark.parametrize("depth_scale", [1000.0, 4000.0, 250.0], ids=["mm", "quarter-mm", "4mm"])
def test_16_bit_png_frame_fuses_like_the_same_depth_sent_raw(http: TestClient, depth_scale: float) -> None:
    """Each scale (units per metre) is honoured: a camera in quarter millimetres or 4 mm units fuses
    the same surface as the metres it encodes."""
    for session_id in ("png", "raw"):
        assert http.post("/sessions", json={"session_id": session_id}).status_code == 201
    encoded = np.round(DEPTH * depth_scale).astype(np.uint16)
    as_png = http.post(
        "/sessions/png/frames",
        files=frame_files(meta_json(depth_scale=depth_scale), png(encoded), PNG, "d.png"),
    )
    metres = (encoded.astype(np.float32) / np.float32(depth_scale)).astype(np.float32)
    as_raw = http.post("/sessions/raw/frames", files=frame_files(meta_json(), metres.tobytes()))
    assert as_png.status_code == 200, as_png.text
    assert as_raw.status_code == 200, as_raw.text
    png_grid, raw_grid = grid_of(http, "png"), grid_of(http, "raw")
    assert np.count_nonzero(raw_grid) > 1000
    np.testing.assert_allclose(png_grid, raw_grid, atol=1e-3, rtol=0)


# Body size -------------------------------------------------------------------------------
SMALL_LIMIT = 64 * 1024


@pytest.fixture
def small_limit_http(random_checkpoint: Path) -> Iterator[TestClient]:
    with app_client(model=random_checkpoint, max_frame_bytes=SMALL_LIMIT, api_key=None) as client:
        yield client


@pytest.mark.parametrize("chunked", [False, True], ids=["content-length", "chunked"])
def test_oversize_frame_is_413_in_process(small_limit_http: TestClient, chunked: bool) -> None:
    # A session holding a small valid frame (80x60 float32 fits the 64 KiB limit).
    small = INTRINSICS.model_copy(
        update={"width": 80, "height": 60, "cx": 39.5, "cy": 29.5, "fx": 67.5, "fy": 67.5}
    )
    session_id = "small"
    assert small_limit_http.post("/sessions", json={"session_id": session_id}).status_code == 201
    small_depth = BoxScene().depth(POSE, small)
    accepted = small_limit_http.post(
        f"/sessions/{session_id}/frames",
        files=frame_files(meta_json(intrinsics=small.model_dump()), small_depth.tobytes()),
    )
    assert accepted.status_code == 200, accepted.text
    before = snapshot(small_limit_http, session_id)

    body, content_type = encoded_multipart(valid_frame())  # 640x480 float32: 1.2 MB
    assert len(body) > SMALL_LIMIT + MULTIPART_OVERHEAD
    response = small_limit_http.post(
        f"/sessions/{session_id}/frames",
        headers={"content-type": content_type},
        content=chunks(body) if chunked else body,
    )
    assert ("content-length" in response.request.headers) is not chunked
    assert_names(
        error_text(response, 413),
        "exceeds the limit",
        str(SMALL_LIMIT + MULTIPART_OVERHEAD),
        "VGN_MAX_FRAME_BYTES",
    )
    assert snapshot(small_limit_http, session_id) == before


def oversize_session_body() -> bytes:
    """A valid ``SessionCreate`` JSON padded past the small app's body limit."""
    return b'{"session_id": "padded"' + b" " * (SMALL_LIMIT + MULTIPART_OVERHEAD) + b"}"


def test_oversize_json_body_is_413(small_limit_http: TestClient) -> None:
    response = small_limit_http.post(
        "/sessions", content=oversize_session_body(), headers={"content-type": "application/json"}
    )
    text = error_text(response, 413)
    assert_names(text, "exceeds the limit")
    assert "depth" not in text and "frame" not in text, "a session body is no frame upload"
    assert small_limit_http.get("/sessions/padded").status_code == 404


def test_oversize_chunked_json_body_is_413(small_limit_http: TestClient) -> None:
    response = small_limit_http.post(
        "/sessions", content=chunks(oversize_session_body()), headers={"content-type": "application/json"}
    )
    assert "content-length" not in response.request.headers
    text = error_text(response, 413)
    assert_names(text, "exceeds the limit")
    assert "depth" not in text and "frame" not in text


@pytest.mark.parametrize("chunked", [False, True], ids=["content-length", "chunked"])
def test_oversize_frame_is_413_from_a_real_server(
    server: EmbeddedService, vgn: VGNClient, chunked: bool
) -> None:
    limit = 4 * MEGA + MULTIPART_OVERHEAD  # the fixture's VGN_MAX_FRAME_BYTES plus the multipart allowance
    session_id = f"oversize-{'chunked' if chunked else 'sized'}"
    with httpx.Client(base_url=server.url, timeout=60.0) as client:
        open_fused_session(client, session_id)
        before = snapshot(client, session_id)
        big = np.zeros((1200, 1000), dtype=np.float32)  # 4.8 MB of raw depth
        intrinsics = {"width": 1000, "height": 1200, "fx": 900.0, "fy": 900.0, "cx": 500.0, "cy": 600.0}
        body, content_type = encoded_multipart(frame_files(meta_json(intrinsics=intrinsics), big.tobytes()))
        assert len(body) > limit
        response = client.post(
            f"/sessions/{session_id}/frames",
            headers={"content-type": content_type},
            content=chunks(body) if chunked else body,
        )
        assert ("content-length" in response.request.headers) is not chunked
        assert_names(error_text(response, 413), "exceeds the limit", str(limit), "VGN_MAX_FRAME_BYTES")
        assert snapshot(client, session_id) == before
    vgn.delete_session(session_id)


# Sessions --------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("spec", "needles"),
    [
        pytest.param(
            {"workspace": {"resolution": 44}}, ("workspace.resolution", "multiple of 8"), id="resolution-44"
        ),
        pytest.param(
            {"workspace": {"size": -0.3}}, ("workspace.size", "greater than 0.01"), id="negative-size"
        ),
        pytest.param({"session_id": "no spaces!"}, ("session_id", "pattern"), id="bad-session-id"),
        pytest.param({"session_id": "-leading-dash"}, ("session_id",), id="session-id-leading-dash"),
        pytest.param({"colour": "red"}, ("colour", "Extra inputs"), id="unknown-field"),
        pytest.param(
            {"intrinsics": {**INTRINSICS_JSON, "cy": -1.0}},
            ("intrinsics", "principal point"),
            id="bad-intrinsics",
        ),
        pytest.param(
            {"workspace": {"pose": {"matrix": SCALED.tolist()}}},
            ("workspace.pose", "not orthonormal"),
            id="non-rigid-workspace-pose",
        ),
    ],
)
def test_bad_session_spec_is_422(shared_http: TestClient, spec: dict, needles: tuple[str, ...]) -> None:
    before = shared_http.get("/sessions").json()["sessions"]
    response = shared_http.post("/sessions", json=spec)
    assert_names(error_text(response, 422), *needles)
    assert shared_http.get("/sessions").json()["sessions"] == before


def test_session_body_that_is_not_json_is_422(http: TestClient) -> None:
    response = http.post("/sessions", content=b"{session_id: x", headers={"content-type": "application/json"})
    assert_names(error_text(response, 422), "body", "JSON")


def test_duplicate_session_id_is_409(http: TestClient) -> None:
    assert http.post("/sessions", json={"session_id": "twice"}).status_code == 201
    response = http.post("/sessions", json={"session_id": "twice"})
    assert_names(error_text(response, 409), "'twice'", "already exists")
    assert len(http.get("/sessions").json()["sessions"]) == 1


@pytest.mark.parametrize(
    ("method", "suffix"),
    [
        ("GET", ""),
        ("DELETE", ""),
        ("POST", "/reset"),
        ("GET", "/grasps"),
        ("GET", "/tsdf"),
        ("GET", "/cloud"),
    ],
)
def test_unknown_session_is_404_naming_it(shared_http: TestClient, method: str, suffix: str) -> None:
    response = shared_http.request(method, f"/sessions/ghost-42{suffix}")
    assert_names(error_text(response, 404), "'ghost-42'", "does not exist")


# Grasp queries ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("params", "needles"),
    [
        pytest.param({"threshold": 1.5}, ("threshold", "less than or equal to 1"), id="threshold-above-1"),
        pytest.param({"threshold": "high"}, ("threshold",), id="threshold-not-a-number"),
        pytest.param({"threshold": "nan"}, ("threshold", "finite number"), id="threshold-nan"),
        pytest.param({"max_grasps": 0}, ("max_grasps", "greater than or equal to 1"), id="max-grasps-0"),
        pytest.param({"nms_size": 0}, ("nms_size",), id="nms-size-0"),
        pytest.param(
            {"crop_min": "0.2,0,0", "crop_max": "0.1,0.3,0.3"},
            ("crop_min", "below crop_max"),
            id="crop-min-not-below-max",
        ),
        pytest.param(
            {"crop_min": "0,0", "crop_max": "0.3,0.3,0.3"}, ("crop_min", "three"), id="crop-min-two-numbers"
        ),
        pytest.param({"crop_max": "a,b,c"}, ("crop_max", "three"), id="crop-max-not-numbers"),
        pytest.param(
            {"approach": "0,0,-1"},
            ("approach", "max_approach_angle", "together"),
            id="approach-without-angle",
        ),
        pytest.param(
            {"max_approach_angle": 30},
            ("approach", "max_approach_angle", "together"),
            id="angle-without-approach",
        ),
        pytest.param(
            {"approach": "0,0,0", "max_approach_angle": 30}, ("approach", "non-zero"), id="zero-approach"
        ),
        pytest.param(
            {"approach": "0,0,-1", "max_approach_angle": 270}, ("max_approach_angle",), id="angle-above-180"
        ),
        pytest.param({"colour": "red"}, ("colour", "Extra inputs"), id="unknown-parameter"),
    ],
)
def test_bad_grasp_query_is_422_naming_the_field(
    shared_http: TestClient, fused: str, params: dict, needles: tuple[str, ...]
) -> None:
    response = shared_http.get(f"/sessions/{fused}/grasps", params=params)
    assert_names(error_text(response, 422), *needles)


def test_valid_grasp_query_is_accepted(shared_http: TestClient, fused: str) -> None:
    """The refusals above are about the values, not the parameters themselves: a query with
    every option answers with grasps that meet each of them. Without the clearance and grip
    checks: they drop every grasp of the random weights on this scene."""
    unchecked = {"threshold": 0.5, "clearance": "false", "grip": "false"}
    unfiltered = shared_http.get(f"/sessions/{fused}/grasps", params=unchecked).json()["grasps"]
    assert unfiltered, "the fused box has grasps"
    approach = unfiltered[0]["approach"]
    params = {
        **unchecked,
        "turn_average": "true",
        "max_grasps": 3,
        "crop_min": "0,0,0",
        "crop_max": "0.3,0.3,0.3",
        "approach": ",".join(f"{x:.6f}" for x in approach),
        "max_approach_angle": 60,
    }
    response = shared_http.get(f"/sessions/{fused}/grasps", params=params)
    assert response.status_code == 200, response.text
    grasps = response.json()["grasps"]
    assert 1 <= len(grasps) <= 3, "at least the grasp the cone is aimed along passes every filter"
    for grasp in grasps:
        assert grasp["quality"] >= 0.5 and all(0 <= x <= 0.3 for x in grasp["position"])
        assert np.dot(grasp["approach"], approach) >= np.cos(np.radians(60)) - 1e-6


@pytest.mark.parametrize("accept", ["text/html", "application/json"])
def test_cloud_in_an_unserved_media_type_is_406(shared_http: TestClient, fused: str, accept: str) -> None:
    response = shared_http.get(f"/sessions/{fused}/cloud", headers={"Accept": accept})
    assert_names(error_text(response, 406), accept, "application/x-npy", "application/x-ply")


# No model --------------------------------------------------------------------------------
@pytest.fixture
def no_model_http() -> Iterator[TestClient]:
    settings = Settings(model="none", api_key=None)  # VGN_MODEL=none, even though a default ships
    with TestClient(create_app(core=PlanningService.from_settings(settings))) as client:
        yield client


def test_vgn_model_none_turns_the_model_off(monkeypatch, tmp_path: Path) -> None:
    monkeypatch.setenv("VGN_MODEL", "None")
    assert Settings().model_path() is None
    monkeypatch.setenv("VGN_MODEL", str(tmp_path / "vgn.safetensors"))
    assert Settings().model_path() == tmp_path / "vgn.safetensors"


def test_without_a_model_the_service_is_live_but_not_ready(no_model_http: TestClient) -> None:
    assert no_model_http.get("/healthz").status_code == 200
    ready = no_model_http.get("/readyz")
    assert ready.status_code == 503
    assert ready.headers["content-type"].startswith("application/json")
    assert ready.json()["ready"] is False
    assert_names(ready.json()["detail"], "no model is configured", "VGN_MODEL")


def test_without_a_model_frames_fuse_but_grasps_are_503(no_model_http: TestClient) -> None:
    session_id = open_fused_session(no_model_http)  # frames are accepted (200) without a model
    response = no_model_http.get(f"/sessions/{session_id}/grasps")
    assert_names(error_text(response, 503), "no model is configured", "VGN_MODEL")
    assert snapshot(no_model_http, session_id)[1] == 1


# API key ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def keyed_http(random_checkpoint: Path) -> Iterator[TestClient]:
    with app_client(model=random_checkpoint, api_key="s3cret") as client:
        yield client


@pytest.mark.parametrize(
    ("headers", "status"),
    [
        pytest.param({}, 401, id="no-key"),
        pytest.param({"X-API-Key": "s3cret"}, 201, id="x-api-key"),
        pytest.param({"Authorization": "Bearer s3cret"}, 201, id="bearer"),
        pytest.param({"X-API-Key": "wrong"}, 401, id="wrong-x-api-key"),
        pytest.param({"Authorization": "Bearer wrong"}, 401, id="wrong-bearer"),
        pytest.param({"Authorization": "Basic czNjcmV0"}, 401, id="basic-auth"),
    ],
)
def test_api_key_guards_the_api(keyed_http: TestClient, headers: dict[str, str], status: int) -> None:
    response = keyed_http.post("/sessions", json={}, headers=headers)
    if status == 401:
        assert_names(error_text(response, 401), "API key", "X-API-Key", "Bearer")
        assert response.headers["www-authenticate"] == "Bearer"
    else:
        assert response.status_code == status, response.text


def test_health_checks_need_no_api_key(keyed_http: TestClient) -> None:
    assert keyed_http.get("/healthz").status_code == 200
    assert keyed_http.get("/readyz").status_code == 200
    assert keyed_http.get("/model").status_code == 401
