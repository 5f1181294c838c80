"""Closing the loop in the simulator: disturbances, the closed loop's watch over an approach,
and the wrist camera's scan, against a real PyBullet world and (for the watch and the scan) a
real service with the shipped model on loopback."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from client.http import VGNClient
from service.launch.embedded import EmbeddedService
from sim_worker.camera import SIM_INTRINSICS, WORKSPACE_CENTRE, Camera, six_views
from sim_worker.closed_loop import (
    STABLE_PLANS,
    WRIST_FRAMES,
    WRIST_SWEEP_DEG,
    ApproachWatch,
    wrist_arc,
    wrist_scan,
)
from sim_worker.disturbance import Disturber, PlannedDisturbance, nearest_object
from sim_worker.grasping import translated
from sim_worker.gripper import Gripper
from sim_worker.objects import object_set
from sim_worker.scenes import generate_scene
from sim_worker.world import World
from tests.helpers.runs import check_results, clear_scene, read_csv
from vgn_contract.tracking import GraspTracker


@pytest.fixture
def pile() -> Iterator[World]:
    """A pile of five blocks, the same every time."""
    with World(renderer="tiny") as world:
        generate_scene(world, "pile", object_set("", "pile"), 5, np.random.default_rng(3))
        yield world


# Disturbances ------------------------------------------------------------------------------------
def test_a_push_moves_the_aimed_at_object_a_few_centimetres_and_buries_nothing(pile: World):
    body = next(iter(pile.objects))
    target = pile.object_pose(body)[0]
    before = {b: pile.object_pose(b)[0] for b in pile.objects}
    planned = PlannedDisturbance(step_share=0.2, kind="push", distance=0.04, angle=0.3, yaw=0.2)
    done = Disturber(1.0, np.random.default_rng(0)).apply(pile, planned, target)
    assert done is not None and done.body == body == nearest_object(pile, target)
    moved = np.linalg.norm(pile.object_pose(body)[0] - before[body])
    if done.kind == "push":
        assert 0.035 < moved < 0.045
        pile.p.performCollisionDetection()
        assert all(c[8] > -0.0021 for c in pile.p.getContactPoints(bodyA=body))
    else:  # every direction was blocked: lifted instead
        assert pile.object_pose(body)[0][2] > before[body][2] + 0.04
    assert all(np.allclose(pile.object_pose(b)[0], p) for b, p in before.items() if b != body)


def test_a_drop_lifts_the_object_and_lets_it_fall_back(pile: World):
    body = next(iter(pile.objects))
    start = pile.object_pose(body)[0]
    planned = PlannedDisturbance(step_share=0.2, kind="drop", distance=0.08, angle=0.0, yaw=0.0)
    done = Disturber(1.0, np.random.default_rng(0)).apply(pile, planned, start)
    assert done.kind == "drop" and done.moved == pytest.approx(0.08)
    pile.wait_for_rest()
    assert pile.object_pose(body)[0][2] < start[2] + 0.04


def test_disturbances_are_drawn_with_their_probability_from_their_own_stream():
    first = Disturber(0.5, np.random.default_rng(1)).draw()
    many = Disturber(0.5, np.random.default_rng(1))
    happened = [many.draw() is not None for _ in range(400)]
    assert 0.42 < np.mean(happened) < 0.58
    again = Disturber(0.5, np.random.default_rng(1))
    assert again.draw() == first
    never = Disturber(0.0, np.random.default_rng(1))
    assert all(never.draw() is None for _ in range(50))
    planned = Disturber(1.0, np.random.default_rng(2)).draw()
    assert planned.kind in ("push", "drop") and 1 <= planned.step(25) <= 13
    with pytest.raises(ValueError, match="probability"):
        Disturber(1.5, np.random.default_rng(0))


# With the shipped model ------------------------------------------------------------------------
@pytest.fixture(scope="module")
def shipped() -> Iterator[VGNClient]:
    env = {"VGN_API_KEY": "", "VGN_TORCH_THREADS": "1"}
    with EmbeddedService(env=env) as service, VGNClient(service.url) as client:
        yield client


def observe(vgn: VGNClient, camera: Camera, session_id: str) -> None:
    for pose in six_views():
        vgn.add_frame(session_id, camera.render_depth(pose), pose)


@pytest.mark.parametrize("count, seed", [(1, 0), (2, 1), (5, 3)])
def test_the_watch_ignores_the_hand_and_sees_the_object_go(shipped: VGNClient, count: int, seed: int):
    with World(renderer="tiny") as world:
        generate_scene(world, "pile", object_set("", "pile"), count, np.random.default_rng(seed))
        camera, hand, views = Camera(world), Gripper(world), six_views()
        session = shipped.create_session(intrinsics=SIM_INTRINSICS).session_id
        observe(shipped, camera, session)
        chosen = shipped.grasps(session).grasps[0]
        reference = [camera.render_depth(pose) for pose in views]
        watch = ApproachWatch(camera, views, reference, hand.body, np.asarray(chosen.position))
        for back in (0.05, 0.03, 0.0):  # the hand moving in, in every view: no change
            hand.reset(translated(chosen.as_matrix(), [0.0, 0.0, -back]))
            assert not watch(5, 25)
        assert watch.changed == 0.0
        assert not watch(6, 25) and watch.looks == 3  # not a look step
        body = nearest_object(world, np.asarray(chosen.position))
        position, orientation = world.object_pose(body)
        world.p.resetBasePositionAndOrientation(
            body, (position + [0.05, 0.0, 0.0]).tolist(), orientation.tolist()
        )
        assert watch(10, 25) and watch.changed > 0.15


@pytest.fixture(scope="module")
def settling() -> Iterator[VGNClient]:
    """The service without the antipodal check, whose plans on this pile settle within the arc: with
    it, the surface's pairs answer the first frames and re-rank as the cloud grows (docs/closed-loop.md)."""
    env = {"VGN_API_KEY": "", "VGN_TORCH_THREADS": "1", "VGN_ANTIPODAL_CHECK": "false"}
    with EmbeddedService(env=env) as service, VGNClient(service.url) as client:
        yield client


def test_the_wrist_scan_stops_once_the_best_grasp_is_stable(settling: VGNClient, pile: World):
    shipped = settling
    camera = Camera(pile)
    session = shipped.create_session(intrinsics=SIM_INTRINSICS).session_id
    arc = wrist_arc(azimuth=0.4, frames=6)  # a longer arc than the default, to leave room to stop
    result = wrist_scan(shipped, session, camera, arc, {})
    assert result.answer.grasps and 2 <= result.frames < len(arc)
    assert shipped.session(session).frame_count == result.frames
    # Plan after each frame by hand: the scan stopped at the first plan whose best grasp kept its id
    # over the last STABLE_PLANS plans, not later.
    replay, tracker, best = shipped.create_session(intrinsics=SIM_INTRINSICS).session_id, GraspTracker(), []
    for pose in arc:
        shipped.add_frame(replay, camera.render_depth(pose), pose)
        tracked = tracker.update(shipped.grasps(replay).grasps)
        best.append(tracked[0].track_id if tracked else None)
        recent = best[-STABLE_PLANS:]
        if len(recent) == STABLE_PLANS and recent[0] is not None and len(set(recent)) == 1:
            break
    assert len(best) == result.frames


def test_the_wrist_arc_circles_the_scene_moving_in_and_looks_at_the_workspace():
    arc = wrist_arc(azimuth=1.0)
    centre = np.asarray(WORKSPACE_CENTRE)
    offsets = [pose[:3, 3] - centre for pose in arc]
    distances = [np.linalg.norm(offset) for offset in offsets]
    assert len(arc) == WRIST_FRAMES and np.all(np.diff(distances) < 0)
    azimuths = np.degrees([np.arctan2(offset[1], offset[0]) for offset in offsets])
    assert np.allclose(np.diff(np.unwrap(azimuths, period=360)), WRIST_SWEEP_DEG / (WRIST_FRAMES - 1))
    for pose in arc:  # the optical axis passes near the workspace centre
        to_centre = centre - pose[:3, 3]
        assert np.degrees(np.arccos(np.clip(pose[:3, 2] @ to_centre / np.linalg.norm(to_centre), -1, 1))) < 8


def test_a_disturbed_closed_loop_run_with_a_wrist_scan_records_what_happened(tmp_path: Path):
    results = tmp_path / "closed"
    run = clear_scene("--rounds", "1", "--object-count", "3", "--disturb", "1", "--closed-loop",
                      "--scan", "wrist", "--results", str(results))  # fmt: skip
    assert run.returncode == 0, run.stderr
    check_results(results, 1)
    rows = read_csv(results / "grasps.csv")
    assert rows and all(row["disturbance"] in ("push", "drop") for row in rows)
    assert all(row["loop"] in ("kept", "stopped", "retried") and int(row["looks"]) >= 1 for row in rows)
    assert all(2 <= int(row["frames"]) <= WRIST_FRAMES for row in rows)
    config = (results / "config.json").read_text()
    assert '"disturb": 1' in config and '"closed_loop": true' in config and '"scan": "wrist"' in config
