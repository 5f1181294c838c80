"""Frames sent as the bare depth image with the meta in the ``X-Frame-Meta`` header (what
the client sends): the same fusion as multipart, and the same clear errors."""

from __future__ import annotations

import io

import numpy as np
import pytest
from fastapi.testclient import TestClient

from tests.helpers.frames import DEPTH, DEPTH_MM, PNG, RAW, frame_files, meta_json, png, snapshot

HEADER = "X-Frame-Meta"


def open_session(http: TestClient, name: str) -> str:
    answer = http.post("/sessions", json={"session_id": name})
    assert answer.status_code == 201, answer.text
    return name


@pytest.mark.parametrize(
    ("body", "media_type"), [(DEPTH.tobytes(), RAW), (png(DEPTH_MM), PNG)], ids=["raw", "png"]
)
def test_a_bare_body_fuses_exactly_as_the_multipart_upload(http: TestClient, body: bytes, media_type: str):
    bare, multipart = open_session(http, "bare"), open_session(http, "multipart")
    meta = meta_json()
    answer = http.post(
        f"/sessions/{bare}/frames", content=body, headers={"Content-Type": media_type, HEADER: meta}
    )
    assert answer.status_code == 200, answer.text
    files = frame_files(meta, body, media_type, "d.png" if media_type == PNG else "d.raw")
    assert http.post(f"/sessions/{multipart}/frames", files=files).status_code == 200
    assert snapshot(http, bare) == snapshot(http, multipart)
    grid = np.load(io.BytesIO(snapshot(http, bare)[0]))
    assert grid.max() > 0.5, "the frame was fused"


@pytest.mark.parametrize(
    ("headers", "body", "status", "words"),
    [
        ({"Content-Type": RAW}, DEPTH.tobytes(), 400, (HEADER,)),
        ({"Content-Type": RAW, HEADER: "{not json"}, DEPTH.tobytes(), 422, ("meta",)),
        ({"Content-Type": RAW, HEADER: meta_json()}, DEPTH.tobytes()[:-4], 400, ("bytes",)),
        ({"Content-Type": "text/plain", HEADER: meta_json()}, DEPTH.tobytes(), 415, ("text/plain", RAW, PNG)),
    ],
    ids=["no-meta-header", "meta-not-json", "short-body", "text-plain"],
)
def test_a_bad_bare_frame_is_named_and_changes_nothing(http: TestClient, headers, body, status, words):
    session = open_session(http, "s")
    before = snapshot(http, session)
    answer = http.post(f"/sessions/{session}/frames", content=body, headers=headers)
    assert answer.status_code == status, answer.text
    detail = answer.json()["detail"] if isinstance(answer.json()["detail"], str) else answer.text
    for word in words:
        assert word in detail, (word, detail)
    assert snapshot(http, session) == before
