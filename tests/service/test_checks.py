"""The chained checks and their alternatives: a location whose network orientation a check drops
is kept in another pose that passes, and without alternatives the chain is the two checks in turn."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from service.baseline import AntipodalConfig, grips_antipodally, plan_antipodal
from service.checks import (
    SUPPORT_BAND_VOXELS,
    SUPPORT_CONTACT_TOLERANCE,
    Checked,
    check_grasps,
    clear_of,
    contact_tolerances,
)
from service.clearance import (
    FALLBACK_MARGIN,
    NETWORK_FINE_MIN_POINTS,
    ClearanceConfig,
    approach_is_clear,
    clear_grasps,
    fingers_inside,
)
from service.core import PlanningService
from service.grid_surface import grid_surface_points
from service.grip import GripConfig, gripping_grasps, support_height
from service.planner import antipodal_config
from service.settings import PACKAGED_MODEL, Settings
from tests.helpers.scenes import INTRINSICS, TABLE_Z, BoxScene, circle_views
from tests.service.test_grip import FROM_ABOVE, SIZE, VOXEL, box, fused_session, grid_of
from vgn_contract.gripper_description import default_gripper
from vgn_contract.schemas import ANTIPODAL_DEFAULT_THRESHOLD, Grasp, GraspQuery, GraspResult, SessionCreate

#: A vertical wall 3 cm thick through the middle of the grid, its faces turned 40 degrees about z
#: from facing ±y: fingers closing along y meet it at 40 degrees, too slanted for :data:`STRICT`.
TURNED_WALL = 40.0
#: A grip check that asks for faces within 37 degrees of square.
STRICT = GripConfig(min_alignment=0.8, preferred_alignment=0.8)


def wall(thickness: float, turn_deg: float, centre=(0.15, 0.15, 0.15)):
    turn = np.radians(turn_deg)
    normal = np.array([-np.sin(turn), np.cos(turn), 0.0])
    return lambda p: np.maximum(np.abs((p - np.asarray(centre)) @ normal) - thickness / 2, p[..., 2] - 0.2)


def grasp_at(pads, rotation: Rotation = FROM_ABOVE, quality: float = 0.9, width: float = 0.03) -> Grasp:
    """A grasp whose pads sit at ``pads``, workspace = world (identity workspace pose)."""
    origin = np.asarray(pads, dtype=float) - rotation.apply([0.0, 0.0, 0.041])
    return Grasp(position=origin.tolist(), orientation=rotation.as_quat().tolist(),
                 approach=rotation.apply([0, 0, 1]).tolist(), width=width, quality=quality)  # fmt: skip


def checked(grasps, grid, alternatives=True):
    surface = grid_surface_points(grid, VOXEL)
    return check_grasps(grasps, surface, grid, VOXEL, np.eye(4), SIZE, STRICT, alternatives)


def test_a_grasp_on_a_slanted_wall_is_turned_until_its_fingers_meet_the_faces_squarely():
    grid = grid_of(wall(0.03, TURNED_WALL))
    grasp = grasp_at((0.15, 0.15, 0.17))
    plain = checked([grasp], grid, alternatives=False)
    assert plain.grasps == [] and plain.grip_dropped == 1 and plain.replaced == 0
    turned = checked([grasp], grid)
    assert turned.replaced == 1 and turned.grip_dropped == 0 and len(turned.grasps) == 1
    kept = turned.grasps[0]
    closing = Rotation.from_quat(kept.orientation).apply([0.0, 1.0, 0.0])
    wall_normal = [-np.sin(np.radians(TURNED_WALL)), np.cos(np.radians(TURNED_WALL)), 0.0]
    assert abs(closing @ wall_normal) > 0.97  # the squarest pose tried: the 45-degree turn
    assert np.allclose(kept.approach, grasp.approach)  # a turn about the approach, not a tilt
    assert kept.quality == grasp.quality  # the location's quality is the network's
    assert kept.width == pytest.approx(0.03, abs=0.006)  # measured where the fingers met the wall


def test_a_grasp_closing_on_nothing_stays_dropped_in_every_pose():
    grid = grid_of(box((0.0, 0.0, 0.0), (0.3, 0.3, 0.05)))  # an empty table top
    above_table = grasp_at((0.15, 0.15, 0.075))  # pads 2.5 cm above it: the fingers close on air
    result = checked([above_table], grid)
    assert result.grasps == [] and result.replaced == 0 and result.grip_dropped == 1


def test_without_alternatives_the_chain_is_the_clearance_check_then_the_grip_check():
    grid = grid_of(box((0.10, 0.12, 0.0), (0.16, 0.15, 0.20)))
    rng = np.random.default_rng(3)
    rotations = Rotation.from_euler("z", rng.uniform(0, 180, (40, 1)), degrees=True) * FROM_ABOVE
    pads = rng.uniform([0.08, 0.10, 0.12], [0.18, 0.17, 0.21], (40, 3))
    grasps = [grasp_at(p, r) for p, r in zip(pads, rotations, strict=True)]
    surface = grid_surface_points(grid, VOXEL)
    clear = clear_grasps(grasps, surface)
    expected = gripping_grasps(clear, grid, VOXEL, np.eye(4), STRICT)
    result = checked(grasps, grid, alternatives=False)
    assert result.grasps == expected and 0 < len(expected) < len(grasps)
    assert result.clearance_dropped == len(grasps) - len(clear)
    assert result.grip_dropped == len(clear) - len(expected)
    with_alternatives = checked(grasps, grid)
    assert set(map(id, expected)) <= set(map(id, with_alternatives.grasps))  # passing grasps stay as they are
    assert len(with_alternatives.grasps) == len(expected) + with_alternatives.replaced


@pytest.fixture(scope="module")
def core() -> Iterator[PlanningService]:
    """The packaged model as a service starts by default, with the network's fallback down to any
    quality and no surface pairs before it."""
    service = PlanningService.from_settings(
        Settings(model=PACKAGED_MODEL, api_key=None, fallback_threshold=0.0, surface_fallback=False)
    )
    yield service
    service.close()


def test_every_grasp_of_the_default_answer_passes_the_checks_as_it_is_answered(core):
    session = fused_session(core)
    answer = core.plan(session, GraspQuery(threshold=0.0))
    assert answer.grasps
    with core.sessions.use(session) as state:
        surface = state.volume.surface_points()
    again = check_grasps(answer.grasps, surface, core.grid(session), VOXEL, np.eye(4), SIZE, core.grip_config,
                         alternatives=False)  # fmt: skip
    assert again.grasps == answer.grasps


def test_a_look_with_nothing_at_the_operating_threshold_falls_back_to_what_the_checks_vouch_for(core):
    # A flat box (8 x 6 x 2 cm): the packaged model is less sure of it than of the usual 6 cm box.
    scene = BoxScene(upper=(0.19, 0.18, TABLE_Z + 0.02))
    session = core.create_session(SessionCreate(intrinsics=INTRINSICS)).session_id
    for pose in circle_views():
        core.add_frame(session, scene.depth(pose), pose)
    operating = core.planner.default_threshold
    named = core.plan(session, GraspQuery(threshold=operating))
    assert named.grasps == [] and named.fallback is False  # a named threshold: no fallback
    fallback = core.plan(session, GraspQuery())
    assert fallback.grasps and fallback.threshold == 0.0  # the service's floor here
    assert fallback.fallback is True and fallback.threshold == core.model_info().defaults.fallback_threshold
    assert all(g.quality < operating for g in fallback.grasps)
    plain = core.plan(session, GraspQuery(turn_average=False, clearance=False, grip=False))
    assert plain.threshold == operating  # no check to vouch for a grasp below it: no fallback
    assert (plain.fallback, plain.clearance, plain.grip) == (False, False, False)


@pytest.mark.parametrize("surface_fallback", [True, False])
def test_before_the_lower_threshold_the_surfaces_antipodal_pairs_are_checked_and_offered(
    surface_fallback,
):
    """A low slab (10 x 5 x 2.5 cm): the packaged model offers nothing at its operating threshold and a
    few grasps below it, while the slab's sides make antipodal pairs that pass the clearance check.
    The pairs come first (in simulation they held more often than the network's grasps below its
    threshold), those whose pads meet opposed faces of the grid's surface where some do; without them
    the network's lower-threshold grasps answer."""
    settings = Settings(model=PACKAGED_MODEL, api_key=None, surface_fallback=surface_fallback)
    service = PlanningService.from_settings(settings)
    try:
        session = fused_session(
            service, BoxScene(lower=(0.12, 0.12, TABLE_Z), upper=(0.22, 0.17, TABLE_Z + 0.025))
        )
        answer = service.plan(session, GraspQuery())
        assert answer.fallback is True and answer.threshold == settings.fallback_threshold
        if not surface_fallback:
            assert answer.grasps and answer.model == service.planner.model_id
            assert all(g.quality < service.planner.default_threshold for g in answer.grasps)
            return
        assert answer.grasps and answer.model == "antipodal"
        with service.sessions.use(session) as state:
            surface, faces = state.volume.surface_points(), state.volume.surface_cloud()
        every = service.plan(session, GraspQuery(planner="antipodal", threshold=settings.fallback_threshold,
                                                 grip=False, max_grasps=None)).grasps  # fmt: skip
        cone = np.radians(settings.antipodal_check_grid_angle)
        on_grid = [grips_antipodally(faces, [g.position], Rotation.from_quat([g.orientation]).as_matrix(),
                                     default_gripper(), cone)[0] for g in every]  # fmt: skip
        # Those whose pads meet opposed faces of the grid's surface too, where some do (the slab's sides
        # are too low for the grid's faces to show them: here none does, and all of them answer).
        kept = [g for g, keep in zip(every, on_grid, strict=True) if keep] or every
        assert {tuple(g.position) for g in answer.grasps} <= {tuple(g.position) for g in kept}
        # Each passes the clearance check as it is offered; the grip check is not theirs to pass:
        # the pairs met their own antipodal test on the fine cloud, where the coarse grid blurs thin walls.
        again = check_grasps(answer.grasps, surface, None, VOXEL, np.eye(4), SIZE, service.grip_config,
                             alternatives=False)  # fmt: skip
        assert again.grasps == answer.grasps and answer.grip_dropped is None  # the grip check did not run
        named = service.plan(session, GraspQuery(threshold=0.8))
        assert named.grasps == [] and named.model == service.planner.model_id  # a named threshold: neither
    finally:
        service.close()


@pytest.mark.parametrize(
    ("grid_angle", "angle"), [(35.0, 20.0), (0.5, 20.0), (0.5, 12.0), (0.5, 0.5)], ids=str
)
def test_the_antipodal_check_keeps_grasps_whose_pads_meet_opposed_faces_or_answers_with_pairs(
    grid_angle, angle
):
    """On the box the network's checked grasps close across its sides. The check keeps those whose pads
    meet faces of the grid's surface opposed within ``grid_angle`` of the closing axis: all within 35
    degrees. Where none does (within half a degree), it judges the fine cloud's faces within ``angle``:
    all within 20 degrees, some within 12 (the fused box's sides are not perfectly flat). Within half a
    degree none does there either: the surface's antipodal pairs that pass every check (the grip check
    too) answer instead. The fine cloud is read only where the grid's faces keep no grasp. Without the
    grip check it does not run."""
    query = GraspQuery(threshold=0.5)
    answers = {}
    for check in (False, True):
        settings = Settings(
            model=PACKAGED_MODEL,
            api_key=None,
            antipodal_check=check,
            antipodal_check_grid_angle=grid_angle,
            antipodal_check_angle=angle,
        )
        service = PlanningService.from_settings(settings)
        try:
            session = fused_session(service)
            answers[check] = service.plan(session, query)
            with service.sessions.use(session) as state:
                answers[check, "read the fine cloud"] = state.volume.cloud_read
            answers[check, "no grip check"] = service.plan(session, query.model_copy(update={"grip": False}))
            answers[check, "default"] = service.plan(session, GraspQuery())
            cloud, grid = service.cloud(session), service.grid(session)
            with service.sessions.use(session) as state:
                surface, faces = state.volume.surface_points(), state.volume.surface_cloud()
            grip_config = service.grip_config
            network = service.planner.model_id
        finally:
            service.close()
    unchecked, answer = answers[False], answers[True]
    # The fine cloud is read only where the grid's faces keep no grasp.
    assert answers[True, "read the fine cloud"] == (grid_angle != 35.0)
    assert not answers[False, "read the fine cloud"]
    # It refines the grip check: without that, the check does not run either.
    assert answers[True, "no grip check"].grasps == answers[False, "no grip check"].grasps
    assert unchecked.grasps and unchecked.model == network
    if angle == 0.5:
        assert answer.model == "antipodal" and answer.grasps and answer.grip_dropped is not None
        default = answers[True, "default"]  # the pairs answer at the baseline's threshold, not VGN's
        assert default.model == "antipodal" and default.threshold == ANTIPODAL_DEFAULT_THRESHOLD
        assert (
            answers[False, "default"].threshold
            == service.planner.default_threshold
            != ANTIPODAL_DEFAULT_THRESHOLD
        )
        assert default.fallback is False
        again = check_grasps(
            answer.grasps, surface, grid, VOXEL, np.eye(4), SIZE, grip_config, alternatives=False
        )
        assert again.grasps == answer.grasps  # each passes both checks as it is offered
        return
    assert answer.model == network and answer.grasps
    assert all(grasp in unchecked.grasps for grasp in answer.grasps)
    assert (len(answer.grasps) < len(unchecked.grasps)) == (angle == 12.0)
    rotations = Rotation.from_quat([g.orientation for g in answer.grasps]).as_matrix()
    positions = np.array([g.position for g in answer.grasps])
    on_grid = grips_antipodally(faces, positions, rotations, default_gripper(), np.radians(grid_angle))
    assert on_grid.all() == (grid_angle == 35.0)
    assert not on_grid.any() or grid_angle == 35.0
    assert grips_antipodally(cloud, positions, rotations, default_gripper(), np.radians(angle)).all()


def test_the_networks_grasps_answered_once_the_fine_cloud_is_read_are_cleared_against_it():
    """Beside the box stands a plate 3 mm thick, where the fingers of grasps across the box's 6 cm side
    come down: the grid's 7.5 mm voxels barely show it, the fine cloud does. With the grid's cone at a
    hundredth of a degree the network's grasps are judged on the fine cloud's faces (89 degrees keeps them);
    the fine cloud read, it clears them as it clears the surface's pairs (more of its points to veto one),
    so none answered brushes the plate, while the grid's surface alone would have let some through."""
    box, plate = BoxScene(), BoxScene(lower=(0.11, 0.19, TABLE_Z), upper=(0.19, 0.193, TABLE_Z + 0.06))

    def depth(pose: np.ndarray) -> np.ndarray:
        hits = [np.where(d > 0, d, np.inf) for d in (box.depth(pose), plate.depth(pose))]
        nearest = np.minimum(*hits)
        return np.where(np.isfinite(nearest), nearest, 0.0).astype(np.float32)

    query = GraspQuery(threshold=0.5)
    answers = {}
    for check in (False, True):
        settings = Settings(model=PACKAGED_MODEL, api_key=None, antipodal_check=check,
                            antipodal_check_grid_angle=0.01, antipodal_check_angle=89.0)  # fmt: skip
        service = PlanningService.from_settings(settings)
        try:
            session = service.create_session(SessionCreate(intrinsics=INTRINSICS)).session_id
            for pose in circle_views():
                service.add_frame(session, depth(pose), pose)
            answers[check] = service.plan(session, query)
            cloud, grid, network = service.cloud(session), service.grid(session), service.planner.model_id
        finally:
            service.close()

    def brushing(answer: GraspResult) -> int:
        # The answer's hand, with as many of the fine cloud's points to veto as the service's.
        hand = ClearanceConfig(margin=answer.clearance_margin, min_points=NETWORK_FINE_MIN_POINTS)
        kept = clear_of(answer.grasps, cloud[:, :3], grid, VOXEL, np.eye(4), SIZE, hand)
        return len(answer.grasps) - len(kept)

    grid_cleared, answer = answers[False], answers[True]
    assert grid_cleared.model == network and brushing(grid_cleared) > 0  # the grid's surface misses it
    assert answer.model == network and answer.grasps and brushing(answer) == 0
    assert answer.clearance_margin == grid_cleared.clearance_margin
    assert {tuple(g.position) for g in answer.grasps} < {tuple(g.position) for g in grid_cleared.grasps}


def test_the_surfaces_pairs_on_the_grids_opposed_faces_answer_before_the_fine_cloud_is_asked():
    """The network's grasps on the box, turned 45 degrees about their approach, close on its edges (those
    whose pads still meet opposed faces aside): their pads meet no opposed faces of the grid's surface
    within 35 degrees, though a fine-cloud cone of 89 degrees would keep them. The surface's pairs whose pads meet the grid's opposed faces come before
    that verdict: they answer, each passing every check and opposed on the grid, the narrow ones only."""
    settings = Settings(
        model=PACKAGED_MODEL, api_key=None, antipodal_check_angle=89.0, narrow_pair_share=0.85
    )
    service = PlanningService.from_settings(settings)
    try:
        session = fused_session(service)
        plain = service.plan(session, GraspQuery(threshold=0.5, clearance=False, grip=False)).grasps
        cloud, grid = service.cloud(session), service.grid(session)
        with service.sessions.use(session) as state:
            surface, faces = state.volume.surface_points(), state.volume.surface_cloud()
        turn = Rotation.from_euler("z", 45.0, degrees=True)
        turned = [g.model_copy(update={"orientation": (Rotation.from_quat(g.orientation) * turn).as_quat().tolist()})
                  for g in plain]  # fmt: skip

        def checked_of(grasps: list[Grasp]):
            return check_grasps(grasps, surface, grid, VOXEL, np.eye(4), SIZE, service.grip_config, False)

        def opposed(grasps: list[Grasp], points: np.ndarray, degrees: float) -> np.ndarray:
            rotations = Rotation.from_quat([g.orientation for g in grasps]).as_matrix()
            positions = np.array([g.position for g in grasps])
            return grips_antipodally(points, positions, rotations, default_gripper(), np.radians(degrees))

        turned = [g for g, keep in zip(turned, opposed(turned, faces, 35.0), strict=True) if not keep]
        assert turned and opposed(turned, cloud, 89.0).any()

        def checked_pairs(config: AntipodalConfig) -> Checked:  # as the service clears the surface's pairs
            checked = checked_of(plan_antipodal(cloud, np.eye(4), config, default_gripper()))
            return replace(
                checked, grasps=clear_of(checked.grasps, cloud[:, :3], grid, VOXEL, np.eye(4), SIZE)
            )

        unchecked = Checked(turned, clearance_dropped=0, grip_dropped=0, replaced=0)
        answer, model = service._opposed(unchecked, "vgn", faces, lambda: cloud, default_gripper(), checked_pairs,
                                         GraspQuery(), lambda checked: checked)  # fmt: skip
        pairs = checked_pairs(antipodal_config(GraspQuery())).grasps
    finally:
        service.close()
    assert model == "antipodal" and answer.grasps
    assert opposed(answer.grasps, faces, 35.0).all()
    assert checked_of(answer.grasps).grasps == answer.grasps  # each passes both checks as it is offered
    # Of the pairs opposed on the grid (across the box's 6 cm side, turned: 6.3 cm and more), the ones
    # that close on at most the given share of the 8 cm opening.
    widest = settings.narrow_pair_share * default_gripper().max_opening
    on_grid = [g for g, keep in zip(pairs, opposed(pairs, faces, 35.0), strict=True) if keep]
    assert answer.grasps == [g for g in on_grid if g.width <= widest] != on_grid


def test_a_grasp_whose_open_fingers_reach_outside_the_workspace_is_not_clear():
    """Beyond the cube the volume shows nothing: on an empty table top, a grasp at the cube's edge
    would otherwise pass with its fingers in the table outside it."""
    grid = grid_of(box((0.0, 0.0, 0.0), (0.3, 0.3, 0.05)))
    at_edge = grasp_at((0.15, 0.02, 0.075))  # fingers close along y: one opens to y = -2 cm
    result = checked([at_edge], grid, alternatives=False)
    # Counted as the workspace's drop, not the approach's: the answer says which stage dropped it.
    assert result.grasps == [] and (result.workspace_dropped, result.clearance_dropped) == (1, 0)
    inside = checked([grasp_at((0.15, 0.05, 0.075))], grid, alternatives=False)
    assert (inside.workspace_dropped, inside.clearance_dropped) == (0, 0)


def test_an_object_sticking_out_of_the_cube_is_taken_to_go_on_past_its_side():
    """The volume shows an object that crosses the cube's side only up to the side. A hand leaning out
    over that side towards a post is dropped where it would sweep through the rest of the object, and
    kept where the table beyond the side is empty."""
    table = box((0.0, 0.0, 0.0), (SIZE, SIZE, TABLE_Z))
    post = box((0.045, 0.14, TABLE_Z), (0.065, 0.16, TABLE_Z + 0.08))
    crossing = box((-0.06, 0.12, TABLE_Z), (0.012, 0.18, TABLE_Z + 0.06))  # 1.2 cm of it in the cube
    leaning = grasp_at((0.055, 0.15, TABLE_Z + 0.05), FROM_ABOVE * Rotation.from_euler("y", -55, degrees=True),
                       width=0.02)  # fmt: skip
    grid = grid_of(lambda p: np.minimum(np.minimum(table(p), post(p)), crossing(p)))
    surface = grid_surface_points(grid, VOXEL)
    result = check_grasps([leaning], surface, None, VOXEL, np.eye(4), SIZE, STRICT, False)
    assert result.grasps == [] and (result.workspace_dropped, result.clearance_dropped) == (0, 1)
    # Told not to carry it on (the service's last resort where nothing else clears), the check keeps it.
    observed = check_grasps([leaning], surface, None, VOXEL, np.eye(4), SIZE, STRICT, False, past_sides=False)
    assert observed.grasps == [leaning]
    # What the cube shows of that object does not meet the hand: what goes on past the side does.
    tolerance = contact_tolerances(
        surface, np.eye(4), support_height(grid, VOXEL), VOXEL, ClearanceConfig().margin
    )
    assert approach_is_clear(surface, [leaning.position], [leaning.orientation], point_tolerance=tolerance)[0]
    alone = grid_of(lambda p: np.minimum(table(p), post(p)))
    kept = check_grasps(
        [leaning], grid_surface_points(alone, VOXEL), None, VOXEL, np.eye(4), SIZE, STRICT, False
    )
    assert kept.grasps == [leaning]


def test_a_hand_coming_in_low_from_beside_the_cube_meets_the_table_there():
    """The volume shows the table only inside the cube, but it goes on past the sides. A block at the
    cube's edge grasped from outside, closing across it with the palm upright: low, the palm sweeps
    under the table's height outside the cube and is dropped; 2 cm higher it is kept. Neither meets
    what the volume shows."""
    table = box((0.0, 0.0, 0.0), (SIZE, SIZE, TABLE_Z))
    block = box((0.135, 0.02, TABLE_Z), (0.165, 0.05, TABLE_Z + 0.06))
    grid = grid_of(lambda p: np.minimum(table(p), block(p)))
    surface = grid_surface_points(grid, VOXEL)
    # Approach along +y from outside the cube, closing along x; the palm's 6 cm stand upright.
    sideways = Rotation.from_matrix([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    low, high = (grasp_at((0.15, 0.035, TABLE_Z + height), sideways) for height in (0.025, 0.045))
    assert clear_of([low, high], surface, grid, VOXEL, np.eye(4), SIZE) == [high]
    grasps = [low, high]
    positions, orientations = [g.position for g in grasps], [g.orientation for g in grasps]
    assert approach_is_clear(surface, positions, orientations).all()  # the observed surface: both clear
    assert fingers_inside(np.array(positions), np.array(orientations), np.eye(4), SIZE).all()


def test_without_the_grip_check_no_other_pose_is_tried():
    """Only the grip check can vouch for a pose the network never scored: a grasp on a post whose
    fingers open outside the cube stays dropped without it, and is turned into the cube with it."""
    grid = grid_of(box((0.135, 0.02, 0.0), (0.165, 0.05, 0.20)))  # a 3 cm post 2 cm from the cube's edge
    surface = grid_surface_points(grid, VOXEL)
    across = grasp_at((0.15, 0.035, 0.17))  # closing along y: one finger opens outside the cube
    without_grip = check_grasps([across], surface, None, VOXEL, np.eye(4), SIZE, STRICT, True)
    assert without_grip.grasps == [] and without_grip.replaced == 0 and without_grip.workspace_dropped == 1
    with_grip = check_grasps([across], surface, grid, VOXEL, np.eye(4), SIZE, STRICT, True)
    assert with_grip.replaced == 1 and len(with_grip.grasps) == 1
    closing = Rotation.from_quat(with_grip.grasps[0].orientation).apply([0.0, 1.0, 0.0])
    assert abs(closing[0]) > 0.97  # turned to close along x, both fingers inside the cube


def test_the_fingertips_may_meet_the_table_in_the_last_centimetre_of_the_approach():
    """Around a flat object a guarded approach stops when the fingertips touch the table: the
    support plane's points are forgiven in the last centimetre of the hand's own approach (the grown
    hand's, longer by the check's margin), an object's are not."""
    table = box((0.0, 0.0, 0.0), (SIZE, SIZE, TABLE_Z))
    tile = box((0.13, 0.1275, TABLE_Z), (0.17, 0.1725, TABLE_Z + 0.015))
    grid = grid_of(lambda p: np.minimum(table(p), tile(p)))
    surface = grid_surface_points(grid, VOXEL)
    support = support_height(grid, VOXEL)
    margin = ClearanceConfig().margin
    tolerance = contact_tolerances(surface, np.eye(4), support, VOXEL, margin)
    band = SUPPORT_BAND_VOXELS * VOXEL  # the plane's points stand for a table up to this much lower
    assert np.allclose(
        np.unique(tolerance), [ClearanceConfig().contact_tolerance, SUPPORT_CONTACT_TOLERANCE + margin + band]
    )

    def clear(
        depth: float, points=surface, tolerances=tolerance
    ) -> bool:  # fingertips ``depth`` under the top
        grasp = grasp_at((0.15, 0.15, TABLE_Z - depth + 0.009))
        args = ([grasp.position], [grasp.orientation])
        return bool(approach_is_clear(points, *args, point_tolerance=tolerances)[0])

    within = SUPPORT_CONTACT_TOLERANCE - 0.001  # the fingertips 1 mm short of the tolerance
    assert not clear(within, tolerances=None)  # the usual 5 mm: dropped
    assert clear(within)  # on the table within the last centimetre: kept
    assert not clear(SUPPORT_CONTACT_TOLERANCE + band + 0.002)  # deeper than the tolerance: dropped
    raised = surface + [0.0, 0.0, 0.02]  # the same points 2 cm up are an object's, not the table's
    assert not clear(within - 0.02, raised, contact_tolerances(raised, np.eye(4), support, VOXEL, margin))
    with pytest.raises(ValueError, match="contact tolerances"):
        clear(within, tolerances=tolerance[:-1])


def test_where_the_wider_hand_clears_nothing_the_narrower_one_answers():
    """A low slab (10 x 6 x 2.5 cm), the surface's pairs off: the network's grasps below its threshold
    all pass within the default margin of the slab's sides. Rather than nothing, the answer is what
    clears a hand grown by the fallback margin."""
    service = PlanningService.from_settings(
        Settings(model=PACKAGED_MODEL, api_key=None, surface_fallback=False)
    )
    try:
        session = fused_session(
            service, BoxScene(lower=(0.12, 0.12, TABLE_Z), upper=(0.22, 0.18, TABLE_Z + 0.025))
        )
        answer = service.plan(session, GraspQuery())
        with service.sessions.use(session) as state:
            surface = state.volume.surface_points()
        grid = service.grid(session)
    finally:
        service.close()
    assert answer.grasps and answer.fallback is True and answer.clearance_margin == FALLBACK_MARGIN

    def cleared(margin: float) -> list[Grasp]:
        config = ClearanceConfig(margin=margin)
        return check_grasps(answer.grasps, surface, grid, VOXEL, np.eye(4), SIZE, alternatives=False,
                            clearance=config).grasps  # fmt: skip

    assert cleared(ClearanceConfig().margin) == [] and cleared(FALLBACK_MARGIN) == answer.grasps
