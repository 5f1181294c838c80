"""``openapi.json`` at the repository root is generated from the app and must not drift."""

from __future__ import annotations

import json
from pathlib import Path

from service.openapi import DEFAULT_PATH, render


def test_openapi_json_is_up_to_date():
    committed = Path(DEFAULT_PATH)
    assert committed.exists(), "run: python -m service.openapi"
    assert json.loads(committed.read_text()) == json.loads(render()), (
        "openapi.json is stale: regenerate it with `python -m service.openapi`"
    )


def test_openapi_documents_the_contract():
    document = json.loads(render())
    paths = document["paths"]
    for path in (
        "/sessions",
        "/sessions/{session_id}",
        "/sessions/{session_id}/frames",
        "/sessions/{session_id}/grasps",
        "/sessions/{session_id}/tsdf",
        "/sessions/{session_id}/cloud",
        "/sessions/{session_id}/reset",
        "/healthz",
        "/readyz",
        "/metrics",
        "/model",
    ):
        assert path in paths, path
    frames = paths["/sessions/{session_id}/frames"]["post"]
    assert "multipart/form-data" in frames["requestBody"]["content"]
    grasp_params = {p["name"] for p in paths["/sessions/{session_id}/grasps"]["get"]["parameters"]}
    assert {
        "threshold",
        "max_grasps",
        "nms_size",
        "crop_min",
        "crop_max",
        "approach",
        "max_approach_angle",
    } <= grasp_params
