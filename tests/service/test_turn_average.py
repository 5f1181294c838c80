"""Turn averaging: VGN's quality averaged over the grid's four quarter turns about gravity,
mapped back with the training augmentation's rule, run as one batch, and kept apart from
plain outputs when a session's output is reused."""

from __future__ import annotations

import math
import threading

import httpx
import numpy as np
import pytest
import torch

from client.grpc_client import GRPCClient
from service.core import PlanningService
from service.grpc.server import build_server
from service.planner import GraspPlanner, InferenceOptions
from service.settings import PACKAGED_MODEL, Settings
from service.vgn.batching import MicroBatcher
from service.vgn.detection import grasp_region
from service.vgn.turns import (
    TURNS,
    _turned_view,
    average_turned_quality,
    average_turned_rotation,
    turned_grids,
    turned_index,
)
from tests.helpers.grids import recorded_grids
from tests.helpers.scenes import INTRINSICS, BoxScene, circle_views
from training.augment import rotate_z
from training.labels import LabelSet
from training.quaternions import about_z, flipped, multiply
from vgn_contract.schemas import GraspQuery, GraspResult, SessionCreate

N = 8


@pytest.mark.parametrize("quarter_turns", [1, 2, 3])
def test_outputs_move_as_the_training_augmentation_moves_labels(quarter_turns: int):
    """The network learnt with labels turned by ``rotate_z``; reading its outputs back must use
    the same rule, or every averaged score would mix neighbouring voxels."""
    i, j, z = np.meshgrid(np.arange(N), np.arange(N), [3], indexing="ij")
    voxel = torch.from_numpy(np.stack([i.ravel(), j.ravel(), z.ravel()], axis=1))
    quaternion = torch.tensor([[0.0, 0.0, 0.0, 1.0]]).expand(len(voxel), 4)
    labels = LabelSet(voxel, quaternion, torch.ones(len(voxel)), torch.ones(len(voxel)))
    _, turned = rotate_z(torch.zeros((N, N, N)), labels, quarter_turns)
    to_i, to_j = turned_index(N, quarter_turns)
    on_grid = (to_i >= 0) & (to_i < N) & (to_j >= 0) & (to_j < N)
    expected = sorted(zip(to_i[on_grid].tolist(), to_j[on_grid].tolist(), strict=True))
    assert sorted(map(tuple, turned.voxel[:, :2].tolist())) == expected
    kept = N * (N - 1) if quarter_turns % 2 else (N - 1) ** 2
    assert on_grid.sum() == kept, "a turn takes the positions of one row (a half turn: and one column) off"


def test_a_network_that_turns_with_the_scene_keeps_its_scores():
    """Qualities that follow the turn exactly average back to the unturned ones, and positions a
    turn takes off the grid never borrow a score."""
    rng = np.random.default_rng(0)
    quality = rng.random((N, N, N)).astype(np.float32)
    turned = np.full((len(TURNS), N, N, N), 7.0, dtype=np.float32)  # 7: a score no turn may read
    for k in TURNS:
        to_i, to_j = turned_index(N, k)
        on_grid = (to_i >= 0) & (to_i < N) & (to_j >= 0) & (to_j < N)
        turned[k][to_i[on_grid], to_j[on_grid]] = quality[on_grid]
    np.testing.assert_allclose(average_turned_quality(turned), quality, rtol=1e-6)


def test_the_grids_are_turned_about_z():
    grid = np.zeros((N, N, N), dtype=np.float32)
    grid[1, 0, 5] = 1.0  # a cell on the +x side, at height 5
    turned = turned_grids(grid)
    cells = [tuple(np.argwhere(g)[0]) for g in turned]
    assert cells == [(1, 0, 5), (N - 1, 1, 5), (N - 2, N - 1, 5), (0, N - 2, 5)]


def test_a_request_queues_its_grids_together_and_gets_them_back_in_order():
    sizes = []

    def forward(grids: np.ndarray) -> list[float]:
        sizes.append(len(grids))
        return [float(g.sum()) for g in grids]

    batcher = MicroBatcher(forward)
    grids = [np.full((2, 2, 2), value, np.float32) for value in (1, 2, 3, 4)]
    assert batcher.run_many(grids) == [8.0, 16.0, 24.0, 32.0]
    assert sizes == [4], "the four grids of one request share one forward pass"

    results: list[list[float]] = []
    threads = [threading.Thread(target=lambda: results.append(batcher.run_many(grids))) for _ in range(3)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert results == [[8.0, 16.0, 24.0, 32.0]] * 3


def test_the_planner_averages_the_shipped_models_outputs_over_the_turns():
    planner = GraspPlanner.from_path(PACKAGED_MODEL, "cpu", InferenceOptions(precision="fp32", lanes=1))
    _, grid = recorded_grids()[0]
    plain = planner.infer(grid)
    averaged = planner.infer(grid, turn_average=True)
    one_by_one = [planner.infer(np.ascontiguousarray(g)) for g in turned_grids(grid)]
    qualities = np.stack([output.quality for output in one_by_one])
    rotations = np.stack([output.rotation for output in one_by_one])
    np.testing.assert_allclose(averaged.quality, average_turned_quality(qualities), atol=1e-5)
    np.testing.assert_allclose(averaged.rotation_where(), average_turned_rotation(rotations), atol=1e-4)
    # Orientations are averaged where asked only; elsewhere nothing is computed (zero).
    region = grasp_region(grid)
    assert region.any() and not region.all()
    some = averaged.rotation_where(region)
    np.testing.assert_allclose(some[:, region], average_turned_rotation(rotations)[:, region], atol=1e-4)
    assert not some[:, ~region].any()
    # A few hundred voxels, as detection asks for: the turned grids' orientations are then
    # computed at those voxels alone, with the same result.
    few = np.zeros_like(region)
    few[tuple(np.argwhere(region)[::40].T)] = True
    assert 0 < few.sum() < 1000
    np.testing.assert_allclose(
        averaged.rotation_where(few)[:, few], average_turned_rotation(rotations)[:, few], atol=1e-4
    )
    np.testing.assert_allclose(plain.rotation_where(region)[:, region], plain.rotation[:, region], atol=1e-6)
    # Widths are the unturned grid's (from a batch of four: float32 rounding apart).
    np.testing.assert_allclose(averaged.width, plain.width, atol=1e-4)
    assert not np.allclose(averaged.quality, plain.quality, atol=1e-3), "the turns disagree somewhere"
    assert planner.runtime()["batches"]["largest"] == len(TURNS)


def test_a_kept_output_serves_only_requests_with_the_same_averaging(core: PlanningService):
    session = core.create_session(SessionCreate(intrinsics=INTRINSICS)).session_id
    scene = BoxScene()
    for pose in circle_views(3):
        core.add_frame(session, scene.depth(pose), pose)
    # Without the clearance and grip checks: they drop every grasp of the random weights on this scene.
    plain, averaged = (
        GraspQuery(threshold=0.0, turn_average=False, clearance=False, grip=False),
        GraspQuery(threshold=0.0, turn_average=True, clearance=False, grip=False),
    )
    first_plain = core.plan(session, plain).grasps
    first_averaged = core.plan(session, averaged).grasps
    assert first_averaged != first_plain
    assert core.plan(session, plain).grasps == first_plain
    assert core.plan(session, averaged).grasps == first_averaged
    default = GraspQuery(threshold=0.0, clearance=False, grip=False)
    assert core.plan(session, default).grasps == first_averaged, "the default is on"


def test_the_operator_chooses_the_default_and_requests_may_override_it(random_checkpoint):
    settings = Settings(
        model=random_checkpoint, api_key=None, turn_average=False, clearance=False, grip=False
    )
    core = PlanningService.from_settings(settings)
    try:
        session = core.create_session(SessionCreate(intrinsics=INTRINSICS)).session_id
        scene = BoxScene()
        for pose in circle_views(3):
            core.add_frame(session, scene.depth(pose), pose)
        default = core.plan(session, GraspQuery(threshold=0.0))
        plain = core.plan(session, GraspQuery(threshold=0.0, turn_average=False))
        averaged = core.plan(session, GraspQuery(threshold=0.0, turn_average=True))
        assert default.grasps == plain.grasps != averaged.grasps
        assert (default.turn_average, averaged.turn_average) == (False, True)
        assert core.plan(session, GraspQuery(planner="antipodal")).turn_average is None
        assert core.model_info().defaults.turn_average is False
    finally:
        core.close()


def test_the_option_over_http_grpc_and_the_cli(vgn, core: PlanningService, capsys):
    """A real server takes ``turn_average`` as a query switch (a bad value is a 422 naming it),
    the gRPC front end gives the same grasps as the core, and ``vgn-client grasps`` passes it on."""
    from client.cli import main

    session = vgn.create_session(intrinsics=INTRINSICS).session_id
    scene = BoxScene()
    for pose in circle_views(3):
        vgn.add_frame(session, scene.depth(pose), pose)
    # Without the clearance and grip checks: they drop every grasp of the random weights on this scene.
    plain = vgn.grasps(session, threshold=0.0, turn_average=False, clearance=False, grip=False)
    averaged = vgn.grasps(session, threshold=0.0, turn_average=True, clearance=False, grip=False)
    assert averaged.grasps and averaged.grasps != plain.grasps
    assert (plain.turn_average, averaged.turn_average) == (False, True)
    default = vgn.grasps(session, threshold=0.0, clearance=False, grip=False)
    assert default.grasps == averaged.grasps and default.turn_average is True, "on unless the operator says"
    assert vgn.model().defaults.turn_average is True
    bad = httpx.get(f"{vgn.url}/sessions/{session}/grasps", params={"turn_average": "maybe"})
    assert bad.status_code == 422 and "turn_average" in bad.json()["message"]

    for option, expected in (("--turn-average", averaged), ("--no-turn-average", plain)):
        argv = [
            "grasps",
            session,
            "--url",
            vgn.url,
            "--threshold",
            "0",
            option,
            "--no-clearance",
            "--no-grip",
            "--json",
        ]
        assert main(argv) == 0
        assert GraspResult.model_validate_json(capsys.readouterr().out).grasps == expected.grasps[:10]

    local = core.create_session(SessionCreate(intrinsics=INTRINSICS)).session_id
    for pose in circle_views(3):
        core.add_frame(local, scene.depth(pose), pose)
    server, port = build_server(core, "127.0.0.1", 0)
    try:
        with GRPCClient(f"grpc://127.0.0.1:{port}") as rpc:
            for turn_average in (False, True, None):
                options = {"threshold": 0.0, "turn_average": turn_average, "clearance": False, "grip": False}
                expected = core.plan(local, GraspQuery(**options))
                answer = rpc.grasps(local, **options)
                assert answer.grasps == expected.grasps
                assert answer.turn_average is (turn_average is not False)
    finally:
        server.stop(None)


def test_average_precision_of_the_label_benchmark():
    from benchmarks.turn_average import average_precision

    assert average_precision(np.array([1, 1, 0, 0]), np.array([0.9, 0.8, 0.2, 0.1])) == 1.0
    # Positives ranked 1st and 3rd: precisions 1 and 2/3.
    assert average_precision(np.array([1, 0, 1, 0]), np.array([0.9, 0.8, 0.7, 0.1])) == pytest.approx(5 / 6)


def _random_rotations(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=(4, N, N, N)).astype(np.float32)
    return q / np.linalg.norm(q, axis=0)


def test_orientations_that_turn_with_the_scene_average_back_to_the_unturned_ones():
    """A network that turns its grasps with the scene, in any of a grasp's four equivalent forms
    (q, -q, q turned by π about the approach, and its negative), averages back exactly to the
    unturned orientation; the turn back uses the training's quaternion algebra."""
    rng = np.random.default_rng(1)
    reference = _random_rotations(rng)
    turned = np.stack([reference] + [_random_rotations(rng) for _ in TURNS[1:]])  # off-grid: noise
    as_rows = torch.from_numpy(np.moveaxis(reference, 0, -1))
    for k in TURNS[1:]:
        rotated = multiply(about_z(k * math.pi / 2).expand_as(as_rows), as_rows)
        form = rng.integers(0, 4, size=(N, N, N))
        rotated = torch.where(torch.from_numpy(form % 2 == 1)[..., None], flipped(rotated), rotated)
        rotated = torch.where(torch.from_numpy(form >= 2)[..., None], -rotated, rotated)
        to_i, to_j = turned_index(N, k)
        on_grid = (to_i >= 0) & (to_i < N) & (to_j >= 0) & (to_j < N)
        for axis in range(4):
            turned[k, axis][to_i[on_grid], to_j[on_grid]] = rotated[..., axis].numpy()[on_grid]
    np.testing.assert_allclose(average_turned_rotation(turned), reference, atol=1e-5)


def _read_back(field: np.ndarray, quarter_turns: int) -> tuple[np.ndarray, np.ndarray]:
    """A turned output read at each unturned grasp position, zero off the grid, and the (N, N)
    mask of the positions the turn keeps: what the averages add up, through ``_turned_view``."""
    region, view = _turned_view(field, quarter_turns)
    values = np.zeros_like(field)
    on_grid = np.zeros(field.shape[:2], dtype=bool)
    values[region], on_grid[region] = view, True
    return values, on_grid


@pytest.mark.parametrize("quarter_turns", [0, 1, 2, 3, 5])
def test_reading_back_a_turned_output_follows_the_turned_index(quarter_turns: int):
    field = np.random.default_rng(quarter_turns).random((N, N, 3)).astype(np.float32)
    to_i, to_j = turned_index(N, quarter_turns)
    on_grid = (to_i >= 0) & (to_i < N) & (to_j >= 0) & (to_j < N)
    expected = np.zeros_like(field)
    expected[on_grid] = field[to_i[on_grid], to_j[on_grid]]
    values, mask = _read_back(field, quarter_turns)
    np.testing.assert_array_equal(values, expected)
    np.testing.assert_array_equal(mask, on_grid)


def test_averaging_some_voxels_gives_the_full_fields_answer_there():
    rng = np.random.default_rng(4)
    turned = np.stack([_random_rotations(rng) for _ in TURNS])
    where = rng.random((N, N, N)) < 0.2
    where[0, :, 0] = where[N - 1, N - 1, :] = True  # voxels that some turns take off the grid
    full = average_turned_rotation(turned)
    some = average_turned_rotation(turned, where=where)
    np.testing.assert_allclose(some[:, where], full[:, where], atol=1e-6)
    np.testing.assert_array_equal(some[:, ~where], turned[0][:, ~where])
    np.testing.assert_array_equal(average_turned_rotation(turned, where=np.zeros_like(where)), turned[0])


def test_the_averaged_orientation_lies_between_disagreeing_turns():
    """Two turns 20° apart about x on either side of the unturned one: the mean is the unturned."""
    reference = np.zeros((4, N, N, N), np.float32)
    reference[3] = 1.0
    tilt = math.radians(20.0)
    tilted = [np.zeros_like(reference) for _ in range(2)]
    for sign, field in zip((1, -1), tilted, strict=True):
        field[0], field[3] = sign * math.sin(tilt / 2), math.cos(tilt / 2)
    # A tilt about x, seen after a quarter turn about z, is a tilt about y (and so on); with
    # these two tilts opposite and the half turn agreeing, the mean is the identity.
    first = multiply(about_z(math.pi / 2), torch.from_numpy(np.moveaxis(tilted[0], 0, -1)))
    third = multiply(about_z(3 * math.pi / 2), torch.from_numpy(np.moveaxis(tilted[1], 0, -1)))
    half = multiply(about_z(math.pi), torch.from_numpy(np.moveaxis(reference, 0, -1)))
    turned = np.stack([reference] + [np.moveaxis(t.numpy(), -1, 0) for t in (first, half, third)])
    averaged = average_turned_rotation(turned)
    inside = (slice(None), slice(1, N - 1), slice(1, N - 1))  # every turn keeps these voxels
    np.testing.assert_allclose(np.abs(averaged[inside][3]), 1.0, atol=1e-6)
