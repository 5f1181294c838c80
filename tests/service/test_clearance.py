"""The clearance check: the swept open hand against synthetic geometry, its hand model against the
simulator's URDF, and the ``clearance`` grasp option over HTTP and in the planning core."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Iterator
from pathlib import Path

import grpc
import numpy as np
import pytest
from fastapi.testclient import TestClient
from scipy.spatial.transform import Rotation

from client.grpc_client import GRPCClient
from service.clearance import (
    EDGE_BAND_SPACINGS,
    EDGE_REACH,
    ClearanceConfig,
    above_table_outside,
    approach_is_clear,
    clear_grasps,
    continued_past_sides,
    hand_boxes,
)
from service.core import PlanningService
from service.grpc.server import build_server
from service.http_app import create_app
from service.settings import PACKAGED_MODEL, Settings
from tests.helpers.scenes import INTRINSICS, BoxScene, circle_views
from vgn_contract.gripper_description import default_gripper
from vgn_contract.grpc_api import convert
from vgn_contract.grpc_api import grasp_planning_pb2 as pb
from vgn_contract.grpc_api.grasp_planning_pb2_grpc import GraspPlanningStub
from vgn_contract.schemas import GraspQuery, GraspResult, SessionCreate

ROOT = Path(__file__).resolve().parents[2]
URDF = ROOT / "sim_worker" / "assets" / "gripper.urdf"
FRANKA = default_gripper()
MAX_OPENING, PREGRASP_DISTANCE = FRANKA.max_opening, FRANKA.pregrasp_distance
IDENTITY = np.array([[0.0, 0.0, 0.0, 1.0]])  # grasp frame = the points' frame: +z approach, y closing
ORIGIN = np.zeros((1, 3))
#: No margin, tolerance or vetoing count: the bare swept hand.
EXACT = ClearanceConfig(margin=0.0, min_points=1, contact_tolerance=0.0)
DEFAULT = ClearanceConfig()


def clear(points, positions=ORIGIN, orientations=IDENTITY, config=DEFAULT) -> bool:
    return bool(approach_is_clear(np.asarray(points, dtype=float), positions, orientations, config)[0])


def cluster(centre, count: int = 5, spread: float = 0.001) -> np.ndarray:
    """``count`` points within ``spread`` of ``centre``, like a patch of surface."""
    offsets = np.random.default_rng(0).uniform(-spread, spread, (count, 3))
    return np.asarray(centre) + offsets


def object_between_the_fingers() -> np.ndarray:
    """A dense block of points that fills the closing region (|y| < 3.5 cm, z in [0, 5 cm])."""
    axes = [np.linspace(-0.03, 0.03, 7), np.linspace(-0.035, 0.035, 8), np.linspace(0.0, 0.05, 6)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


# The swept hand on synthetic geometry ------------------------------------------------------------
def test_a_patch_in_a_fingers_path_drops_the_grasp():
    for side in (1.0, -1.0):  # a patch on top of where each pad comes down, 3 cm above the tip
        assert not clear(cluster((0.0, side * 0.047, 0.02)))
    assert clear(cluster((0.0, 0.047, 0.06)))  # beyond the fingertips at the grasp pose: never reached


def test_points_between_the_fingers_are_allowed():
    assert clear(object_between_the_fingers())
    assert clear(object_between_the_fingers(), config=EXACT)


def test_a_wall_beside_the_object_at_the_pregrasp_height_drops_the_grasp():
    obj = object_between_the_fingers()
    # A wall 9 cm to the side, from 6 to 12 cm behind the finger bases: beyond the fingers (they
    # reach y = 6.6 cm) but in the 20 cm wide palm's path on the way in from the pre-grasp pose.
    ys, zs = np.meshgrid(np.linspace(-0.03, 0.03, 7), np.linspace(-0.12, -0.06, 7), indexing="ij")
    wall = np.column_stack([ys.ravel(), np.full(ys.size, 0.09), zs.ravel()])
    assert clear(obj)
    assert not clear(np.vstack([obj, wall]))
    assert clear(np.vstack([obj, wall + [0.0, 0.02, 0.0]]))  # 11 cm to the side: past the palm's 10 cm


def test_a_single_noise_point_is_below_the_vetoing_count():
    in_path = (0.0, 0.047, 0.02)
    assert ClearanceConfig().min_points == 2
    assert clear([in_path])
    assert not clear(cluster(in_path, count=2))
    assert not clear([in_path], config=ClearanceConfig(min_points=1))


def test_the_margin_grows_the_hand():
    just_outside = cluster((0.0, 0.0552 + 0.0015, 0.045), spread=0.0002)  # 1.5 mm outside the pad
    assert clear(just_outside, config=EXACT)
    assert not clear(just_outside, config=ClearanceConfig(margin=0.002, min_points=1, contact_tolerance=0.0))


def test_contact_in_the_last_millimetres_of_the_approach_is_tolerated():
    """Fingertips meeting the table a few mm before the grasp pose: a guarded approach stops there."""
    xs, ys = np.meshgrid(np.linspace(-0.05, 0.05, 21), np.linspace(-0.12, 0.12, 49), indexing="ij")

    def table(depth: float) -> np.ndarray:  # the fingertips end ``depth`` below the plane
        return np.column_stack([xs.ravel(), ys.ravel(), np.full(xs.size, 0.05 - depth)])

    into = (
        DEFAULT.contact_tolerance - DEFAULT.margin - 0.0005
    )  # the grown fingertips just within the tolerance
    assert into > 0.0
    assert clear(table(-0.003))  # 3 mm short of the table
    assert clear(table(into))
    assert not clear(table(into + 0.001))
    assert not clear(table(0.01))
    assert not clear(table(into), config=ClearanceConfig(contact_tolerance=0.0))


def test_the_verdict_does_not_depend_on_the_frame():
    """Moving the geometry and the grasps by one rigid transform changes no verdict."""
    rng = np.random.default_rng(3)
    points = np.vstack(
        [object_between_the_fingers(), cluster((0.0, 0.047, 0.02)), rng.uniform(-0.2, 0.2, (20, 3))]
    )
    rotations = Rotation.random(40, random_state=4)
    positions = rng.uniform(-0.12, 0.12, (40, 3))
    local = approach_is_clear(points, positions, rotations.as_quat())
    assert 0 < local.sum() < 40
    moved = Rotation.random(random_state=5)
    shift = np.array([0.3, -0.2, 0.1])
    world = approach_is_clear(
        moved.apply(points) + shift, moved.apply(positions) + shift, (moved * rotations).as_quat()
    )
    np.testing.assert_array_equal(local, world)


def test_the_swept_volume_matches_dense_sampling_of_the_motion():
    """The exact slab test agrees with the hand placed every 0.5 mm along the approach."""
    centres, rotations, halves = hand_boxes()
    points = np.random.default_rng(6).uniform([-0.05, -0.12, -0.13], [0.05, 0.12, 0.07], (4000, 3))
    swept = np.zeros(len(points), dtype=bool)
    for offset in np.arange(0.0, PREGRASP_DISTANCE + 1e-9, 0.0005):
        for centre, rotation, half in zip(centres, rotations, halves, strict=True):
            in_box = (points + [0.0, 0.0, offset] - centre) @ rotation
            swept |= np.all(np.abs(in_box) <= half, axis=1)
    verdicts = np.array([clear([p], config=EXACT) for p in points])
    disagree = np.flatnonzero(verdicts == swept)  # verdict True means clear, i.e. not swept
    assert len(disagree) <= 4  # only points within 0.5 mm of a sampled placement may differ
    assert swept.sum() > 200


def test_surface_that_meets_a_side_of_the_cube_is_carried_on_straight_out_of_it():
    """Points at a side face go on outwards every spacing for the reach; points inside the cube away
    from its sides, or at the floor, do not; the cube may stand anywhere in the world."""
    size, spacing, floor = 0.3, 0.0075, 0.05
    at_side = np.array([[0.3 - 0.5 * EDGE_BAND_SPACINGS * spacing, 0.15, 0.08]])  # near x = size
    inside = np.array([[0.15, 0.15, 0.08], [0.3 - 1.5 * EDGE_BAND_SPACINGS * spacing, 0.2, 0.08]])
    on_floor = np.array([[0.001, 0.15, floor - 0.001]])  # the table at the -x side: not an object's
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_euler("z", 30, degrees=True).as_matrix()
    pose[:3, 3] = [0.4, -0.2, 0.7]
    world = np.vstack([at_side, inside, on_floor]) @ pose[:3, :3].T + pose[:3, 3]
    carried = continued_past_sides(world, np.linalg.inv(pose), size, spacing, floor)
    local = (carried - pose[:3, 3]) @ pose[:3, :3]
    steps = int(round(EDGE_REACH / spacing))
    assert len(local) == steps
    np.testing.assert_allclose(np.sort(local[:, 0]), 0.3 + spacing * np.arange(1, steps + 1), atol=1e-9)
    np.testing.assert_allclose(local[:, 1:], np.tile(at_side[0, 1:], (steps, 1)), atol=1e-9)
    everything = continued_past_sides(world, np.linalg.inv(pose), size, spacing, None)
    assert len(everything) == 2 * steps  # without a floor the table's point goes on too
    assert continued_past_sides(np.zeros((0, 3)), np.eye(4), size, spacing, floor).shape == (0, 3)


def test_the_table_past_the_cube_is_met_where_the_swept_hand_dips_under_it_outside_the_footprint():
    """Against the hand's boxes placed every 0.5 mm along the approach, each sampled on a 9^3 lattice
    that includes its corners: a grasp is refused exactly when some sample lies under the table and
    outside the cube's footprint, but for samples within the lattice's spacing of the plane."""
    size, table, last = 0.3, 0.05, 0.01
    rng = np.random.default_rng(11)  # a draw where the segments' crossings decide some verdicts
    count = 80
    positions = np.column_stack(
        [rng.uniform(-0.06, 0.06, count), rng.uniform(0.0, size, count), table + rng.uniform(0.0, 0.1, count)]
    )
    orientations = Rotation.random(count, random_state=12)
    verdicts = above_table_outside(
        positions, orientations.as_quat(), np.eye(4), size, table, EXACT, first=last
    )
    lattice = np.stack(np.meshgrid(*[np.linspace(-1.0, 1.0, 9)] * 3, indexing="ij"), -1).reshape(-1, 3)
    centres, rotations, halves = hand_boxes()
    matrices = orientations.as_matrix()
    depths = np.full(count, np.inf)  # how far the deepest sample outside the footprint goes under the table
    for offset in np.arange(last, PREGRASP_DISTANCE + 1e-9, 0.0005):
        for centre, rotation, half in zip(centres, rotations, halves, strict=True):
            local = centre + (lattice * half) @ rotation.T - [0.0, 0.0, offset]  # grasp frame
            world = positions[:, None, :] + np.einsum("gij,kj->gki", matrices, local)
            outside = np.any((world[..., :2] < 0.0) | (world[..., :2] > size), axis=-1)
            heights = np.where(outside, world[..., 2] - table, np.inf)
            depths = np.minimum(depths, heights.min(axis=1))
    decided = np.abs(depths) > 0.003  # farther from the plane than the lattice's spacing
    assert np.array_equal(verdicts[decided], depths[decided] > 0.0)
    assert 10 < verdicts.sum() < count - 10 and decided.sum() > 0.8 * count
    # Inside the footprint the table is the observed surface's business, not this check's: a hand from
    # above sunk 5 cm into it passes in the middle of the cube, and not 1 cm from its side.
    from_above = Rotation.from_euler("x", 180, degrees=True).as_quat()
    sunk = np.array([[0.15, 0.15, table - 0.05], [0.01, 0.15, table - 0.05]])
    assert above_table_outside(sunk, [from_above] * 2, np.eye(4), size, table, EXACT).tolist() == [
        True,
        False,
    ]
    assert above_table_outside(np.zeros((0, 3)), np.zeros((0, 4)), np.eye(4), size, table).shape == (0,)


def test_no_geometry_or_no_grasps():
    assert clear(np.zeros((0, 3)))
    assert approach_is_clear(np.zeros((10, 3)), np.zeros((0, 3)), np.zeros((0, 4))).shape == (0,)
    assert clear_grasps([], np.zeros((10, 3))) == []


def test_invalid_settings_are_refused():
    for bad in ({"margin": -0.001}, {"min_points": 0}, {"opening": -0.01}, {"contact_tolerance": -0.001}):
        with pytest.raises(ValueError):
            ClearanceConfig(**bad)
    for unfit in (
        {"opening": 0.1},
        {"contact_tolerance": 0.06},
    ):  # wider than the hand opens, past the approach
        with pytest.raises(ValueError, match="franka"):
            approach_is_clear(np.zeros((3, 3)), ORIGIN, IDENTITY, ClearanceConfig(**unfit))


# The hand model is the simulator's ----------------------------------------------------------------
def urdf_boxes(link: str, joint_position: float) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """(centre, half extents, roll) of the link's collision boxes, the finger moved by its joint."""
    robot = ET.parse(URDF).getroot()
    shift = {"palm": 0.0, "left_finger": joint_position, "right_finger": -joint_position}[link]
    boxes = []
    for collision in robot.find(f"link[@name='{link}']").findall("collision"):
        origin = collision.find("origin")
        centre = np.array([float(v) for v in origin.get("xyz").split()]) + [0.0, shift, 0.0]
        roll = float((origin.get("rpy") or "0 0 0").split()[0])
        size = np.array([float(v) for v in collision.find("geometry/box").get("size").split()])
        boxes.append((centre, size / 2, roll))
    return boxes


def test_the_hand_boxes_are_the_urdf_collision_boxes_at_the_max_opening():
    assert ROOT / FRANKA.urdf == URDF  # the description names the URDF compared here
    expected = [
        *urdf_boxes("palm", 0.0),
        *urdf_boxes("left_finger", MAX_OPENING / 2),
        *urdf_boxes("right_finger", MAX_OPENING / 2),
    ]
    centres, rotations, halves = hand_boxes(MAX_OPENING)
    assert len(expected) == len(centres) == 7
    for (centre, half, roll), c, r, h in zip(expected, centres, rotations, halves, strict=True):
        np.testing.assert_allclose(c, centre, atol=1e-9)
        np.testing.assert_allclose(h, half, atol=1e-9)
        np.testing.assert_allclose(r, Rotation.from_euler("x", roll).as_matrix(), atol=1e-9)


def test_the_approach_is_the_executors():
    pytest.importorskip("pybullet")
    from sim_worker.gripper import GripperSpec

    assert GripperSpec().pregrasp_distance == PREGRASP_DISTANCE
    assert GripperSpec().max_opening == MAX_OPENING  # the executor approaches fully open


# The grasp option ----------------------------------------------------------------------------------
# The packaged model: a random network's grasps on the box scene all hit the table or the box.
@pytest.fixture(scope="module")
def trained() -> Iterator[PlanningService]:
    # The check alone: a dropped grasp is not tried again in other poses (tests/service/test_checks.py).
    settings = Settings(model=PACKAGED_MODEL, api_key=None, max_sessions=8, alternatives=False)
    service = PlanningService.from_settings(settings)
    yield service
    service.close()


def fused_session(core: PlanningService, views: int = 6) -> str:
    session = core.create_session(SessionCreate(intrinsics=INTRINSICS)).session_id
    scene = BoxScene()
    for pose in circle_views()[:views]:
        core.add_frame(session, scene.depth(pose), pose)
    return session


def test_the_core_checks_every_grasp_before_max_grasps(trained):
    """The clearance check alone (the grip check, also on by default, is tests/service/test_grip.py's)."""
    session = fused_session(trained)
    everything = trained.plan(session, GraspQuery(threshold=0.0, clearance=False, grip=False))
    checked = trained.plan(session, GraspQuery(threshold=0.0, clearance=True, grip=False))
    assert everything.clearance_dropped is None
    default = trained.plan(session, GraspQuery(threshold=0.0, grip=False))
    assert (default.grasps, default.clearance_dropped) == (checked.grasps, checked.clearance_dropped), "on"
    assert 0 < len(checked.grasps) < len(everything.grasps)
    assert checked.clearance_dropped + checked.workspace_dropped == len(everything.grasps) - len(
        checked.grasps
    )
    assert [g for g in everything.grasps if g in checked.grasps] == checked.grasps  # a subset, same order
    with trained.sessions.use(session) as s:
        surface = s.volume.surface_points()
    assert checked.grasps == clear_grasps(everything.grasps, surface, workspace=(np.eye(4), 0.3))
    first = trained.plan(session, GraspQuery(threshold=0.0, clearance=True, max_grasps=1, grip=False))
    assert first.grasps == checked.grasps[:1]  # the best clear grasp, not the best grasp if it collides


def test_the_antipodal_planner_takes_the_option_too(trained):
    session = fused_session(trained, views=2)
    everything = trained.plan(session, GraspQuery(planner="antipodal", clearance=False, grip=False))
    checked = trained.plan(session, GraspQuery(planner="antipodal", clearance=True, grip=False))
    assert everything.clearance_dropped is None and checked.clearance_dropped is not None
    assert [g for g in everything.grasps if g in checked.grasps] == checked.grasps
    assert checked.clearance_dropped + checked.workspace_dropped == len(everything.grasps) - len(
        checked.grasps
    )


def test_the_option_over_http_and_grpc(trained):
    """Accepted by both front ends, on when not given (the service's default), the planner's
    own grasps when false, a subset when true, the same answers."""
    session = fused_session(trained)
    server, port = build_server(trained, "127.0.0.1", 0)
    try:
        with TestClient(create_app(core=trained)) as http, GRPCClient(f"grpc://127.0.0.1:{port}") as rpc:
            url = f"/sessions/{session}/grasps"
            answers = {
                value: http.get(
                    url,
                    params={
                        "threshold": 0.0,
                        "grip": "false",
                        **({} if value is None else {"clearance": value}),
                    },
                )
                for value in (None, "false", "true")
            }
            assert all(a.status_code == 200 for a in answers.values())
            default, plain, on = (GraspResult.model_validate(a.json()) for a in answers.values())
            assert plain.clearance_dropped is None
            assert on.grasps and len(on.grasps) < len(plain.grasps)
            assert [g for g in plain.grasps if g in on.grasps] == on.grasps
            assert on.clearance_dropped + on.workspace_dropped == len(plain.grasps) - len(on.grasps)
            assert (default.grasps, default.clearance_dropped) == (on.grasps, on.clearance_dropped)
            for clearance, expected in ((False, plain), (True, on), (None, on)):
                over_grpc = rpc.grasps(session, threshold=0.0, clearance=clearance, grip=False)
                assert over_grpc.grasps == expected.grasps
                assert (over_grpc.clearance_dropped, over_grpc.workspace_dropped) == (
                    expected.clearance_dropped,
                    expected.workspace_dropped,
                )
            bad = http.get(url, params={"clearance": "maybe"})
            assert bad.status_code == 422 and "clearance" in bad.json()["message"]
            # A bool cannot be invalid on the wire; an invalid request with the option set still is.
            with grpc.insecure_channel(f"127.0.0.1:{port}") as channel:
                request = pb.GraspQuery(session_id=session, threshold=2.0, clearance=True, grip=False)
                with pytest.raises(grpc.RpcError) as caught:
                    GraspPlanningStub(channel).GetGrasps(request)
            assert caught.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    finally:
        server.stop(None)


@pytest.mark.parametrize("clearance", [True, False, None])
def test_the_grpc_message_carries_the_option_whenever_set(clearance):
    """Off is sent too: left unset, the service applies its default (on)."""
    message = convert.grasp_query_message("s", GraspQuery(clearance=clearance))
    assert message.HasField("clearance") is (clearance is not None)
    assert GraspQuery(**convert.grasp_query_dict(message)).clearance is clearance


def test_the_client_sends_the_option_whenever_set():
    assert "clearance" not in GraspQuery().to_params()
    assert GraspQuery(clearance=True).to_params()["clearance"] == "true"
    assert GraspQuery(clearance=False).to_params()["clearance"] == "false"
