"""The session viewer: its data and errors over HTTP, and the page itself in headless Chromium."""

from __future__ import annotations

import io
import json
import re
from pathlib import Path
from urllib.parse import urlencode, urljoin, urlsplit

import httpx
import numpy as np
import pytest
from fastapi.testclient import TestClient
from PIL import Image

from service.core import PlanningService
from service.http_app import create_app
from service.settings import Settings
from service.viewer.scene import grasp_outline, tilt_degrees
from tests.helpers.browser import headless_chromium
from tests.helpers.scenes import INTRINSICS, BoxScene, circle_views
from vgn_contract.gripper_description import default_gripper
from vgn_contract.schemas import Grasp

SCENE = BoxScene()
#: Without the clearance check: it drops every grasp of the random weights on this scene.
OPTIONS = {"threshold": 0.5, "max_grasps": 12, "clearance": "false", "grip": "false"}


def fuse(client, session_id: str, views: int = 6) -> None:
    for pose in circle_views(views):
        files = {
            "meta": (None, f'{{"camera_pose": {{"matrix": {pose.tolist()}}}}}'),
            "depth": ("d.raw", SCENE.depth(pose).tobytes(), "application/octet-stream"),
        }
        assert client.post(f"/sessions/{session_id}/frames", files=files).status_code == 200


@pytest.fixture(scope="module")
def viewer_http(random_checkpoint: Path):
    core = PlanningService.from_settings(Settings(model=random_checkpoint, api_key=None))
    with TestClient(create_app(core=core)) as client:
        client.post("/sessions", json={"session_id": "box", "intrinsics": INTRINSICS.model_dump()})
        fuse(client, "box")
        yield client


def test_gripper_outline_has_the_grasp_width_and_finger_depth() -> None:
    grasp = Grasp(
        position=(0.1, 0.2, 0.3), orientation=(0, 1, 0, 0), approach=(0, 0, -1), width=0.04, quality=0.9
    )
    outline = grasp_outline(grasp)
    left_tip, left_base, right_base, right_tip = (np.array(p) for p in outline[:4])
    assert np.linalg.norm(left_base - right_base) == pytest.approx(0.04)
    # Fingers point along the approach (straight down for this grasp), from the palm.
    np.testing.assert_allclose(left_tip - left_base, [0, 0, -default_gripper().finger_depth], atol=1e-6)
    np.testing.assert_allclose(right_tip - right_base, [0, 0, -default_gripper().finger_depth], atol=1e-6)
    assert outline[4] is None
    assert tilt_degrees(grasp) == 0.0


def test_view_data_matches_the_grasp_query(viewer_http: TestClient) -> None:
    scene = viewer_http.get("/sessions/box/view/data", params=OPTIONS).json()
    planned = viewer_http.get("/sessions/box/grasps", params=OPTIONS).json()
    assert [g["quality"] for g in scene["grasps"]] == [round(g["quality"], 4) for g in planned["grasps"]]
    assert scene["frame_count"] == 6 and scene["threshold"] == 0.5 and len(scene["workspace_edges"]) == 36
    points = np.array(scene["cloud"]["points"])
    assert 0 < len(points) <= scene["cloud"]["total"]
    assert np.percentile(SCENE.distance_to_surface(points), 95) < 0.004
    cropped = viewer_http.get(
        "/sessions/box/view/data", params={**OPTIONS, "crop_min": "0,0,0", "crop_max": "0.3,0.3,0.08"}
    ).json()
    assert all(g["position"][2] <= 0.08 for g in cropped["grasps"])


def test_standalone_view_page_is_self_contained(viewer_http: TestClient) -> None:
    response = viewer_http.get("/sessions/box/view", params={**OPTIONS, "standalone": "true"})
    assert response.status_code == 200 and response.headers["content-type"].startswith("text/html")
    page = response.text
    assert "Plotly" in page and "<script src" not in page and "http://" not in page.split("</head>")[1]
    assert "* plotly.js v" in page and '"session_id":"box"' in page


def test_view_page_loads_plotly_from_the_services_cacheable_route(viewer_http: TestClient) -> None:
    response = viewer_http.get("/sessions/box/view", params=OPTIONS, headers={"Accept-Encoding": "gzip"})
    assert response.status_code == 200 and "* plotly.js v" not in response.text, "the library is not inlined"
    assert response.headers["content-encoding"] == "gzip"
    assert int(response.headers["content-length"]) < len(response.content) / 2
    data = viewer_http.get("/sessions/box/view/data", params=OPTIONS, headers={"Accept-Encoding": "gzip"})
    assert data.headers["content-encoding"] == "gzip" and data.json()["session_id"] == "box"
    (source,) = re.findall(r'<script src="([^"]+)"></script>', response.text)
    script_url = urljoin(str(response.url), source)
    assert urlsplit(script_url).path.startswith("/viewer/plotly-"), script_url
    raw = httpx.Headers({"Accept-Encoding": "identity"})
    plain = viewer_http.get(script_url, headers=raw)
    assert plain.status_code == 200 and plain.headers["content-type"].startswith("text/javascript")
    assert "immutable" in plain.headers["cache-control"] and "content-encoding" not in plain.headers
    assert len(plain.content) > 1_000_000 and b"plotly" in plain.content[:5000].lower()
    packed = viewer_http.get(script_url, headers={"Accept-Encoding": "gzip"})
    assert packed.headers["content-encoding"] == "gzip" and packed.content == plain.content
    assert int(packed.headers["content-length"]) < len(plain.content) / 2
    again = viewer_http.get(script_url, headers={"If-None-Match": plain.headers["etag"]})
    assert again.status_code == 304 and not again.content
    stale = viewer_http.get("/viewer/plotly-0000000000000000.min.js")
    assert stale.status_code == 404 and "reload the page" in stale.json()["detail"]


@pytest.mark.parametrize(
    ("path", "params", "status", "words"),
    [
        ("/sessions/nope/view", {}, 404, ["nope"]),
        ("/sessions/nope/view/data", {}, 404, ["nope"]),
        ("/sessions/box/view", {"threshold": 2}, 422, ["threshold"]),
        ("/sessions/box/view", {"refresh": -1}, 422, ["refresh"]),
        ("/sessions/box/view", {"approach": "0,0,-1"}, 422, ["max_approach_angle"]),
        ("/sessions/box/view", {"crop_min": "0,0"}, 422, ["crop_min"]),
    ],
)
def test_view_rejects_bad_requests(viewer_http: TestClient, path, params, status, words) -> None:
    response = viewer_http.get(path, params=params)
    assert response.status_code == status, response.text
    for word in words:
        assert word in response.text


def test_view_of_an_empty_session(viewer_http: TestClient) -> None:
    viewer_http.post("/sessions", json={"session_id": "empty"})
    scene = viewer_http.get("/sessions/empty/view/data").json()
    assert scene["frame_count"] == 0 and scene["cloud"]["points"] == [] and scene["grasps"] == []
    assert viewer_http.get("/sessions/empty/view").status_code == 200


def test_view_needs_the_api_key(random_checkpoint: Path) -> None:
    core = PlanningService.from_settings(Settings(model=random_checkpoint, api_key="s3cret"))
    with TestClient(create_app(core=core)) as client:
        key = {"X-API-Key": "s3cret"}
        client.post("/sessions", json={"session_id": "k"}, headers=key)
        assert client.get("/sessions/k/view").status_code == 401
        assert client.get("/sessions/k/view/data").status_code == 401
        page = client.get("/sessions/k/view", headers=key)
        assert page.status_code == 200
        (source,) = re.findall(r'<script src="([^"]+)"></script>', page.text)
        assert client.get(urljoin(str(page.url), source)).status_code == 200, "a public library, no data"


def test_view_without_a_model_still_shows_the_surface() -> None:
    core = PlanningService.from_settings(Settings(model="none", api_key=None))
    with TestClient(create_app(core=core)) as client:
        client.post("/sessions", json={"session_id": "m", "intrinsics": INTRINSICS.model_dump()})
        fuse(client, "m", views=2)
        scene = client.get("/sessions/m/view/data").json()
        assert scene["grasps"] == [] and "no model" in scene["planning_error"]
        assert scene["cloud"]["total"] > 0
        assert client.get("/sessions/m/view", params={"planner": "antipodal"}).status_code == 200


def plot_pixels(driver) -> np.ndarray:
    """The 3D plot's area of a screenshot, RGB."""
    shot = Image.open(io.BytesIO(driver.get_screenshot_as_png())).convert("RGB")
    rect = driver.execute_script("return document.getElementById('plot').getBoundingClientRect().toJSON()")
    scale = driver.execute_script("return window.devicePixelRatio")
    box = [round(rect[k] * scale) for k in ("left", "top", "right", "bottom")]
    return np.asarray(shot.crop(box))


def test_page_renders_in_headless_chromium(server, vgn, tmp_path: Path) -> None:
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    session = vgn.create_session(intrinsics=INTRINSICS).session_id
    poses = circle_views(6)
    for pose in poses[:5]:
        vgn.add_frame(session, SCENE.depth(pose), pose)
    expected = vgn.grasps(session, **OPTIONS).grasps
    assert expected, "the scene must give grasps for this test to mean anything"
    with headless_chromium() as driver:
        driver.get(f"{server.url}/sessions/{session}/view?{urlencode({**OPTIONS, 'refresh': 0.5})}")
        WebDriverWait(driver, 60).until(lambda d: d.execute_script("return document.body.dataset.rendered"))
        rows = driver.find_elements(By.CSS_SELECTOR, "#grasp-rows tr")
        assert len(rows) == len(expected)
        shown = [float(row.find_elements(By.TAG_NAME, "td")[1].text) for row in rows]
        np.testing.assert_allclose(shown, [g.quality for g in expected], atol=1e-3)
        pixels = plot_pixels(driver)
        driver.save_screenshot("/tmp/viewer_test.png")
        # Not blank: a good part of the plot is drawn, in many colours (height-shaded surface).
        drawn = np.any(pixels < 235, axis=-1).mean()
        colours = len(np.unique(pixels.reshape(-1, 3) // 16, axis=0))
        assert drawn > 0.05 and colours > 40, (drawn, colours)

        rows[2].click()  # the list is redrawn: find the row again
        selected = driver.find_elements(By.CSS_SELECTOR, "#grasp-rows tr.selected")
        assert [row.get_attribute("data-rank") for row in selected] == ["3"]
        names = driver.execute_script("return document.getElementById('plot').data.map(t => t.name)")
        assert "selected #3" in names

        # Frames keep arriving: the page notices and re-plans on its own.
        vgn.add_frame(session, SCENE.depth(poses[5]), poses[5])
        status = driver.find_element(By.ID, "status")
        WebDriverWait(driver, 30).until(lambda d: status.text.startswith("6 frames"))
        errors = [entry for entry in driver.get_log("browser") if entry["level"] == "SEVERE"]
        assert errors == []


def test_cli_saves_the_viewer(server, vgn, tmp_path: Path, capsys) -> None:
    from client.cli import main

    session = vgn.create_session(intrinsics=INTRINSICS).session_id
    for pose in circle_views(2):
        vgn.add_frame(session, SCENE.depth(pose), pose)
    out = tmp_path / "view.html"
    argv = [
        "view",
        session,
        "--url",
        server.url,
        "--out",
        str(out),
        "--threshold",
        "0.5",
        "--no-clearance",
        "--no-grip",
    ]
    assert main(argv) == 0
    page = out.read_text(encoding="utf-8")
    assert "<script src" not in page, "a saved page opens offline"
    scene = json.loads(page.split('<script id="scene" type="application/json">')[1].split("</script>")[0])
    assert scene["session_id"] == session and scene["frame_count"] == 2 and scene["query"]["refresh"] == 0
    assert scene["grasps"] and scene["query"]["clearance"] is False
    planned = vgn.grasps(session, threshold=0.5, max_grasps=20, clearance=False, grip=False)
    assert len(scene["grasps"]) == len(planned.grasps)
    assert main(["view", "nope", "--url", server.url, "--out", str(tmp_path / "x.html")]) == 1
    assert "404" in capsys.readouterr().err and not (tmp_path / "x.html").exists()
    assert main(["view", session, "--url", server.url, "--out", str(out), "--approach", "0,0,-1"]) == 2
    assert "max_approach_angle" in capsys.readouterr().err
