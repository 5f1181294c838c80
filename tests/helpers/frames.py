"""Frame uploads built by hand for the HTTP API, and reading a session back.

The standard frame is the analytic box scene (``helpers.scenes``) seen from the first of
``circle_views()``, sent as raw float32 metres with ``INTRINSICS``.
"""

from __future__ import annotations

import io
import json
from typing import Any

import httpx
import numpy as np
from fastapi.testclient import TestClient
from PIL import Image

from tests.helpers.scenes import INTRINSICS, BoxScene, circle_views

RAW = "application/octet-stream"
PNG = "image/png"
POSE = circle_views()[0]
DEPTH = BoxScene().depth(POSE)  # (480, 640) float32 metres, the table and the box
DEPTH_MM = np.round(DEPTH * 1000).astype(np.uint16)
INTRINSICS_JSON = INTRINSICS.model_dump()


def meta_json(
    camera_pose: dict | None = None, intrinsics: dict | None = INTRINSICS_JSON, **fields: Any
) -> str:
    """The ``meta`` part: ``POSE`` and ``INTRINSICS`` unless told otherwise."""
    meta: dict[str, Any] = {"camera_pose": camera_pose or {"matrix": POSE.tolist()}, **fields}
    if intrinsics is not None:
        meta["intrinsics"] = intrinsics
    return json.dumps(meta)


def frame_files(
    meta: str | bytes | None = None,
    depth: bytes | None = None,
    media_type: str = RAW,
    filename: str | None = "d.raw",
) -> dict[str, tuple]:
    """Multipart ``files`` of a frame upload; ``meta``/``depth`` default to a valid frame."""
    files: dict[str, tuple] = {}
    if meta is not None:
        files["meta"] = (None, meta, "application/json")
    if depth is not None:
        files["depth"] = (filename, depth, media_type)
    return files


def valid_frame() -> dict[str, tuple]:
    return frame_files(meta_json(), DEPTH.tobytes())


def png(image: Image.Image | np.ndarray) -> bytes:
    image = Image.fromarray(image) if isinstance(image, np.ndarray) else image
    buffer = io.BytesIO()
    image.save(buffer, format="PNG")
    return buffer.getvalue()


def snapshot(client: httpx.Client | TestClient, session_id: str) -> tuple[bytes, int]:
    """The session's TSDF as ``.npy`` bytes and its frame count."""
    grid = client.get(f"/sessions/{session_id}/tsdf")
    info = client.get(f"/sessions/{session_id}")
    assert grid.status_code == 200 and info.status_code == 200
    return grid.content, info.json()["frame_count"]


def open_fused_session(client: httpx.Client | TestClient, session_id: str = "fused") -> str:
    """A session without default intrinsics holding one valid fused frame."""
    assert client.post("/sessions", json={"session_id": session_id}).status_code == 201
    fused = client.post(f"/sessions/{session_id}/frames", files=valid_frame())
    assert fused.status_code == 200, fused.text
    assert fused.json()["frame_count"] == 1
    return session_id
