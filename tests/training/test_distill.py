"""Distilling turn averaging: a teacher's turn-averaged answer as soft labels that move with the
scene's augmentation, their loss, and a training run that uses them."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from service.checks import check_grasps
from service.grid_surface import grid_surface_points
from service.grip import GripConfig
from service.planner import GraspPlanner, InferenceOptions
from service.settings import PACKAGED_MODEL
from service.vgn.checkpoint import card_path, save_vgn, weights_id
from service.vgn.network import VGN
from tests.helpers.datasets import VOXEL, N, make_dataset
from tests.helpers.grids import recorded_grids
from training.augment import Placement
from training.cli import main
from training.dataset import PackedGrid, Sample, SceneDataset, collate, load_scenes
from training.distill import (
    CHECKED_QUALITY,
    SoftTargets,
    failing_checks,
    load_targets,
    save_targets,
    soft_targets,
    teach,
    teaching_key,
)
from training.grids import MAX_DEPTH, RESOLUTION
from training.labels import LabelSet
from training.loss import distillation_loss
from training.quaternions import flipped
from training.shards import quantize
from vgn_contract.schemas import Grasp
from vgn_data.dataset import RawDataset


@pytest.fixture(scope="module")
def teacher() -> GraspPlanner:
    return GraspPlanner.from_path(
        PACKAGED_MODEL, "cpu", InferenceOptions(precision="float32", batch_window_ms=0)
    )


@pytest.fixture(scope="module")
def raw(tmp_path_factory: pytest.TempPathFactory) -> RawDataset:
    return make_dataset(tmp_path_factory.mktemp("raw") / "boxes", scenes=4)


def as_dict(labels: LabelSet) -> dict[tuple[int, ...], tuple[float, np.ndarray]]:
    return {
        tuple(v): (float(q), r)
        for v, q, r in zip(
            labels.voxel.tolist(), labels.label.numpy(), labels.quaternion.numpy(), strict=True
        )
    }


@pytest.mark.parametrize("quarter_turns", [1, 2, 3])
def test_soft_labels_moved_with_a_turned_scene_are_the_teachers_answer_for_it(
    teacher: GraspPlanner, quarter_turns: int
):
    """Training turns a scene and its soft labels together; the moved soft labels must be what
    the teacher says about the turned scene, or the student would learn a shifted answer. The
    averaged quality is the same whichever way the scene is turned."""
    _, grid = recorded_grids()[0]
    original = soft_targets(teacher, grid)
    moved = Placement(quarter_turns, 0).apply_labels(
        original.draw(len(original), np.random.default_rng(0)), N
    )
    turned = soft_targets(teacher, np.ascontiguousarray(np.rot90(grid, quarter_turns, axes=(0, 1))))
    expected = as_dict(turned.draw(len(turned), np.random.default_rng(0)))
    # Away from the two border rows, where a turn takes positions off the grid, every voxel of
    # the turned scene averages all four turns, as the original's does.
    inner = {v: a for v, a in as_dict(moved).items() if 1 <= v[0] < N - 1 and 1 <= v[1] < N - 1}
    common = inner.keys() & expected.keys()
    assert len(common) > 0.9 * len(inner) > 1000
    angles = []
    for voxel in common:
        (quality, quaternion), (want_quality, want_quaternion) = inner[voxel], expected[voxel]
        assert quality == pytest.approx(want_quality, abs=1e-3), f"quality at {voxel} differs"
        alignment = max(
            abs(float(np.dot(quaternion, want_quaternion))),
            abs(float(np.dot(flipped(torch.from_numpy(quaternion)).numpy(), want_quaternion))),
        )
        angles.append(2 * np.degrees(np.arccos(min(alignment, 1.0))))
    # Averaged orientations are aligned to the unturned grid's own prediction, which differs
    # between the two scenes where the four turns disagree; elsewhere they agree.
    assert np.median(angles) < 1.0 and np.mean(np.asarray(angles) < 5.0) > 0.6


def test_soft_labels_cover_the_grasp_region_and_draws_are_subsets(teacher: GraspPlanner):
    _, grid = recorded_grids()[0]
    targets = soft_targets(teacher, grid)
    assert targets.voxel.dtype == np.uint8 and 1000 < len(targets) < grid.size
    assert np.all((targets.quality >= 0) & (targets.quality <= 1))
    draw = targets.draw(100, np.random.default_rng(1))
    assert len(draw) == 100 and len(set(map(tuple, draw.voxel.tolist()))) == 100
    assert torch.allclose(draw.quaternion.norm(dim=-1), torch.ones(100), atol=1e-6)
    assert len(targets.draw(10**6, np.random.default_rng(1))) == len(targets)


def test_checked_soft_labels_are_zero_exactly_where_the_services_checks_drop_the_grasp(teacher: GraspPlanner):
    """With the checks, a teacher grasp the service would drop (clearance or grip) teaches
    quality 0; every other soft label is the teacher's answer unchanged."""
    _, grid = recorded_grids()[0]
    plain, checked = soft_targets(teacher, grid), soft_targets(teacher, grid, VOXEL)
    np.testing.assert_array_equal(checked.voxel, plain.voxel)
    np.testing.assert_array_equal(checked.quaternion, plain.quaternion)
    zeroed = (checked.quality == 0) & (plain.quality > 0)
    assert np.all(checked.quality[~zeroed] == plain.quality[~zeroed])
    assert np.all(plain.quality[zeroed] >= CHECKED_QUALITY)
    strong = plain.quality >= CHECKED_QUALITY
    assert 0 < zeroed.sum() < strong.sum(), "the checks drop some of the teacher's grasps, not all"

    # The same verdicts as the service's checks on those grasps as world-frame Grasps (the
    # workspace at the world origin), including the clearance check's surface points. Each grasp
    # is judged alone: the preference for square grips depends on what else a request returns.
    rows = np.flatnonzero(strong)[::7]
    quaternion = plain.quaternion[rows].astype(np.float64)
    quaternion /= np.linalg.norm(quaternion, axis=1, keepdims=True)
    grasps = [
        Grasp(position=(v * VOXEL).tolist(), orientation=q.tolist(), approach=[0.0, 0.0, 1.0], width=0.04, quality=0.9)
        for v, q in zip(plain.voxel[rows].astype(np.float64), quaternion, strict=True)
    ]  # fmt: skip
    alone = GripConfig(preferred_alignment=GripConfig().min_alignment)
    surface, size = grid_surface_points(grid, VOXEL), grid.shape[0] * VOXEL
    kept = check_grasps(grasps, surface, grid, VOXEL, np.eye(4), size, alone, alternatives=False).grasps
    kept_rows = {tuple(g.position) for g in kept}
    service_drops = np.array([tuple(g.position) not in kept_rows for g in grasps])
    quality = np.ones(len(rows))
    np.testing.assert_array_equal(
        failing_checks(grid, VOXEL, plain.voxel[rows].astype(np.int64), quaternion, quality), service_drops
    )
    assert 0 < service_drops.sum() < len(rows)


def test_checks_in_worker_processes_give_the_same_targets_as_in_this_one():
    """The checks run in spawned processes while the network answers the next scenes; the
    targets, in scene order, are those of the serial run, bit for bit."""
    grids = [PackedGrid(quantize(grid)) for _, grid in recorded_grids()[:5]]
    sizes = [VOXEL] * len(grids)
    serial = teach(PACKAGED_MODEL, grids, "cpu", progress=False, voxel_sizes=sizes)
    parallel = teach(PACKAGED_MODEL, grids, "cpu", progress=False, voxel_sizes=sizes, workers=2)
    assert len(parallel) == len(serial) == len(grids)
    for one, other in zip(parallel, serial, strict=True):
        for name in ("voxel", "quality", "quaternion", "width"):
            assert np.array_equal(getattr(one, name), getattr(other, name))
    unchecked = teach(PACKAGED_MODEL, grids, "cpu", progress=False)
    assert any(not np.array_equal(c.quality, u.quality) for c, u in zip(serial, unchecked, strict=True)), (
        "the checks zeroed some of the teacher's grasps"
    )


def one_voxel_targets(voxel, quaternion, quality=0.7, width=4.0) -> SoftTargets:
    return SoftTargets(
        voxel=np.asarray([voxel], np.uint8),
        quality=np.asarray([quality], np.float16),
        quaternion=np.asarray([quaternion], np.float16),
        width=np.asarray([width], np.float16),
    )


def test_a_draw_moves_soft_labels_with_the_grid_and_the_trial_labels(raw: RawDataset, tmp_path: Path):
    """A soft label put where a trial label is, with its orientation, stays with it through
    every turn and height the draws pick."""
    scenes, _ = load_scenes([raw.root], RESOLUTION, MAX_DEPTH, tmp_path / "cache")
    soft = []
    for scene in scenes:
        first = scene.labels.select(torch.arange(len(scene.labels)) == 0)
        soft.append(one_voxel_targets(first.voxel[0].tolist(), first.quaternion[0].numpy()))
    data = SceneDataset(scenes, augment="height", seed=0, soft=soft)
    placements = set()
    for epoch in range(6):
        data.epoch = epoch
        for index in range(len(data)):
            sample = data[index]
            assert sample.soft is not None and len(sample.soft) == 1
            hard = sample.labels.voxel.tolist()
            position = sample.soft.voxel[0].tolist()
            # The trial label shares its first label's voxel only if nothing dropped it; match by content.
            matches = [n for n, v in enumerate(hard) if v == position]
            assert matches, "the soft label left its trial label"
            assert any(
                torch.allclose(sample.labels.quaternion[n], sample.soft.quaternion[0], atol=1e-3)
                for n in matches
            )
            placements.add((position[0], position[2]))
    assert len(placements) > 4, "draws turned and lifted the scenes"
    with pytest.raises(ValueError, match="soft targets"):
        SceneDataset(scenes, augment=None, seed=0, soft=soft[:1])


def test_the_soft_loss_reads_only_soft_voxels_and_is_least_at_the_teachers_answer():
    quaternion = Rotation.random(random_state=2).as_quat().astype(np.float32)
    soft = one_voxel_targets([3, 4, 5], quaternion, quality=0.75, width=4.0).draw(1, np.random.default_rng(0))
    empty = LabelSet(
        torch.zeros((0, 3), dtype=torch.long), torch.zeros((0, 4)), torch.zeros(0), torch.zeros(0)
    )
    batch = collate(
        [Sample(torch.zeros(N, N, N), empty, VOXEL, soft), Sample(torch.zeros(N, N, N), empty, VOXEL)]
    )
    assert batch.soft_scene.tolist() == [0] and len(batch) == 0

    def loss_at(
        q: float, rotation: np.ndarray, width: float
    ) -> tuple[torch.Tensor, tuple[torch.Tensor, ...]]:
        output = (
            torch.full((2, 1, N, N, N), 0.5),
            torch.tensor([0.0, 0, 0, 1]).view(1, 4, 1, 1, 1).repeat(2, 1, N, N, N),
            torch.zeros(2, 1, N, N, N),
        )
        output[0][0, 0, 3, 4, 5], output[1][0, :, 3, 4, 5], output[2][0, 0, 3, 4, 5] = (
            q,
            torch.tensor(rotation),
            width,
        )
        output = tuple(t.requires_grad_(True) for t in output)
        return distillation_loss(output, batch).sum(), output

    best, output = loss_at(0.75, quaternion, 4.0)
    best.backward()
    for tensor in output:
        elsewhere = tensor.grad.clone()
        elsewhere[0, :, 3, 4, 5] = 0
        assert torch.all(elsewhere == 0), "no gradient away from the soft labels"
    assert abs(float(output[0].grad[0, 0, 3, 4, 5])) < 1e-4, "BCE is least at the teacher's quality"
    turned = (Rotation.from_quat(quaternion) * Rotation.from_euler("z", np.pi)).as_quat().astype(np.float32)
    assert loss_at(0.75, turned, 4.0)[0].item() == pytest.approx(best.item(), abs=1e-5), (
        "either of the two grasps"
    )
    for worse in (
        loss_at(0.95, quaternion, 4.0),
        loss_at(0.75, quaternion, 6.0),
        loss_at(0.75, -np.roll(quaternion, 1), 4.0),
    ):
        assert worse[0].item() > best.item() + 1e-3


def test_a_run_with_a_teacher_records_it_and_resumes_only_with_it(raw: RawDataset, tmp_path: Path, capsys):
    torch.manual_seed(0)
    weights = tmp_path / "teacher.safetensors"
    save_vgn(VGN(), weights)
    out = tmp_path / "student" / "vgn.safetensors"
    args = ["--data", str(raw.root), "--out", str(out), "--cache", str(tmp_path / "cache"), "--no-progress"]
    args += ["--batch-scenes", "2", "--val-fraction", "0.25", "--threads", "1", "--threshold", "0.8"]

    assert main([*args, "--epochs", "1", "--teacher", str(tmp_path / "missing.safetensors")]) == 2
    assert "--teacher" in capsys.readouterr().err
    assert main([*args, "--epochs", "1", "--teacher", str(weights), "--soft-per-draw", "0"]) == 2
    assert "--soft-per-draw" in capsys.readouterr().err
    assert main([*args, "--epochs", "1", "--teacher-checks"]) == 2
    assert "--teacher-checks needs --teacher" in capsys.readouterr().err

    assert main([*args, "--epochs", "1", "--teacher", str(weights), "--soft-per-draw", "64"]) == 0
    assert "worked out" in capsys.readouterr().out
    card = json.loads(card_path(out).read_text())
    distillation = card["training"]["distillation"]
    assert (
        distillation["teacher"]["weights_id"] == weights_id(weights)
        and distillation["soft_labels_per_draw"] == 64
    )
    train = card["history"][0]["train"]
    assert train["distill_loss"] > 0 and 0 < train["soft_labels"] <= 64 * card["training"]["train_scenes"]
    assert "distill_loss" not in (card["history"][0]["val"] or {}), "validation scores trial labels only"

    other = tmp_path / "other.safetensors"
    save_vgn(VGN(), other)
    assert main([*args, "--epochs", "2", "--resume", "--teacher", str(other)]) == 2
    assert "teacher" in capsys.readouterr().err
    assert main([*args, "--epochs", "2", "--resume", "--teacher", str(weights), "--soft-per-draw", "64"]) == 0
    assert "read from vgn.teacher.npz" in capsys.readouterr().out, "a resume reads the saved soft labels"
    # The checks change the targets: a run without them does not resume with them.
    checked = [*args, "--epochs", "3", "--resume", "--teacher", str(weights), "--soft-per-draw", "64"]
    assert main([*checked, "--teacher-checks"]) == 2
    assert "teacher_checks" in capsys.readouterr().err


def test_saved_soft_labels_are_read_back_only_for_the_same_teacher_and_grids(tmp_path: Path):
    """A resume skips the teacher only when its answer could not differ: same weights, same grids
    in the same order, same checks. A damaged file is worked out again, not trusted."""
    grids = [PackedGrid(quantize(grid)) for _, grid in recorded_grids()[:3]]
    targets = teach(PACKAGED_MODEL, grids, "cpu", progress=False)
    key = teaching_key(PACKAGED_MODEL, grids)
    path = tmp_path / "vgn.teacher.npz"
    save_targets(path, key, targets)

    read = load_targets(path, key)
    assert read is not None and len(read) == len(targets)
    for saved, original in zip(read, targets, strict=True):
        for name in ("voxel", "quality", "quaternion", "width"):
            assert np.array_equal(getattr(saved, name), getattr(original, name))

    other_weights = tmp_path / "other.safetensors"
    save_vgn(VGN(), other_weights)
    changed = [grids[0], grids[2], grids[1]]
    for other_key in (
        teaching_key(other_weights, grids),
        teaching_key(PACKAGED_MODEL, changed),
        teaching_key(PACKAGED_MODEL, grids[:2]),
        teaching_key(PACKAGED_MODEL, grids, [VOXEL] * 3),
    ):
        assert other_key != key and load_targets(path, other_key) is None
    assert teaching_key(PACKAGED_MODEL, grids) == key, "the key is a function of its inputs"

    path.write_bytes(path.read_bytes()[:1000])
    assert load_targets(path, key) is None
    assert load_targets(tmp_path / "missing.npz", key) is None


def test_a_run_with_checked_targets_records_them(raw: RawDataset, tmp_path: Path):
    out = tmp_path / "student" / "vgn.safetensors"
    args = ["--data", str(raw.root), "--out", str(out), "--cache", str(tmp_path / "cache"), "--no-progress"]
    args += ["--batch-scenes", "2", "--val-fraction", "0.25", "--threads", "1", "--threshold", "0.8"]
    args += ["--epochs", "1", "--teacher", str(PACKAGED_MODEL), "--soft-per-draw", "64", "--teacher-checks"]
    assert main(args) == 0
    distillation = json.loads(card_path(out).read_text())["training"]["distillation"]
    assert distillation["checks"].startswith("quality 0 where the clearance or grip check fails")
