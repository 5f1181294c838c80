"""The antipodal baseline planner on the analytic box scene, in process and over HTTP."""

from __future__ import annotations

import numpy as np
import pytest
from fastapi.testclient import TestClient
from scipy.spatial.transform import Rotation

from service.baseline import AntipodalConfig, grips_antipodally, plan_antipodal
from service.baseline.antipodal import WIDTH_MARGIN
from service.checks import check_grasps, clear_of
from service.core import PlanningService
from service.http_app import create_app
from service.planner import antipodal_config
from service.settings import Settings
from tests.helpers.scenes import INTRINSICS, TABLE_Z, BoxScene, CylinderScene, circle_views
from vgn_contract.gripper_description import default_gripper
from vgn_contract.schemas import GraspQuery, SessionCreate

SCENE = BoxScene()  # 0.08 (x) x 0.06 (y) x 0.06 (z) on the table
FINGER_DEPTH = default_gripper().finger_depth


def fused_session(core: PlanningService, views: int = 6, scene: BoxScene | CylinderScene = SCENE) -> str:
    session_id = core.create_session(SessionCreate(intrinsics=INTRINSICS)).session_id
    for pose in circle_views(views):
        core.add_frame(session_id, scene.depth(pose), pose)
    return session_id


@pytest.fixture
def antipodal(core: PlanningService):
    session_id = fused_session(core)
    return core.plan(session_id, GraspQuery(planner="antipodal", threshold=0.0))


def test_grasps_fit_the_box(antipodal):
    assert antipodal.model == "antipodal" and antipodal.frame_count == 6 and antipodal.planning_ms > 0
    grasps = antipodal.grasps
    assert len(grasps) >= 3
    qualities = [g.quality for g in grasps]
    assert qualities == sorted(qualities, reverse=True) and all(0.0 <= q <= 1.0 for q in qualities)
    lower, upper = np.asarray(SCENE.lower) - 0.02, np.asarray(SCENE.upper) + 0.02
    for grasp in grasps:
        matrix = grasp.as_matrix()
        np.testing.assert_allclose(matrix[:3, 2], grasp.approach, atol=1e-6)
        middle = np.asarray(grasp.position) + 0.5 * FINGER_DEPTH * matrix[:3, 2]  # of the closing region
        assert np.all(middle >= lower) and np.all(middle <= upper)
        # across the 6 cm side (+ the planner's 2 mm margin; the fused surface rounds the box's
        # edges by a few mm), square or up to the friction cone's 30 degrees across it, which on
        # the diagonal is wider; never across the 8 cm side, which is too wide
        assert 0.055 <= grasp.width <= default_gripper().max_opening
        tip = np.asarray(grasp.position) + FINGER_DEPTH * matrix[:3, 2]
        assert tip[2] > TABLE_Z
        assert abs(matrix[1, 1]) > np.cos(np.radians(30.0)) - 0.01  # closing along world y


def test_best_grasp_is_top_down_across_the_narrow_side(antipodal):
    best = antipodal.grasps[0]
    matrix = best.as_matrix()
    assert best.approach[2] < -0.95 and best.quality > 0.9
    assert abs(matrix[1, 1]) > 0.95
    tip = np.asarray(best.position) + FINGER_DEPTH * matrix[:3, 2]
    assert TABLE_Z < tip[2] < SCENE.upper[2] - 0.03  # deep on the box, clear of the table


def test_a_curved_face_is_gripped_across(core):
    """Across a lying cylinder the normals about each contact tilt up and down by up to the
    friction cone: their mean still faces the jaw, so the planner closes across the diameter."""
    cylinder = CylinderScene()
    result = core.plan(fused_session(core, scene=cylinder), GraspQuery(planner="antipodal", threshold=0.0))
    across = [
        g for g in result.grasps
        if abs(g.as_matrix()[1, 1]) > 0.9 and g.width == pytest.approx(2 * cylinder.radius + 0.002, abs=0.004)
    ]  # fmt: skip
    assert across, [(round(g.width, 3), g.approach) for g in result.grasps]


def test_reproducible_and_filtered(core):
    session_id = fused_session(core)
    query = GraspQuery(planner="antipodal", threshold=0.0)
    first, second = core.plan(session_id, query), core.plan(session_id, query)
    assert first.grasps == second.grasps
    top = core.plan(session_id, GraspQuery(planner="antipodal", threshold=0.0, max_grasps=2))
    assert top.grasps == first.grasps[:2]
    cone = core.plan(
        session_id,
        GraspQuery(planner="antipodal", threshold=0.0, approach="0,0,-1", max_approach_angle=10.0),
    )
    assert cone.grasps and all(g.approach[2] < -np.cos(np.radians(10.0)) for g in cone.grasps)
    cropped = core.plan(
        session_id, GraspQuery(planner="antipodal", threshold=0.0, crop_min="0,0,0", crop_max="0.15,0.3,0.3")
    )
    assert cropped.grasps and all(g.position[0] <= 0.15 for g in cropped.grasps)
    high = core.plan(session_id, GraspQuery(planner="antipodal", threshold=0.9))
    assert high.grasps and all(g.quality >= 0.9 for g in high.grasps), "a box has grasps scoring 0.9"


def test_empty_inputs_give_no_grasps(core):
    session_id = core.create_session(SessionCreate(intrinsics=INTRINSICS)).session_id
    result = core.plan(session_id, GraspQuery(planner="antipodal", threshold=0.0))
    assert result.grasps == [] and result.frame_count == 0
    assert plan_antipodal(np.zeros((0, 6), np.float32), np.eye(4), AntipodalConfig()) == []


def test_antipodal_over_http_needs_no_model():
    core = PlanningService.from_settings(Settings(model="none", api_key=None))  # VGN_MODEL=none
    with TestClient(create_app(core=core)) as http:
        session_id = http.post("/sessions", json={"intrinsics": INTRINSICS.model_dump()}).json()["session_id"]
        for pose in circle_views(6):
            core.add_frame(session_id, SCENE.depth(pose), pose)
        assert http.get(f"/sessions/{session_id}/grasps").status_code == 503  # VGN needs a model
        response = http.get(
            f"/sessions/{session_id}/grasps", params={"planner": "antipodal", "threshold": 0.5}
        )
        assert response.status_code == 200, response.text
        body = response.json()
        assert body["model"] == "antipodal" and body["grasps"]
        assert http.get(f"/sessions/{session_id}/grasps", params={"planner": "magic"}).status_code == 422


def test_another_planners_grasp_is_judged_by_the_faces_its_pads_meet(core):
    """The antipodal test at a given pose: the planner's own best grasp meets the box's opposed sides;
    turned 45 degrees about its approach it meets them at 45 degrees, outside a 20-degree cone and
    inside a 50-degree one; lifted clear of the box its pads close on nothing."""
    session_id = fused_session(core)
    best = core.plan(session_id, GraspQuery(planner="antipodal", threshold=0.0)).grasps[0]
    cloud = core.cloud(session_id)
    matrix = best.as_matrix()
    turned = matrix[:3, :3] @ Rotation.from_euler("z", 45.0, degrees=True).as_matrix()
    lifted = np.asarray(best.position) - 0.2 * matrix[:3, 2]
    cone = np.radians(20.0)
    poses = [(best.position, matrix[:3, :3]), (best.position, turned), (lifted, matrix[:3, :3])]
    positions, rotations = np.array([p for p, _ in poses]), np.array([r for _, r in poses])
    assert grips_antipodally(cloud, positions, rotations, default_gripper(), cone).tolist() == [
        True,
        False,
        False,
    ]
    wide = grips_antipodally(cloud, positions[1:2], rotations[1:2], default_gripper(), np.radians(50.0))
    assert wide.tolist() == [True]


def plate_cloud(thickness: float) -> np.ndarray:
    """(M, 6) points and outward normals of an upright 8 x ``thickness`` x 6 cm plate standing on a
    table patch (world frame, the table at z = 0, 2 mm spacing)."""
    step = 0.002
    xs, zs = np.arange(-0.04, 0.0401, step), np.arange(0.0, 0.0601, step)
    x, z = (a.ravel() for a in np.meshgrid(xs, zs))
    faces = [np.column_stack([x, np.full_like(x, side * thickness / 2), z]) for side in (-1, 1)]
    normals = [np.tile([0.0, side, 0.0], (len(x), 1)) for side in (-1, 1)]
    tx, ty = (a.ravel() for a in np.meshgrid(np.arange(-0.1, 0.1001, step), np.arange(-0.1, 0.1001, step)))
    table = np.abs(ty) > thickness / 2 + step
    faces.append(np.column_stack([tx[table], ty[table], np.zeros(table.sum())]))
    normals.append(np.tile([0.0, 0.0, 1.0], (table.sum(), 1)))
    return np.column_stack([np.concatenate(faces), np.concatenate(normals)])


def test_no_pair_closes_on_less_than_the_hand_holds():
    """A plate thinner than the hand's held opening (the success test's 10 % of the opening) is no
    grasp: the closed fingers would read as holding nothing. A thicker one is gripped across."""
    hand = default_gripper()
    thin, thick = 0.75 * hand.held_opening, 2.0 * hand.held_opening
    assert plan_antipodal(plate_cloud(thin), np.eye(4), AntipodalConfig(), hand) == []
    across = plan_antipodal(plate_cloud(thick), np.eye(4), AntipodalConfig(), hand)
    assert across and all(g.width == pytest.approx(thick + WIDTH_MARGIN, abs=1e-6) for g in across)


def test_the_surfaces_pairs_clear_the_fine_cloud_they_were_found_on(core):
    """The grid's 7.5 mm surface lets through a pair whose open fingers brush the box's 2.5 mm
    surface on the way in: the service clears its pairs against the fine cloud as well."""
    session_id = fused_session(core)
    query = GraspQuery(planner="antipodal", threshold=0.0, max_grasps=None)
    answer = core.plan(session_id, query)
    cloud, grid = core.cloud(session_id), core.grid(session_id)
    with core.sessions.use(session_id) as session:
        surface, workspace, pose = (
            session.volume.surface_points(),
            session.workspace,
            session.volume.workspace_pose,
        )

    def clear_of_cloud(grasps: list) -> list:
        return clear_of(grasps, cloud[:, :3], grid, workspace.voxel_size, pose, workspace.size)

    found = plan_antipodal(cloud, pose, antipodal_config(query), default_gripper())
    on_grid = check_grasps(found, surface, grid, workspace.voxel_size, pose, workspace.size, core.grip_config,
                           core.settings.alternatives)  # fmt: skip
    brushing = len(on_grid.grasps) - len(clear_of_cloud(on_grid.grasps))
    assert brushing > 0  # the scene has such a pair
    assert answer.grasps == clear_of_cloud(on_grid.grasps)
    assert answer.clearance_dropped == on_grid.clearance_dropped + brushing
