"""Closed-loop planning: grasp track ids, sessions that forget, and the gRPC ``Track`` stream
against a real server on loopback."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import grpc
import httpx
import numpy as np
import pytest
from scipy.spatial import cKDTree

from client import BadRequest
from client.grpc_client import GRPCClient, frame_message
from client.http import VGNClient
from service.launch.embedded import EmbeddedService
from service.tsdf import SceneVolume
from tests.helpers.scenes import INTRINSICS, TABLE_Z, BoxScene, circle_views
from vgn_contract.grpc_api import grasp_planning_pb2 as pb
from vgn_contract.grpc_api.grasp_planning_pb2_grpc import GraspPlanningStub
from vgn_contract.schemas import Grasp
from vgn_contract.tracking import GraspTracker, grasp_angle

POSES = circle_views(6)
BOX = BoxScene()
MOVED = BoxScene(lower=(0.11, 0.02, TABLE_Z), upper=(0.19, 0.08, TABLE_Z + 0.06))  # 10 cm along -y
#: Clearance off: the random test weights' grasps are not meant to be collision-free.
QUERY = {"clearance": False, "grip": False, "threshold": 0.0, "max_grasps": 20}


def grasp(position, yaw_deg: float = 0.0, quality: float = 0.9) -> Grasp:
    half = np.deg2rad(yaw_deg) / 2
    # A top-down grasp (approach -z: a half turn about x), then turned about the approach.
    down = np.array([1.0, 0.0, 0.0, 0.0])
    turn = np.array([0.0, 0.0, np.sin(half), np.cos(half)])
    from scipy.spatial.transform import Rotation

    orientation = (Rotation.from_quat(down) * Rotation.from_quat(turn)).as_quat()
    return Grasp(
        position=list(position),
        orientation=list(orientation),
        approach=[0, 0, -1],
        width=0.04,
        quality=quality,
    )


# The tracker -----------------------------------------------------------------------------------
def test_a_grasp_that_moves_a_little_keeps_its_id_and_one_that_jumps_gets_a_new_one():
    tracker = GraspTracker()
    first = tracker.update([grasp([0.1, 0.1, 0.1]), grasp([0.2, 0.1, 0.1])])
    assert [g.track_id for g in first] == [1, 2]
    second = tracker.update([grasp([0.205, 0.1, 0.1], yaw_deg=5), grasp([0.1, 0.16, 0.1])])
    assert [g.track_id for g in second] == [2, 3]  # ranks swapped; the far one is new
    third = tracker.update([grasp([0.1, 0.16, 0.1], yaw_deg=30)])  # turned too far
    assert [g.track_id for g in third] == [4]


def test_a_half_turn_about_the_approach_is_the_same_grasp():
    a, b = grasp([0, 0, 0]), grasp([0, 0, 0], yaw_deg=180)
    assert grasp_angle(np.asarray(a.orientation), np.asarray(b.orientation)) == pytest.approx(0.0, abs=1e-9)
    tracker = GraspTracker()
    tracker.update([a])
    assert tracker.update([b])[0].track_id == 1


def test_two_new_grasps_never_share_an_id():
    tracker = GraspTracker()
    tracker.update([grasp([0.1, 0.1, 0.1])])
    ids = [g.track_id for g in tracker.update([grasp([0.104, 0.1, 0.1]), grasp([0.102, 0.1, 0.1])])]
    assert sorted(ids) == [1, 2] and ids[1] == 1  # the closer one keeps the track


def test_tracker_limits_are_checked():
    with pytest.raises(ValueError):
        GraspTracker(max_distance=0.0)
    with pytest.raises(ValueError):
        GraspTracker(max_angle_deg=200)


# Forgetting --------------------------------------------------------------------------------
def fuse(volume: SceneVolume, scene: BoxScene, views: list[np.ndarray]) -> None:
    for pose in views:
        volume.integrate(scene.depth(pose), INTRINSICS, pose, 2.0)


def test_what_a_frame_does_not_see_is_not_forgotten():
    """Forgetting weighs only what a frame sees again: a view from one side leaves the voxels
    only the other side saw as they were."""
    volume = SceneVolume(0.3, 40, np.eye(4), 40, decay=0.3)
    fuse(volume, BOX, POSES)
    before = volume.grid()
    fuse(volume, BOX, [POSES[0]] * 10)
    after = volume.grid()
    unseen = SceneVolume(0.3, 40, np.eye(4), 40)
    fuse(unseen, BOX, [POSES[0]])
    weights = np.asarray(unseen.coarse._volume.extract_volume_tsdf())[:, 1].reshape(before.shape)
    hidden = weights == 0  # voxels the first view does not update
    assert 0.1 < hidden.mean() < 0.9
    assert np.array_equal(before[hidden], after[hidden])
    for v in (volume, unseen):
        v.close()


def difference(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """(share of voxels observed in one grid only, 99th percentile of the value gap where both
    observe). A forgetting volume weighs recent views more than a fresh one does, so projective
    TSDF values seen from several sides differ a little even for the same scene."""
    both = (a > 0) & (b > 0)
    return float(np.mean((a > 0) != (b > 0))), float(np.percentile(np.abs(a[both] - b[both]), 99))


def stray_share(points: np.ndarray, reference: np.ndarray) -> float:
    """The share of ``points`` farther than 1 cm from every point of ``reference``."""
    assert len(points) and len(reference)
    distances, _ = cKDTree(reference).query(points)
    return float(np.mean(distances > 0.01))


@pytest.mark.parametrize("decay", [None, 0.5, 0.7])
def test_a_forgetting_volume_follows_a_moved_box_and_a_static_one_does_not(decay):
    """After the box moved 10 cm, a forgetting volume is (nearly) the fresh volume of the new
    scene; a static one keeps averaging the old box in."""
    volume = SceneVolume(0.3, 40, np.eye(4), 40, decay=decay)
    fresh = SceneVolume(0.3, 40, np.eye(4), 40)
    fuse(volume, BOX, POSES * 2)
    fuse(volume, MOVED, POSES * 3)
    fuse(fresh, MOVED, POSES)
    only_one, gap = difference(volume.grid(), fresh.grid())
    if decay is None:
        assert only_one > 0.015 and gap > 0.3
    else:  # measured: 0.5 -> (0.0047, 0.13), 0.7 -> (0.0032, 0.10); static (0.021, 0.48)
        assert only_one < 0.008 and gap < 0.2
    # The cloud volume forgets too, in upload order: its points lie on the new scene's.
    stray = stray_share(volume.cloud()[:, :3], fresh.cloud()[:, :3])
    assert stray > 0.1 if decay is None else stray < 0.08
    volume.close()
    fresh.close()


# Over the service ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def service(random_checkpoint: Path) -> Iterator[EmbeddedService]:
    env = {"VGN_API_KEY": "", "VGN_TORCH_THREADS": "1"}
    with EmbeddedService(model=random_checkpoint, env=env, grpc=True) as running:
        yield running


def test_a_session_with_decay_reports_it_and_a_bad_decay_is_a_clear_error(service):
    with VGNClient(service.url) as http, GRPCClient(service.grpc_url) as rpc:
        assert http.create_session(decay=0.7).decay == 0.7
        assert rpc.create_session(decay=0.5).decay == 0.5
        assert http.create_session().decay is None
        with pytest.raises(ValueError, match="decay"):  # checked before it is sent
            http.create_session(decay=1.5)
        with pytest.raises(BadRequest, match="decay"):  # checked by the service
            rpc.create_session(decay=1.5)
    answer = httpx.post(f"{service.url}/sessions", json={"decay": 1.0})
    assert answer.status_code == 422 and "decay" in answer.text
    with grpc.insecure_channel(service.grpc_url.removeprefix("grpc://")) as channel:
        with pytest.raises(grpc.RpcError) as raised:
            GraspPlanningStub(channel).CreateSession(pb.CreateSessionRequest(decay=0.0), timeout=30)
        assert raised.value.code() == grpc.StatusCode.INVALID_ARGUMENT and "decay" in raised.value.details()


def test_track_sends_the_grasps_of_get_grasps_with_stable_ids(service):
    with VGNClient(service.url) as http, GRPCClient(service.grpc_url) as rpc:
        tracked = rpc.create_session(intrinsics=INTRINSICS).session_id
        plain = http.create_session(intrinsics=INTRINSICS).session_id
        frames = [(BOX.depth(pose), pose) for pose in POSES]
        updates = list(rpc.track(tracked, frames, plan_every=2, **QUERY))
        assert [u.frame_count for u in updates] == [2, 4, 6]
        for depth, pose in frames:
            http.add_frame(plain, depth, pose)
        reference = http.grasps(plain, **QUERY)
        last = updates[-1]
        assert last.grasps and all(g.track_id for g in last.grasps)
        assert [g.position for g in last.grasps] == [g.position for g in reference.grasps]
        assert all(g.track_id is None for g in reference.grasps)  # GET /grasps has no tracks
        # The same static scene planned again: the grasps that stay keep their ids.
        again = list(rpc.track(tracked, frames[:1], **QUERY))
        assert {g.track_id for g in again[0].grasps} == set(range(1, len(again[0].grasps) + 1))


def test_track_ids_persist_between_plans_of_one_stream(service):
    with GRPCClient(service.grpc_url) as rpc:
        session = rpc.create_session(intrinsics=INTRINSICS).session_id
        frames = [(BOX.depth(pose), pose) for pose in POSES * 2]
        updates = list(rpc.track(session, frames, plan_every=6, **QUERY))
        first, second = ({(tuple(g.position), g.track_id) for g in u.grasps} for u in updates)
        ids = {position: track for position, track in first}
        kept = [track == ids[position] for position, track in second if position in ids]
        assert kept and all(kept)


def test_a_bad_frame_ends_the_track_stream_naming_it(service):
    with (
        grpc.insecure_channel(service.grpc_url.removeprefix("grpc://")) as channel,
        GRPCClient(service.grpc_url) as rpc,
    ):
        stub = GraspPlanningStub(channel)
        session = rpc.create_session(intrinsics=INTRINSICS).session_id
        good = frame_message(session, BOX.depth(POSES[0]), POSES[0], None, 1000.0, 2.0)
        bad = pb.Frame(session_id=session, depth=b"\0" * 10, encoding=pb.DEPTH_ENCODING_RAW_FLOAT32,
                       camera_pose=good.camera_pose)  # fmt: skip
        query = pb.GraspQuery(clearance=False, grip=False)
        requests = [pb.TrackRequest(frame=good, query=query), pb.TrackRequest(frame=bad)]
        answers = stub.Track(iter(requests), timeout=30)
        first = next(answers)
        assert first.frames_received == 1 and first.cycle_ms > 0
        with pytest.raises(grpc.RpcError) as raised:
            next(answers)
        assert raised.value.code() == grpc.StatusCode.INVALID_ARGUMENT
        assert "frame 1" in raised.value.details()
        assert rpc.session(session).frame_count == 1  # the good frame stays fused


def test_track_options_are_checked(service):
    with grpc.insecure_channel(service.grpc_url.removeprefix("grpc://")) as channel:
        stub = GraspPlanningStub(channel)
        for options in ({"plan_every": 0}, {"match_angle": 0.0}, {"match_distance": -1.0}):
            with pytest.raises(grpc.RpcError) as raised:
                list(
                    stub.Track(iter([pb.TrackRequest(frame=pb.Frame(session_id="x"), **options)]), timeout=30)
                )
            assert raised.value.code() == grpc.StatusCode.INVALID_ARGUMENT


def test_a_forgetting_session_keeps_its_decay_through_a_snapshot(service):
    with VGNClient(service.url) as http:
        session = http.create_session(intrinsics=INTRINSICS, decay=0.6).session_id
        http.add_frame(session, BOX.depth(POSES[0]), POSES[0])
        copy = http.import_session(http.snapshot(session), session_id=f"{session}-copy")
        assert copy.decay == 0.6 and copy.frame_count == 1
