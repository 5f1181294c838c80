"""``VGN_MAX_FRAME_BYTES`` as enforced by a real server with the default settings: it bounds the
depth image; a whole request body may hold 64 KiB more (the frame's meta, multipart headers),
and the 413 for a frame upload's body says both numbers instead of naming the sum as
``VGN_MAX_FRAME_BYTES`` (other requests' 413 names the sum alone)."""

from __future__ import annotations

import http.client
import json
from collections.abc import Iterator
from urllib.parse import urlsplit

import httpx
import numpy as np
import pytest

from client.http import FRAME_META_HEADER
from service.api.limits import MULTIPART_OVERHEAD
from service.launch.embedded import EmbeddedService
from service.settings import Settings

#: The documented default (README, settings): 32 MiB.
DEFAULT_LIMIT = 33_554_432
#: A 4096 x 2048 float32 depth image is exactly the default limit.
WIDTH, HEIGHT = 4096, 2048
INTRINSICS = {"width": WIDTH, "height": HEIGHT, "fx": 3000.0, "fy": 3000.0, "cx": 2048.0, "cy": 1024.0}
META = json.dumps({"camera_pose": {"matrix": np.eye(4).tolist()}, "intrinsics": INTRINSICS})


@pytest.fixture(scope="module")
def default_server() -> Iterator[EmbeddedService]:
    """A real server on loopback whose frame limit is the default one."""
    env = {"VGN_API_KEY": "", "VGN_TORCH_THREADS": "1", "VGN_MODEL": "none"}
    with EmbeddedService(env=env, unset=("VGN_MAX_FRAME_BYTES",)) as service:
        httpx.post(f"{service.url}/sessions", json={"session_id": "big"}).raise_for_status()
        yield service


def test_the_documented_default_is_the_setting() -> None:
    field = Settings.model_fields["max_frame_bytes"]
    assert Settings().max_frame_bytes == field.default == DEFAULT_LIMIT
    assert "depth image" in field.description and "64 KiB" in field.description
    assert MULTIPART_OVERHEAD == 64 * 1024


def test_a_depth_image_of_exactly_the_limit_is_fused_from_a_larger_multipart_body(default_server) -> None:
    depth = np.zeros((HEIGHT, WIDTH), np.float32).tobytes()
    assert len(depth) == DEFAULT_LIMIT
    files = {"meta": (None, META, "application/json"), "depth": ("d.raw", depth, "application/octet-stream")}
    request = httpx.Request("POST", f"{default_server.url}/sessions/big/frames", files=files)
    assert len(request.read()) > DEFAULT_LIMIT, "the body holds more than the depth image"
    with httpx.Client(timeout=120.0) as client:
        response = client.send(request)
    assert response.status_code == 200, response.text
    assert response.json()["frame_count"] == 1


def test_a_depth_image_over_the_limit_names_the_setting_with_its_value(default_server) -> None:
    depth = bytes(DEFAULT_LIMIT + 4)
    response = httpx.post(
        f"{default_server.url}/sessions/big/frames",
        content=depth,
        headers={"Content-Type": "application/octet-stream", FRAME_META_HEADER: META},
        timeout=120.0,
    )
    assert response.status_code == 413, response.text
    detail = response.json()["detail"]
    assert f"depth image of {DEFAULT_LIMIT + 4} bytes" in detail
    assert f"limit of {DEFAULT_LIMIT} bytes (VGN_MAX_FRAME_BYTES)" in detail


def declared_body_answer(url: str, size: int, path: str = "/sessions/big/frames") -> tuple[int, str]:
    """Status and detail for a request that declares ``size`` body bytes and sends none: the limit
    is checked on the declared length, before any body is read."""
    parts = urlsplit(url)
    connection = http.client.HTTPConnection(parts.hostname, parts.port, timeout=30)
    try:
        connection.putrequest("POST", path)
        connection.putheader("Content-Type", "application/json")
        connection.putheader("Content-Length", str(size))
        connection.endheaders()
        response = connection.getresponse()
        return response.status, json.loads(response.read())["detail"]
    finally:
        connection.close()


def test_a_body_over_the_limit_spells_out_both_numbers(default_server) -> None:
    body_limit = DEFAULT_LIMIT + MULTIPART_OVERHEAD
    status, detail = declared_body_answer(default_server.url, body_limit + 1)
    assert status == 413
    assert f"exceeds the limit of {body_limit} bytes" in detail
    assert f"VGN_MAX_FRAME_BYTES={DEFAULT_LIMIT}" in detail and f"plus {MULTIPART_OVERHEAD}" in detail
    assert f"{body_limit} bytes (VGN_MAX_FRAME_BYTES)" not in detail, "the sum is not the setting"


def test_a_body_over_the_limit_that_is_no_frame_upload_does_not_talk_of_depth_images(default_server) -> None:
    body_limit = DEFAULT_LIMIT + MULTIPART_OVERHEAD
    status, detail = declared_body_answer(default_server.url, 100 * 2**20, path="/sessions")
    assert status == 413
    assert detail == f"request body of {100 * 2**20}+ bytes exceeds the limit of {body_limit} bytes"
