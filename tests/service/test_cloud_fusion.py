"""The cloud volume's queue: compact frames, fused off the request path, bounded, never lost."""

from __future__ import annotations

import threading
import time

import httpx
import numpy as np
import pytest
from fastapi.testclient import TestClient
from scipy.spatial import cKDTree

from client.http import VGNClient
from service.cloud_fusion import CloudFusion
from service.core import PlanningService
from service.http_app import create_app
from service.settings import Settings
from service.tsdf import SceneVolume, TSDFVolume, compact_depth
from tests.helpers.scenes import INTRINSICS, BoxScene, circle_views
from vgn_contract.schemas import SessionCreate

SCENE = BoxScene()
VOXEL = 0.3 / 120
#: Views at 0.45, 0.6 and 0.8 m.
VIEWS = (
    circle_views(3, distance=0.45, tilt_deg=20) + circle_views(3) + circle_views(3, distance=0.8, tilt_deg=45)
)
DEPTHS = [SCENE.depth(pose) for pose in VIEWS]


def volume(fusion: CloudFusion, max_pending: int = 16) -> SceneVolume:
    return SceneVolume(0.3, 40, np.eye(4), cloud_resolution=120, max_pending=max_pending, fusion=fusion)


def reference_cloud(indices: range | list[int]) -> np.ndarray:
    """The same frames fused into a queue that never fills and is fused on reading."""
    scene = volume(CloudFusion(idle_s=3600), max_pending=1000)
    for k in indices:
        scene.integrate(DEPTHS[k], INTRINSICS, VIEWS[k], 2.0)
    return scene.cloud()


def wait_until(predicate, timeout_s: float = 20.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.01)


def test_float16_frames_give_the_cloud_of_float32_frames_within_a_voxel():
    """Queued float16 frames: every point within 3/4 of a voxel of the cloud of the float32
    frames and the other way round (99 % within a tenth), normals within 2° (p95)."""
    full = TSDFVolume(0.3, 120)
    for depth, pose in zip(DEPTHS, VIEWS, strict=True):
        full.integrate(depth, INTRINSICS, pose, 2.0)
    points, normals = full.surface_cloud()
    cloud = reference_cloud(range(len(VIEWS)))
    near, index = cKDTree(points).query(cloud[:, :3])
    back = cKDTree(cloud[:, :3]).query(points)[0]
    assert near.max() < 0.75 * VOXEL and back.max() < 0.75 * VOXEL
    assert np.percentile(near, 99) < 0.1 * VOXEL and np.percentile(back, 99) < 0.1 * VOXEL
    cosine = np.clip(np.sum(cloud[:, 3:] * normals[index], axis=1), -1.0, 1.0)
    assert np.percentile(np.degrees(np.arccos(cosine)), 95) < 2.0
    compact = compact_depth(DEPTHS[4])
    assert compact.dtype == np.float16 and compact.shape == (480, 640)
    assert compact.nbytes * 2 == DEPTHS[4].nbytes


def test_queue_is_bounded_and_no_frame_is_lost():
    """A worker that never finds the uploads idle still makes room when the queue is full."""
    scene = volume(CloudFusion(idle_s=3600), max_pending=3)
    for k in range(len(VIEWS)):
        scene.integrate(DEPTHS[k], INTRINSICS, VIEWS[k], 2.0)
        assert scene.pending <= 3
    np.testing.assert_allclose(scene.cloud(), reference_cloud(range(len(VIEWS))), atol=1e-6)
    assert scene.pending == 0


def test_byte_budget_bounds_all_queues_together():
    one_frame = compact_depth(DEPTHS[4]).nbytes
    fusion = CloudFusion(idle_s=3600, max_queued_bytes=3 * one_frame)
    scenes = [volume(fusion, max_pending=100) for _ in range(2)]
    for k in range(3, 9):
        for scene in scenes:
            scene.integrate(DEPTHS[k], INTRINSICS, VIEWS[k], 2.0)
            assert fusion.queued_bytes <= 4 * one_frame  # a queue with nothing in it may take one
    for scene in scenes:
        np.testing.assert_allclose(scene.cloud(), reference_cloud(range(3, 9)), atol=1e-6)
    assert fusion.queued_bytes == 0


def test_worker_fuses_in_lulls_once_the_cloud_was_read():
    fusion = CloudFusion(idle_s=0.01)
    scene, lazy = volume(fusion), volume(fusion)
    assert len(scene.cloud()) == 0  # a cloud reader: kept fused in the background from now on
    for k in range(3):
        scene.integrate(DEPTHS[k], INTRINSICS, VIEWS[k], 2.0)
        lazy.integrate(DEPTHS[k], INTRINSICS, VIEWS[k], 2.0)
    wait_until(lambda: scene.pending == 0)
    time.sleep(0.1)
    assert lazy.pending == 3, "a session never read and a queue under a quarter full waits for a read"
    lazy.integrate(DEPTHS[3], INTRINSICS, VIEWS[3], 2.0)  # 4 of 16: worth fusing now
    wait_until(lambda: lazy.pending == 0)
    np.testing.assert_allclose(scene.cloud(), reference_cloud(range(3)), atol=1e-6)
    np.testing.assert_allclose(lazy.cloud(), reference_cloud(range(4)), atol=1e-6)


def test_no_fusion_while_frames_keep_arriving():
    fusion = CloudFusion(idle_s=1.0)  # far longer than a frame takes, even on a loaded machine
    scene = volume(fusion)
    scene.cloud()
    for k in range(6):  # a few ms apart
        scene.integrate(DEPTHS[k], INTRINSICS, VIEWS[k], 2.0)
        assert scene.pending == k + 1
    wait_until(lambda: scene.pending == 0)


def test_no_fusion_starts_while_grasps_are_planned_nor_right_after():
    """A fine fusion holds the GIL for tens of milliseconds: planning counts as activity, so a
    queue that is due waits for the plan to end and for a lull after it."""
    fusion = CloudFusion(idle_s=0.3)
    scene = volume(fusion)
    scene.cloud()
    with fusion.planning():
        scene.integrate(DEPTHS[0], INTRINSICS, VIEWS[0], 2.0)
        time.sleep(0.6)  # twice the lull after the frame: due, but a plan runs
        assert scene.pending == 1
    ended = time.monotonic()
    wait_until(lambda: scene.pending == 0)
    assert time.monotonic() - ended >= 0.3, "fused before a lull after the plan"


def test_reset_while_the_worker_fuses_keeps_no_stale_frame():
    fusion = CloudFusion(idle_s=0.0)
    scene = volume(fusion)
    for round_ in range(5):
        for k in range(len(VIEWS)):
            scene.integrate(DEPTHS[k], INTRINSICS, VIEWS[k], 2.0)
        time.sleep(0.02 * round_)  # reset at different points of the worker's progress
        scene.reset()
        for k in (1, 4):
            scene.integrate(DEPTHS[k], INTRINSICS, VIEWS[k], 2.0)
        np.testing.assert_allclose(scene.cloud(), reference_cloud([1, 4]), atol=1e-6)
        scene.reset()
    assert fusion.queued_bytes == 0


def test_closed_volume_frees_its_queue():
    fusion = CloudFusion(idle_s=3600)
    scene = volume(fusion)
    scene.integrate(DEPTHS[0], INTRINSICS, VIEWS[0], 2.0)
    assert fusion.queued_bytes > 0
    scene.close()
    scene.integrate(DEPTHS[1], INTRINSICS, VIEWS[1], 2.0)  # a request still holding it
    assert fusion.queued_bytes == 0 and scene.pending == 0


def test_concurrent_uploads_reads_and_resets_over_http(vgn: VGNClient):
    """Uploads, cloud reads, resets and a delete racing on the real service; afterwards a
    reset session fused with known frames gives exactly their cloud."""
    session = vgn.create_session(intrinsics=INTRINSICS).session_id
    doomed = vgn.create_session(intrinsics=INTRINSICS).session_id
    stop, errors = threading.Event(), []

    def loop(action) -> None:
        with VGNClient(vgn.url) as client:
            k = 0
            while not stop.is_set():
                try:
                    action(client, k)
                except Exception as error:  # noqa: BLE001 - collected and reported below
                    errors.append(error)
                    return
                k += 1

    def upload(client: VGNClient, k: int) -> None:
        client.add_frame(session, DEPTHS[k % len(DEPTHS)], VIEWS[k % len(VIEWS)], max_depth=2.0)

    def read(client: VGNClient, k: int) -> None:
        assert client.cloud(session).shape[1] == 6

    def reset(client: VGNClient, k: int) -> None:
        client.reset_session(session)
        time.sleep(0.03)

    threads = [threading.Thread(target=loop, args=(action,)) for action in (upload, upload, read, reset)]
    for k in range(3):
        vgn.add_frame(doomed, DEPTHS[k], VIEWS[k], max_depth=2.0)
    for thread in threads:
        thread.start()
    time.sleep(1.5)
    vgn.delete_session(doomed)  # with frames queued for its cloud
    time.sleep(1.0)
    stop.set()
    for thread in threads:
        thread.join(timeout=60)
    assert not errors, errors
    vgn.reset_session(session)
    for k in (2, 5, 7):
        vgn.add_frame(session, DEPTHS[k], VIEWS[k], max_depth=2.0)
    np.testing.assert_allclose(vgn.cloud(session), reference_cloud([2, 5, 7]), atol=1e-5)
    assert vgn.session(session).frame_count == 3


def test_a_burst_of_uploads_never_fuses_the_cloud_volume():
    """Within the queue's bound an upload burst costs its senders the coarse volume only."""
    frames = 40
    scene = volume(CloudFusion(idle_s=3600), max_pending=frames)
    for k in range(frames):
        scene.integrate(DEPTHS[k % len(DEPTHS)], INTRINSICS, VIEWS[k % len(VIEWS)], 2.0)
    assert scene.pending == frames and scene._fine is None


def test_the_worker_thread_ends_when_idle_and_on_close():
    fusion = CloudFusion(idle_s=0.01, linger_s=1.0)
    scene = volume(fusion)
    scene.cloud()
    scene.integrate(DEPTHS[0], INTRINSICS, VIEWS[0], 2.0)
    assert fusion.running
    wait_until(lambda: scene.pending == 0 and not fusion.running)
    scene.integrate(DEPTHS[1], INTRINSICS, VIEWS[1], 2.0)  # starts it again
    assert fusion.running
    wait_until(lambda: scene.pending == 0)
    fusion.close()
    np.testing.assert_allclose(scene.cloud(), reference_cloud([0, 1]), atol=1e-6)
    assert not fusion.running
    scene.integrate(DEPTHS[2], INTRINSICS, VIEWS[2], 2.0)  # after shutdown: no thread, no queue
    assert not fusion.running and scene.pending == 0


def test_service_shutdown_stops_the_worker_and_frees_every_queue(settings: Settings):
    with TestClient(create_app(settings)) as http:
        core: PlanningService = http.app.state.core
        fusion = core.sessions.cloud_fusion
        read, unread = (
            http.post("/sessions", json={"intrinsics": INTRINSICS.model_dump()}).json()["session_id"]
            for _ in range(2)
        )
        assert http.get(f"/sessions/{read}/cloud").status_code == 200  # fused by the worker when idle
        for k in range(6):
            meta = {"camera_pose": {"matrix": VIEWS[k].tolist()}, "max_depth": 2.0}
            files = {"meta": (None, str(meta).replace("'", '"')), "depth": ("d", DEPTHS[k].tobytes())}
            for session in (read, unread):  # the unread one keeps its frames queued
                assert http.post(f"/sessions/{session}/frames", files=files).status_code == 200
        assert fusion.running and fusion.queued_bytes >= 6 * DEPTHS[0].nbytes / 2
    assert not fusion.running and fusion.closed and fusion.queued_bytes == 0
    assert len(core.sessions) == 0


def test_expiry_while_the_worker_fuses(random_checkpoint):
    """Sessions expiring and swept while the worker fuses their frames: their queues
    are freed, and the worker goes on fusing the sessions that remain."""
    core = PlanningService.from_settings(Settings(model=random_checkpoint, api_key=None))
    fusion = core.sessions.cloud_fusion
    try:
        doomed = [core.create_session(SessionCreate(intrinsics=INTRINSICS)).session_id for _ in range(3)]
        for session in doomed:
            core.cloud(session)  # readers: the worker fuses them in the lull after the uploads
            for k in range(len(VIEWS)):
                core.add_frame(session, DEPTHS[k], VIEWS[k], max_depth=2.0)
        wait_until(lambda: fusion.queued_bytes < 3 * len(VIEWS) * DEPTHS[0].nbytes / 2)  # under way
        ttl_s, core.sessions.ttl_s = core.sessions.ttl_s, 0.0  # every idle session is past it now
        assert core.sessions.sweep() == 3
        core.sessions.ttl_s = ttl_s
        assert fusion.queued_bytes == 0
        kept = core.create_session(SessionCreate(intrinsics=INTRINSICS)).session_id
        core.cloud(kept)
        for k in (0, 4, 8):
            core.add_frame(kept, DEPTHS[k], VIEWS[k], max_depth=2.0)
        wait_until(lambda: fusion.queued_bytes == 0)  # fused in the background
        np.testing.assert_allclose(core.cloud(kept), reference_cloud([0, 4, 8]), atol=1e-6)
    finally:
        core.close()
    assert not fusion.running


def test_coarse_grid_is_fused_by_the_upload_itself(vgn: VGNClient):
    """The grid the network plans on reflects each frame as soon as its upload returns."""
    session = vgn.create_session(intrinsics=INTRINSICS).session_id
    coarse = TSDFVolume(0.3, 40)
    for k in (3, 4, 5):
        vgn.add_frame(session, DEPTHS[k], VIEWS[k], max_depth=2.0)
        coarse.integrate(DEPTHS[k], INTRINSICS, VIEWS[k], 2.0)
        np.testing.assert_array_equal(vgn.tsdf(session), coarse.grid())


def test_cloud_and_viewer_right_after_uploads_hold_every_frame(vgn: VGNClient):
    session = vgn.create_session(intrinsics=INTRINSICS).session_id
    order = [k % len(VIEWS) for k in range(30)]
    for k in order:
        vgn.add_frame(session, DEPTHS[k], VIEWS[k], max_depth=2.0)
    view = httpx.get(f"{vgn.url}/sessions/{session}/view/data", params={"threshold": 0.99}, timeout=120)
    assert view.status_code == 200, view.text
    expected = reference_cloud(order)
    assert view.json()["cloud"]["total"] == len(expected)  # the viewer drained the queue first
    np.testing.assert_allclose(vgn.cloud(session), expected, atol=1e-5)


@pytest.mark.parametrize(
    ("body", "meta", "words"),
    [
        (b"\0" * 100, {}, "raw depth must be 640x480"),
        (None, {"max_depth": -1.0}, "max_depth"),
        (None, {"camera_pose": {"matrix": [[1, 0], [0, 1]]}}, "camera_pose"),
    ],
)
def test_a_rejected_frame_changes_neither_volume(vgn: VGNClient, body, meta, words):
    session = vgn.create_session(intrinsics=INTRINSICS).session_id
    vgn.add_frame(session, DEPTHS[1], VIEWS[1], max_depth=2.0)
    grid, cloud = vgn.tsdf(session), vgn.cloud(session)
    vgn.add_frame(session, DEPTHS[2], VIEWS[2], max_depth=2.0)  # queued, not fused yet
    full_meta = {"camera_pose": {"matrix": VIEWS[3].tolist()}, "max_depth": 2.0, **meta}
    files = {
        "meta": (None, str(full_meta).replace("'", '"')),
        "depth": ("d", body if body is not None else DEPTHS[3].tobytes(), "application/octet-stream"),
    }
    answer = httpx.post(f"{vgn.url}/sessions/{session}/frames", files=files, timeout=60)
    assert 400 <= answer.status_code < 500 and words in answer.text, answer.text
    assert vgn.session(session).frame_count == 2
    reference = SceneVolume(0.3, 40, np.eye(4), cloud_resolution=120, fusion=CloudFusion(idle_s=3600))
    for k in (1, 2):
        reference.integrate(DEPTHS[k], INTRINSICS, VIEWS[k], 2.0)
    np.testing.assert_array_equal(vgn.tsdf(session), reference.grid())
    np.testing.assert_allclose(vgn.cloud(session), reference.cloud(), atol=1e-5)
    assert not np.array_equal(vgn.tsdf(session), grid) and len(cloud)  # frame 2 did count
