"""Session snapshots: a session exported and imported carries on exactly as the original, and
a damaged or foreign file is refused with the reason before any session exists."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest

from tests.helpers.scenes import INTRINSICS, BoxScene, circle_views
from vgn_contract import snapshot as fmt

SCENE = BoxScene()
NPZ = {"Content-Type": fmt.MEDIA_TYPE}


def post_frame(http, session_id: str, pose: np.ndarray) -> None:
    meta = json.dumps({"camera_pose": {"matrix": pose.tolist()}})
    headers = {"Content-Type": "application/octet-stream", "X-Frame-Meta": meta}
    response = http.post(
        f"/sessions/{session_id}/frames", content=SCENE.depth(pose).tobytes(), headers=headers
    )
    assert response.status_code == 200, response.text


def fused_session(http, session_id: str, views: int = 3) -> bytes:
    assert (
        http.post(
            "/sessions", json={"session_id": session_id, "intrinsics": INTRINSICS.model_dump()}
        ).status_code
        == 201
    )
    for pose in circle_views(views):
        post_frame(http, session_id, pose)
    response = http.get(f"/sessions/{session_id}/snapshot")
    assert response.status_code == 200 and response.headers["content-type"] == fmt.MEDIA_TYPE
    return response.content


def rewritten(data: bytes, **changes: object) -> bytes:
    """The snapshot with members replaced (arrays) or meta fields changed (anything else)."""
    with np.load(io.BytesIO(data)) as archive:
        arrays = {name: archive[name] for name in archive.files}
    meta = json.loads(arrays[fmt.META].tobytes())
    for name, value in changes.items():
        if isinstance(value, np.ndarray):
            arrays[name] = value
        else:
            meta[name] = value
    arrays[fmt.META] = np.frombuffer(json.dumps(meta).encode(), np.uint8)
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    return buffer.getvalue()


def test_an_imported_session_carries_on_as_the_original(http):
    data = fused_session(http, "original")
    assert fmt.session_id_of(data) == "original" and len(data) < 2_000_000
    imported = http.put("/sessions/copy/snapshot", content=data, headers=NPZ)
    assert imported.status_code == 201, imported.text
    original = http.get("/sessions/original").json()
    assert imported.json()["frame_count"] == 3 and imported.json()["workspace"] == original["workspace"]
    assert imported.json()["intrinsics"] == original["intrinsics"]
    post_frame(http, "original", circle_views(5)[4])  # both go on fusing the same frame
    post_frame(http, "copy", circle_views(5)[4])
    for read in ("tsdf", "cloud"):
        assert http.get(f"/sessions/original/{read}").content == http.get(f"/sessions/copy/{read}").content, (
            read
        )
    query = {"threshold": 0.0, "clearance": "false", "grip": "false", "max_grasps": 10}
    assert (
        http.get("/sessions/original/grasps", params=query).json()["grasps"]
        == (http.get("/sessions/copy/grasps", params=query).json()["grasps"])
    )


def test_a_snapshot_never_overwrites_a_session(http):
    data = fused_session(http, "moving", views=1)
    assert http.put("/sessions/moving/snapshot", content=data, headers=NPZ).status_code == 409
    assert http.delete("/sessions/moving").status_code == 204
    response = http.put("/sessions/moving/snapshot", content=data, headers=NPZ)
    assert response.status_code == 201 and response.json()["session_id"] == "moving"


@pytest.mark.parametrize(
    ("change", "words"),
    [
        (lambda data: b"not a zip", "not a session snapshot"),
        (lambda data: data[: len(data) // 2], "not a session snapshot"),
        (lambda data: rewritten(data, version=99), "version 1"),
        (lambda data: rewritten(data, session_id="../x"), "not a valid session id"),
        (lambda data: rewritten(data, frame_count=-1), "frame_count"),
        (lambda data: rewritten(data, workspace={"resolution": 12}), "settings are invalid"),
        (lambda data: rewritten(data, coarse=np.zeros((16**3, 2), np.float32)), "R = 40"),
        (lambda data: rewritten(data, coarse=np.zeros((40**3, 2), np.float64)), "float32"),
        (lambda data: rewritten(data, coarse=np.full((40**3, 2), np.nan, np.float32)), "out of range"),
        (lambda data: rewritten(data, fine=np.zeros((5, 2), np.float32)), "'fine' must be"),
        (lambda data: rewritten(data, extra=np.zeros(3)), "unknown members"),
    ],
    ids=[
        "junk",
        "truncated",
        "version",
        "id",
        "count",
        "workspace",
        "shape",
        "dtype",
        "nan",
        "fine",
        "extra",
    ],
)
def test_a_bad_snapshot_is_refused_with_its_reason(http, change, words):
    data = fused_session(http, "source", views=1)
    response = http.put("/sessions/target/snapshot", content=change(data), headers=NPZ)
    assert response.status_code == 400 and words in response.json()["detail"], response.text
    assert http.get("/sessions/target").status_code == 404


def test_a_snapshot_needs_its_media_type(http):
    data = fused_session(http, "typed", views=1)
    response = http.put("/sessions/t2/snapshot", content=data, headers={"Content-Type": "application/json"})
    assert response.status_code == 415 and fmt.MEDIA_TYPE in response.json()["detail"]
