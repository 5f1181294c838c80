"""Micro-batching: concurrent grasp requests share one forward pass and get the answers
they would have got alone. This is the path a GPU takes (``VGN_DEVICE=cuda``); only the
device differs, so it is tested here on the CPU."""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

import httpx
import numpy as np
import pytest
import torch

from client.connect import connect
from client.http import VGNClient
from service.launch.embedded import EmbeddedService
from service.planner import GraspPlanner, InferenceOptions, resolve_heads
from service.settings import PACKAGED_MODEL
from service.vgn.batching import MicroBatcher
from service.vgn.outputs import ComputedHeads, HeadsOnDemand
from tests.helpers.grids import recorded_grids
from tests.helpers.scenes import INTRINSICS, BoxScene, circle_views

SESSIONS = 6


def test_concurrent_grids_run_as_one_batch_with_the_unbatched_results():
    options = InferenceOptions(precision="fp32", batch_window_ms=200.0)
    planner = GraspPlanner.from_path(PACKAGED_MODEL, "cpu", options)
    grids = [grid for _, grid in recorded_grids()]
    alone = [planner.infer(grid) for grid in grids]
    before = planner.runtime()["batches"]
    start = threading.Barrier(len(grids))

    def ask(grid: np.ndarray):
        start.wait()
        return planner.infer(grid)

    with ThreadPoolExecutor(len(grids)) as pool:
        together = list(pool.map(ask, grids))
    after = planner.runtime()["batches"]
    assert after["batches"] - before["batches"] < len(grids), "concurrent requests shared forward passes"
    assert after["largest"] > 1
    for single, batched in zip(alone, together, strict=True):
        for name in ("quality", "rotation", "width"):
            np.testing.assert_allclose(getattr(batched, name), getattr(single, name), atol=1e-5, rtol=1e-5)


@pytest.mark.parametrize("lanes", [2, 3])
def test_a_batch_split_into_lanes_gives_each_grid_its_own_result(lanes: int):
    """Parts of a batch run side by side on a CPU; every grid still gets what it gets alone."""
    grids = [grid for _, grid in recorded_grids()]
    options = InferenceOptions(precision="fp32", lanes=lanes)
    planner = GraspPlanner.from_path(PACKAGED_MODEL, "cpu", options)
    assert planner.runtime()["lanes"] == lanes
    split = planner._forward_batch(np.stack(grids))
    alone = [planner.infer(grid) for grid in grids]
    assert len(split) == len(grids) > lanes
    for single, batched in zip(alone, split, strict=True):
        for name in ("quality", "rotation", "width"):
            np.testing.assert_allclose(getattr(batched, name), getattr(single, name), atol=1e-5, rtol=1e-5)


def test_rotation_and_width_on_demand_equal_the_whole_heads():
    """The fast network computes rotation and width where they are read: a few voxels at a
    time (from the decoder's features), or whole past a few thousand; both equal the
    reference network's heads."""
    grids = [grid for _, grid in recorded_grids()]
    fast = GraspPlanner.from_path(PACKAGED_MODEL, "cpu", InferenceOptions(precision="fp32", lanes=2))
    reference = GraspPlanner.from_path(PACKAGED_MODEL, "cpu", InferenceOptions(form="reference"))
    voxels = tuple(np.random.default_rng(1).integers(0, grids[0].shape[0], size=(3, 200)))
    everywhere = tuple(index.ravel() for index in np.indices(grids[0].shape))
    for lazy, whole in zip(fast._forward_batch(np.stack(grids)), map(reference.infer, grids), strict=True):
        assert isinstance(lazy.heads, HeadsOnDemand) and isinstance(whole.heads, ComputedHeads)
        np.testing.assert_allclose(lazy.quality, whole.quality, atol=1e-4)
        np.testing.assert_allclose(
            lazy.heads.rotation_at(*voxels), whole.rotation[(slice(None), *voxels)], atol=1e-4
        )
        np.testing.assert_allclose(lazy.width_at(*voxels), whole.width[voxels], atol=1e-3, rtol=1e-4)
        assert lazy.heads._whole is None, "a few voxels do not run the whole heads"
        np.testing.assert_allclose(
            lazy.heads.rotation_at(*everywhere), whole.rotation.reshape(4, -1), atol=1e-4
        )
        assert lazy.heads._whole is not None
        np.testing.assert_allclose(lazy.width, whole.width, atol=1e-3, rtol=1e-4)


def test_whole_heads_give_the_same_planner_output_as_heads_on_demand():
    """``heads="whole"`` (a GPU's default) computes rotation and width at every voxel with
    quality; the planner's output is the same as with heads on demand (a CPU's default)."""
    grids = [grid for _, grid in recorded_grids()]
    on_demand = GraspPlanner.from_path(PACKAGED_MODEL, "cpu", InferenceOptions(precision="fp32"))
    whole = GraspPlanner.from_path(PACKAGED_MODEL, "cpu", InferenceOptions(precision="fp32", heads="whole"))
    assert (on_demand.runtime()["heads"], whole.runtime()["heads"]) == ("on-demand", "whole")
    for grid in grids:
        lazy, computed = on_demand.infer(grid, turn_average=True), whole.infer(grid, turn_average=True)
        assert isinstance(computed.heads, ComputedHeads) and isinstance(lazy.heads, HeadsOnDemand)
        np.testing.assert_allclose(computed.quality, lazy.quality, atol=1e-6)
        np.testing.assert_allclose(computed.width, lazy.width, atol=1e-4, rtol=1e-5)
        strong = lazy.quality > 0.5
        np.testing.assert_allclose(computed.rotation_where(strong), lazy.rotation_where(strong), atol=1e-4)


def test_an_unknown_heads_choice_is_refused():
    with pytest.raises(ValueError, match="heads must be one of"):
        resolve_heads("sometimes", torch.device("cpu"))
    assert resolve_heads("auto", torch.device("cpu")) == "on-demand"
    assert resolve_heads("auto", torch.device("cuda")) == "whole"


def test_orientations_at_voxels_whose_widths_were_just_read_come_from_the_same_computation():
    """Detection reads widths where quality passes, then orientations at some of those voxels:
    the second read reuses the first's computation, and a read elsewhere computes afresh."""
    _, grid = recorded_grids()[0]
    planner = GraspPlanner.from_path(PACKAGED_MODEL, "cpu", InferenceOptions(precision="fp32"))
    heads = planner.infer(grid).heads
    assert isinstance(heads, HeadsOnDemand)
    rng = np.random.default_rng(2)
    voxels = np.unique(rng.integers(0, grid.shape[0] ** 3, 300))
    i, j, depth = np.unravel_index(voxels, grid.shape)
    whole_rotation, whole_width = ComputedHeads(*heads.whole()).whole()
    heads._whole = None  # back to computing voxel by voxel
    np.testing.assert_allclose(heads.width_at(i, j, depth), whole_width[i, j, depth], atol=1e-3, rtol=1e-4)
    first = heads._last
    subset = rng.permutation(len(voxels))[:50]
    rotation = heads.rotation_at(i[subset], j[subset], depth[subset])
    assert heads._last is first, "a subset is read from the last computation"
    np.testing.assert_allclose(rotation, whole_rotation[:, i[subset], j[subset], depth[subset]], atol=1e-4)
    elsewhere = np.setdiff1d(np.arange(grid.shape[0] ** 3), voxels)[:20]
    a, b, c = np.unravel_index(elsewhere, grid.shape)
    np.testing.assert_allclose(heads.rotation_at(a, b, c), whole_rotation[:, a, b, c], atol=1e-4)
    assert heads._last is not first


def test_a_cpu_gets_one_lane_per_group_of_torch_threads(monkeypatch):
    import torch

    from service import planner

    monkeypatch.setattr(planner, "usable_cores", lambda: 16)
    monkeypatch.setattr(torch, "get_num_threads", lambda: 8)
    assert planner.default_lanes(torch.device("cpu")) == 2
    monkeypatch.setattr(torch, "get_num_threads", lambda: 16)
    assert planner.default_lanes(torch.device("cpu")) == 1
    assert planner.default_lanes(torch.device("cuda")) == 1


def test_a_failing_forward_reaches_every_waiting_request_and_the_batcher_goes_on():
    calls = []

    def forward(grids: np.ndarray) -> list:
        calls.append(len(grids))
        if grids[0, 0, 0, 0] < 0:
            raise ValueError("bad grid")
        return [float(g.sum()) for g in grids]

    batcher = MicroBatcher(forward)
    with pytest.raises(ValueError, match="bad grid"):
        batcher.run(-np.ones((2, 2, 2), np.float32))
    assert batcher.run(np.ones((2, 2, 2), np.float32)) == 8.0
    # Grids of different sizes never share a batch.
    assert batcher.run(np.ones((4, 4, 4), np.float32)) == 64.0


def test_sessions_asking_at_once_over_http_and_grpc_share_forward_passes():
    """Several sessions of a real server request grasps at the same moment, first over HTTP,
    then over gRPC; with a batching window each burst is answered from shared forward passes,
    with the grasps each session gets alone: both front ends plan through the same batcher."""
    # Without reuse: the repeated requests on unchanged sessions must each run the network.
    env = {
        "VGN_API_KEY": "",
        "VGN_BATCH_WINDOW_MS": "300",
        "VGN_PRECISION": "fp32",
        "VGN_REUSE_OUTPUT": "false",
    }
    scene = BoxScene()
    views = [(scene.depth(pose), pose) for pose in circle_views(3)]
    with EmbeddedService(model=PACKAGED_MODEL, env=env, grpc=True) as service, VGNClient(service.url) as vgn:
        sessions = []
        for _ in range(SESSIONS):
            session_id = vgn.create_session(intrinsics=INTRINSICS).session_id
            for depth, pose in views:
                vgn.add_frame(session_id, depth, pose)
            sessions.append(session_id)
        alone = [vgn.grasps(s, threshold=0.5).grasps for s in sessions]
        assert alone[0], "the box offers grasps"
        for url in (service.url, service.grpc_url):
            before = vgn.model().runtime.batches.model_dump()
            start = threading.Barrier(SESSIONS)

            def ask(session_id: str, url: str = url, start: threading.Barrier = start):
                with connect(url) as own:
                    start.wait()
                    return own.grasps(session_id, threshold=0.5).grasps

            with ThreadPoolExecutor(SESSIONS) as pool:
                together = list(pool.map(ask, sessions))
            after = httpx.get(f"{service.url}/model").json()["runtime"]["batches"]
            for batched, single in zip(together, alone, strict=True):  # equal up to float rounding
                assert [g.position for g in batched] == [g.position for g in single], url
                assert np.allclose([g.quality for g in batched], [g.quality for g in single], atol=1e-5)
                assert np.allclose(
                    [g.orientation for g in batched], [g.orientation for g in single], atol=1e-5
                )
            assert after["batches"] - before["batches"] < SESSIONS, url
            assert after["largest"] > 1, url
