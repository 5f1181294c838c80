"""The grip check: fingers closing on grids of known geometry, the verdict in any workspace
frame, and the ``grip`` grasp option in the planning core and over HTTP and gRPC."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np
import pytest
from fastapi.testclient import TestClient
from scipy.spatial.transform import Rotation

from client.grpc_client import GRPCClient
from service.core import PlanningService
from service.grip import GripConfig, GripMeasure, gripping_grasps, measure_grip, support_height
from service.grpc.server import build_server
from service.http_app import create_app
from service.settings import PACKAGED_MODEL, Settings
from service.tsdf import TSDFVolume
from tests.helpers.scenes import INTRINSICS, TABLE_Z, BoxScene, circle_views
from vgn_contract.grpc_api import convert
from vgn_contract.schemas import Grasp, GraspQuery, GraspResult, SessionCreate

N, SIZE = 40, 0.3
VOXEL = SIZE / N
TRUNCATION = 4 * VOXEL
#: A grasp from straight above: approach -z (world), fingers closing along world y.
FROM_ABOVE = Rotation.from_matrix([[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]])


def grid_of(signed_distance: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """The network input a perfect fusion of a surface gives: (tsdf + 1) / 2 within the
    truncation band, 0 beyond it (far free space and deep inside alike), at voxel centres."""
    centres = (np.stack(np.meshgrid(*[np.arange(N)] * 3, indexing="ij"), axis=-1) + 0.5) * VOXEL
    tsdf = np.clip(signed_distance(centres) / TRUNCATION, -1.0, 1.0)
    return np.where(np.abs(tsdf) < 0.98, (tsdf + 1.0) / 2.0, 0.0).astype(np.float32)


def slab(thickness: float, tilt_deg: float, centre=(0.15, 0.15, 0.15)) -> Callable[[np.ndarray], np.ndarray]:
    """A wall ``thickness`` thick whose faces are turned ``tilt_deg`` about x from facing ±y."""
    tilt = np.radians(tilt_deg)
    normal = np.array([0.0, np.cos(tilt), np.sin(tilt)])
    return lambda p: np.abs((p - np.asarray(centre)) @ normal) - thickness / 2


def box(lower, upper) -> Callable[[np.ndarray], np.ndarray]:
    """An axis-aligned box: distance outside, negative depth inside."""
    lower, upper = np.asarray(lower), np.asarray(upper)

    def distance(p: np.ndarray) -> np.ndarray:
        outside = np.linalg.norm(np.maximum(np.maximum(lower - p, p - upper), 0.0), axis=-1)
        inside = np.minimum(np.min(p - lower, axis=-1), np.min(upper - p, axis=-1))
        return np.where(inside > 0, -inside, outside)

    return distance


def grip_at(grid: np.ndarray, position, rotation: Rotation = FROM_ABOVE, support="find"):
    """The check's measure of one grasp whose pads sit at ``position`` + 4 cm along the approach."""
    origin = np.asarray(position, dtype=float) - rotation.apply([0.0, 0.0, 0.041])
    return measure_grip(grid, VOXEL, origin[None], rotation.as_quat()[None], support=support)


def test_fingers_closing_on_square_faces_meet_them_squarely():
    measure = grip_at(grid_of(slab(0.03, 0.0)), (0.15, 0.15, 0.15))
    assert measure.contact.tolist() == [[1.0, 1.0]]
    assert np.all(measure.alignment > 0.97)
    # Each open pad is 4 cm out; the faces are 1.5 cm from the middle: 2.5 cm of closing.
    assert np.allclose(measure.reach, 0.025, atol=0.003)
    assert measure.passes().tolist() == [True]


@pytest.mark.parametrize("tilt", [20.0, 45.0, 70.0])
def test_alignment_is_the_cosine_of_the_faces_tilt(tilt):
    measure = grip_at(grid_of(slab(0.03, tilt)), (0.15, 0.15, 0.15))
    assert np.allclose(measure.alignment, np.cos(np.radians(tilt)), atol=0.05)
    assert measure.passes().tolist() == [bool(np.cos(np.radians(tilt)) >= GripConfig().min_alignment)]


def test_nothing_between_the_fingers_or_on_one_side_only_is_refused():
    # Above the table, nothing between the fingers: the rays cross observed free space to the middle.
    table = grip_at(grid_of(lambda p: p[..., 2] - 0.05), (0.15, 0.15, 0.065))
    assert table.known.tolist() == [[1.0, 1.0]] and table.contact.tolist() == [[0.0, 0.0]]
    assert not table.passes()[0]
    # An object only on the +y side of the grasp: the -y finger closes on nothing.
    aside = grip_at(grid_of(box((0.10, 0.155, 0.10), (0.20, 0.18, 0.20))), (0.15, 0.15, 0.15))
    assert aside.contact[0, 0] == 1.0 and aside.known[0, 1] == 1.0 and aside.contact[0, 1] == 0.0
    assert not aside.passes()[0]


def test_a_finger_on_a_side_no_camera_saw_is_left_to_the_network():
    """With one view the far side of an object is unobserved: its finger's rays see nothing
    before the middle, so only the near finger is judged."""
    grid = grid_of(slab(0.03, 0.0))
    grid[:, : N // 2] = 0.0  # y below the middle never observed (the slab's -y face included)
    measure = grip_at(grid, (0.15, 0.15, 0.15))
    assert measure.known[0, 0] == 1.0 and measure.known[0, 1] == 0.0
    assert measure.passes().tolist() == [True]
    tilted = grid_of(slab(0.03, 70.0))
    tilted[:, : N // 2] = 0.0
    assert not grip_at(tilted, (0.15, 0.15, 0.15)).passes()[0], "the finger it sees is still judged"
    nothing = grip_at(np.zeros((N, N, N), np.float32), (0.15, 0.15, 0.15))
    assert nothing.known.tolist() == [[0.0, 0.0]] and nothing.passes()[0], "nothing observed: no verdict"


def test_where_some_grasps_grip_squarely_only_those_are_kept():
    """A square wall and one tilted 55° (cosine 0.57: enough for the check, short of a square
    grip): grasps on both keep the square one; grasps on the tilted wall alone are all kept."""
    square, tilted = slab(0.03, 0.0), slab(0.03, 55.0)
    grid = grid_of(lambda p: np.where(p[..., 0] < 0.15, square(p), tilted(p)))
    origins = [np.array([x, 0.15, 0.15]) - FROM_ABOVE.apply([0.0, 0.0, 0.041]) for x in (0.08, 0.22)]
    grasps = [
        Grasp(position=o, orientation=FROM_ABOVE.as_quat(), approach=FROM_ABOVE.apply([0.0, 0.0, 1.0]),
              width=0.03, quality=0.9)
        for o in origins
    ]  # fmt: skip
    measure = measure_grip(grid, VOXEL, np.array(origins), np.tile(FROM_ABOVE.as_quat(), (2, 1)))
    assert measure.passes().tolist() == [True, True]
    assert measure.kept().tolist() == [True, False]
    assert gripping_grasps(grasps, grid, VOXEL, np.eye(4)) == grasps[:1]
    assert gripping_grasps(grasps[1:], grid, VOXEL, np.eye(4)) == grasps[1:], "no square grip: the rest stay"
    no_preference = GripConfig(preferred_alignment=GripConfig().min_alignment)
    assert gripping_grasps(grasps, grid, VOXEL, np.eye(4), no_preference) == grasps


def test_the_thresholds_are_the_configs():
    measure = grip_at(grid_of(slab(0.03, 45.0)), (0.15, 0.15, 0.15))
    assert measure.passes(GripConfig(min_alignment=0.6)).tolist() == [True]
    assert measure.passes(GripConfig(min_alignment=0.8)).tolist() == [False]
    with pytest.raises(ValueError):
        GripConfig(min_contact=1.5)
    with pytest.raises(ValueError):
        GripConfig(min_alignment=-2.0)
    with pytest.raises(ValueError):
        GripConfig(preferred_alignment=1.5)


def test_the_verdict_does_not_depend_on_the_workspace_frame():
    """World-frame grasps on a workspace whose corner is moved and turned get the verdict the same
    grasps get in the workspace frame."""
    grid = grid_of(box((0.12, 0.135, 0.05), (0.18, 0.165, 0.11)))
    rng = np.random.default_rng(3)
    turns = Rotation.from_euler("z", rng.uniform(-0.6, 0.6, (40, 1))) * FROM_ABOVE
    positions = np.array([0.15, 0.15, 0.121]) + rng.uniform(-0.02, 0.02, (40, 3))
    local = measure_grip(grid, VOXEL, positions, turns.as_quat()).passes()
    assert 0 < local.sum() < len(local), "the sample must hold both verdicts"
    corner = np.eye(4)
    corner[:3, :3] = Rotation.from_euler("z", 30, degrees=True).as_matrix()
    corner[:3, 3] = (0.4, -0.2, 0.7)
    world = Rotation.from_matrix(corner[:3, :3])
    grasps = [
        Grasp(position=corner[:3, :3] @ p + corner[:3, 3], orientation=(world * r).as_quat(),
              approach=(world * r).apply([0.0, 0.0, 1.0]), width=0.03, quality=0.9)
        for p, r in zip(positions, turns, strict=True)
    ]  # fmt: skip
    kept = gripping_grasps(grasps, grid, VOXEL, corner)
    assert kept == [g for g, ok in zip(grasps, local, strict=True) if ok]
    assert gripping_grasps([], grid, VOXEL, corner) == []


@pytest.fixture(scope="module")
def trained() -> Iterator[PlanningService]:
    """The packaged model with the checks alone: a dropped grasp is not tried again in other poses, and
    the antipodal check does not narrow what the grip check passed (tests/service/test_checks.py covers
    both)."""
    settings = Settings(
        model=PACKAGED_MODEL, api_key=None, max_sessions=8, alternatives=False, antipodal_check=False
    )
    service = PlanningService.from_settings(settings)
    yield service
    service.close()


def fused_session(core: PlanningService, scene: BoxScene | None = None) -> str:
    """A session with ``scene`` (default the usual box) fused from the six circle views."""
    session = core.create_session(SessionCreate(intrinsics=INTRINSICS)).session_id
    for pose in circle_views():
        core.add_frame(session, (scene or BoxScene()).depth(pose), pose)
    return session


def test_the_core_checks_every_grasp_before_max_grasps(trained):
    session = fused_session(trained)
    everything = trained.plan(session, GraspQuery(threshold=0.0, clearance=False, grip=False))
    checked = trained.plan(session, GraspQuery(threshold=0.0, clearance=False, grip=True))
    assert everything.grip_dropped is None
    assert 0 < len(checked.grasps) < len(everything.grasps)
    assert checked.grip_dropped == len(everything.grasps) - len(checked.grasps)
    assert [g for g in everything.grasps if g in checked.grasps] == checked.grasps  # a subset, same order
    grid = trained.grid(session)
    workspace = np.eye(4)
    assert checked.grasps == gripping_grasps(everything.grasps, grid, VOXEL, workspace)
    first = trained.plan(session, GraspQuery(threshold=0.0, clearance=False, grip=True, max_grasps=1))
    assert first.grasps == checked.grasps[:1]
    both = trained.plan(session, GraspQuery(threshold=0.0))  # the default: both checks
    assert both.clearance_dropped is not None and both.grip_dropped is not None
    assert both.grasps == gripping_grasps(
        trained.plan(session, GraspQuery(threshold=0.0, grip=False)).grasps, grid, VOXEL, workspace
    )
    antipodal = trained.plan(session, GraspQuery(planner="antipodal", grip=True))
    assert antipodal.grip_dropped is not None


def test_the_operator_sets_the_square_grip(trained):
    """``VGN_GRIP_PREFERRED_ALIGNMENT`` reaches the check: set between the alignments of the box's
    grasps, it keeps only the squarer ones; at the minimum alignment, every grasp that passes."""
    session = fused_session(trained)
    unchecked = trained.plan(session, GraspQuery(threshold=0.0, clearance=False, grip=False)).grasps
    passing = gripping_grasps(
        unchecked, trained.grid(session), VOXEL, np.eye(4), GripConfig(preferred_alignment=0.5)
    )
    measure = measure_grip(trained.grid(session), VOXEL, np.array([g.position for g in passing]),
                           np.array([g.orientation for g in passing]))  # fmt: skip
    squareness = np.where(measure.known > 0, measure.alignment, 1.0).min(axis=1)  # of the fingers it judges
    between = float(np.sort(squareness)[len(squareness) // 2])
    kept = measure.kept(GripConfig(preferred_alignment=between))
    squarer = [g for g, square in zip(passing, kept, strict=True) if square]
    for preferred, expected in ((0.5, passing), (between, squarer)):
        core = PlanningService.from_settings(
            Settings(
                model=PACKAGED_MODEL,
                api_key=None,
                grip_preferred_alignment=preferred,
                alternatives=False,
                antipodal_check=False,
            )
        )
        try:
            session = fused_session(core)
            assert core.plan(session, GraspQuery(threshold=0.0, clearance=False)).grasps == expected
        finally:
            core.close()
    assert 0 < len(expected) < len(passing)
    with pytest.raises(ValueError):
        Settings(grip_preferred_alignment=1.5)


def test_a_volume_of_one_frame_is_not_checked(trained):
    """From one view the fused surface misleads the check: it runs from the second frame on."""
    session = trained.create_session(SessionCreate(intrinsics=INTRINSICS)).session_id
    first, second = circle_views()[:2]
    trained.add_frame(session, BoxScene().depth(first), first)
    one = trained.plan(session, GraspQuery(threshold=0.0, clearance=False, grip=True))
    assert one.grip is True and one.grip_dropped is None, "on for the request, but not run"
    assert one.grasps == trained.plan(session, GraspQuery(threshold=0.0, clearance=False, grip=False)).grasps
    trained.add_frame(session, BoxScene().depth(second), second)
    assert (
        trained.plan(session, GraspQuery(threshold=0.0, clearance=False, grip=True)).grip_dropped is not None
    )


def test_the_option_over_http_and_grpc(trained):
    session = fused_session(trained)
    server, port = build_server(trained, "127.0.0.1", 0)
    try:
        with TestClient(create_app(core=trained)) as http, GRPCClient(f"grpc://127.0.0.1:{port}") as rpc:
            url = f"/sessions/{session}/grasps"
            answers = [
                http.get(url, params={"threshold": 0.0, **({} if value is None else {"grip": value})})
                for value in (None, "false", "true")
            ]
            assert all(a.status_code == 200 for a in answers)
            default, plain, on = (GraspResult.model_validate(a.json()) for a in answers)
            assert plain.grip_dropped is None and on.grip_dropped is not None
            assert (default.grasps, default.grip_dropped) == (on.grasps, on.grip_dropped)
            assert (default.grip, plain.grip, on.grip) == (True, False, True), "each answer says"
            for grip, expected in ((False, plain), (True, on), (None, on)):
                over_grpc = rpc.grasps(session, threshold=0.0, grip=grip)
                assert over_grpc.grasps == expected.grasps
                assert (over_grpc.grip, over_grpc.grip_dropped) == (expected.grip, expected.grip_dropped)
            bad = http.get(url, params={"grip": "maybe"})
            assert bad.status_code == 422 and "grip" in bad.json()["message"]
            assert http.get("/model").json()["defaults"]["grip"] is True
    finally:
        server.stop(None)


@pytest.mark.parametrize("grip", [True, False, None])
def test_the_option_travels_whenever_set(grip):
    """Off is sent too: left unset, the service applies its default (on)."""
    message = convert.grasp_query_message("s", GraspQuery(grip=grip))
    assert message.HasField("grip") is (grip is not None)
    assert GraspQuery(**convert.grasp_query_dict(message)).grip is grip
    assert GraspQuery(grip=grip).to_params().get("grip") == {True: "true", False: "false", None: None}[grip]


def test_a_grip_exactly_at_the_least_contact_and_alignment_passes():
    """The bounds are "at least": a finger on them passes, one just under either does not."""
    config = GripConfig()
    at = np.full((1, 2), config.min_alignment)
    contact = np.full((1, 2), config.min_contact)
    known = np.ones((1, 2))
    reach = np.zeros((1, 2))
    assert GripMeasure(known, contact, at, reach).passes(config).tolist() == [True]
    assert GripMeasure(known, contact, np.nextafter(at, 0.0), reach).passes(config).tolist() == [False]
    assert GripMeasure(known, np.nextafter(contact, 0.0), at, reach).passes(config).tolist() == [False]
    square = np.full((1, 2), config.preferred_alignment)
    assert GripMeasure(known, contact, square, reach).kept(config).tolist() == [True]


def test_the_support_plane_is_where_most_of_the_surface_lies_flat():
    table = box((0.0, 0.0, 0.0), (SIZE, SIZE, 0.05))
    on_table = box((0.10, 0.10, 0.05), (0.16, 0.16, 0.11))
    assert support_height(grid_of(lambda p: np.minimum(table(p), on_table(p))), VOXEL) == pytest.approx(
        0.05, abs=1e-3
    )
    assert support_height(grid_of(box((0.10, 0.10, 0.10), (0.16, 0.16, 0.16))), VOXEL) is None  # no table


def test_a_thin_object_on_the_table_is_judged_by_its_faces_not_the_tables_blur():
    """A 1.2 cm tile fused from six views: within a voxel or two of the table the grid's gradient
    tilts its side faces up; judged by the horizontal part of the normal there, a grasp across
    it grips squarely."""
    tile = BoxScene(lower=(0.125, 0.1275, TABLE_Z), upper=(0.175, 0.1725, TABLE_Z + 0.012))
    volume = TSDFVolume(SIZE, N)
    for pose in circle_views():
        volume.integrate(tile.depth(pose), INTRINSICS, pose, max_depth=1.5)
    grid = volume.grid()
    assert support_height(grid, VOXEL) == pytest.approx(TABLE_Z, abs=1e-3)
    pads = (0.15, 0.15, TABLE_Z + 0.009)  # fingertips at the table top
    blurred, judged = grip_at(grid, pads, support=None), grip_at(grid, pads)
    assert blurred.alignment.min() < 0.7 <= judged.alignment.min()
    assert judged.square().tolist() == [True]
