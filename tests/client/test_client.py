"""The client library end to end against a real uvicorn on loopback, sync and async."""

from __future__ import annotations

import numpy as np
import pytest

from client import AsyncVGNClient, Intrinsics, NotFound, Workspace
from service.tsdf import SceneVolume
from tests.helpers.scenes import INTRINSICS, BoxScene, circle_views
from vgn_contract.geometry import matrix_from_pose
from vgn_contract.schemas import Pose

SCENE = BoxScene()


def reference_grid() -> np.ndarray:
    volume = SceneVolume(0.3, 40, np.eye(4), cloud_resolution=40)
    for pose in circle_views(6):
        volume.integrate(SCENE.depth(pose), INTRINSICS, pose, 2.0)
    return volume.grid()


def test_scene_fused_over_http_matches_in_process_fusion(vgn):
    session = vgn.create_session(intrinsics=INTRINSICS)
    for count, pose in enumerate(circle_views(6), start=1):
        result = vgn.add_frame(session.session_id, SCENE.depth(pose), pose)
        assert result.frame_count == count and result.integration_ms > 0
    grid = vgn.tsdf(session.session_id)
    assert grid.shape == (40, 40, 40) and grid.dtype == np.float32
    np.testing.assert_allclose(grid, reference_grid(), atol=1e-6)
    cloud = vgn.cloud(session.session_id)
    assert cloud.shape[1] == 6
    assert np.percentile(SCENE.distance_to_surface(cloud[:, :3].astype(np.float64)), 95) < 0.003
    info = vgn.session(session.session_id)
    assert info.frame_count == 6 and info.intrinsics == INTRINSICS
    vgn.delete_session(session.session_id)
    with pytest.raises(NotFound, match=session.session_id):
        vgn.session(session.session_id)


def test_grasps_are_typed_and_ranked(vgn):
    session = vgn.create_session(session_id="ranked", intrinsics=INTRINSICS)
    for pose in circle_views(3):
        vgn.add_frame(session.session_id, SCENE.depth(pose), pose)
    # Without the clearance and grip checks: they drop every grasp of the random weights on this scene.
    result = vgn.grasps(session.session_id, threshold=0.0, max_grasps=20, clearance=False, grip=False)
    assert result.frame_count == 3 and result.model and result.planning_ms > 0
    assert 0 < len(result.grasps) <= 20
    qualities = [g.quality for g in result.grasps]
    assert qualities == sorted(qualities, reverse=True)
    for grasp in result.grasps:
        assert np.linalg.norm(grasp.orientation) == pytest.approx(1.0, abs=1e-6)
        np.testing.assert_allclose(grasp.as_matrix()[:3, 2], grasp.approach, atol=1e-6)
        assert 0.0 <= grasp.position[0] <= 0.3 and 0.0 <= grasp.position[2] <= 0.3
    vgn.delete_session(session.session_id)


def test_png_depth_and_matrix_pose(vgn):
    """uint16 millimetres are PNG-encoded by the client; a 4x4 pose works like a Pose."""
    pose = circle_views(1)[0]
    depth_mm = np.round(SCENE.depth(pose) * 1000).astype(np.uint16)
    png = vgn.create_session(intrinsics=INTRINSICS).session_id
    raw = vgn.create_session(intrinsics=INTRINSICS).session_id
    vgn.add_frame(png, depth_mm, pose)
    vgn.add_frame(raw, depth_mm.astype(np.float32) / 1000, Pose.from_matrix(pose))
    np.testing.assert_allclose(vgn.tsdf(png), vgn.tsdf(raw), atol=1e-5)


def test_workspace_pose_and_reset(vgn):
    workspace = Workspace(pose=Pose(position=[-0.03, 0.0, 0.0]))
    session = vgn.create_session(workspace=workspace)
    small = Intrinsics(width=320, height=240, fx=270.0, fy=270.0, cx=159.75, cy=119.75)
    pose = circle_views(1)[0]
    vgn.add_frame(session.session_id, SCENE.depth(pose, small), pose, intrinsics=small)
    at_origin = vgn.create_session()
    vgn.add_frame(at_origin.session_id, SCENE.depth(pose, small), pose, intrinsics=small)
    # The workspace starts 3 cm (4 voxels of 7.5 mm) further along -x: the same world point
    # lies 4 voxels further along its x index.
    shifted, reference = vgn.tsdf(session.session_id), vgn.tsdf(at_origin.session_id)
    assert np.count_nonzero(reference[:-4]) > 1000
    np.testing.assert_allclose(shifted[4:], reference[:-4], atol=1e-4)
    info = vgn.reset_session(session.session_id)
    assert info.frame_count == 0 and not vgn.tsdf(session.session_id).any()
    assert info.workspace.pose.position == [-0.03, 0.0, 0.0]


def test_service_endpoints(vgn):
    assert vgn.health() == {"status": "ok"}
    readiness = vgn.ready()
    assert readiness.ready
    model = vgn.model()
    assert model.loaded and model.parameters == 313_238 and model.model_id in readiness.detail
    assert 'vgn_requests_total{method="GET",route="/model",status="200"}' in vgn.metrics()
    assert vgn.sessions().max_sessions >= 1


async def test_async_client(server):
    async with AsyncVGNClient(server.url) as vgn:
        session = await vgn.create_session(intrinsics=INTRINSICS)
        for pose in circle_views(2):
            await vgn.add_frame(
                session.session_id,
                SCENE.depth(pose),
                matrix_from_pose(pose[:3, 3], Pose.from_matrix(pose).orientation),
            )
        result = await vgn.grasps(
            session.session_id, threshold=0.0, max_grasps=3, clearance=False, grip=False
        )
        assert result.frame_count == 2 and 1 <= len(result.grasps) <= 3
        assert (await vgn.tsdf(session.session_id)).any()
        await vgn.delete_session(session.session_id)
        with pytest.raises(NotFound):
            await vgn.grasps(session.session_id)


def test_client_validates_before_sending(vgn):
    """Bad poses fail in the client with the same checks the service applies."""
    with pytest.raises(ValueError, match="not rigid"):
        vgn.add_frame("any", np.zeros((480, 640), np.float32), np.diag([2.0, 1.0, 1.0, 1.0]))
    with pytest.raises(ValueError, match="unit length"):
        vgn.add_frame(
            "any", np.zeros((480, 640), np.float32), {"position": [0, 0, 0], "orientation": [0, 0, 0, 3]}
        )
