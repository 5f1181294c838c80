"""Training pipeline: loss, augmentation, grids, cache, and a short train → resume → serve run.

The datasets are tiny synthetic raw datasets: analytic box scenes seen by small cameras,
with a handful of hand-placed labels, written through ``vgn_data.dataset.RawDataset``.
"""

from __future__ import annotations

import json
import math
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from service.core import PlanningService
from service.planner import GraspPlanner
from service.vgn.checkpoint import card_path, card_summary, load_vgn, save_vgn, weights_id
from service.vgn.network import VGN
from tests.helpers.datasets import SMALL, TOP_DOWN, VOXEL, N, make_dataset
from training import report
from training.augment import random_augment, rotate_z, shift_z
from training.checkpoint import checkpoint_path
from training.cli import build_parser, config_from_args, main
from training.dataset import (
    Batch,
    Sample,
    collate,
    load_scenes,
    prepare_grids,
    split_scenes,
    subsample_scenes,
)
from training.grids import cache_key
from training.labels import LabelSet
from training.loss import Predictions, gather, per_label_loss, rotation_loss, vgn_loss
from training.metrics import MetricAccumulator, choose_threshold, rotation_error_deg
from training.quaternions import flipped, multiply
from training.train import TrainConfig
from vgn_contract.schemas import SessionCreate
from vgn_data.dataset import DatasetSetup, RawDataset


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> RawDataset:
    return make_dataset(tmp_path_factory.mktemp("raw") / "boxes", scenes=4)


def labels_of(voxels, quaternions, label=1.0) -> LabelSet:
    voxels = torch.as_tensor(voxels, dtype=torch.long).reshape(-1, 3)
    count = len(voxels)
    return LabelSet(
        voxel=voxels,
        quaternion=torch.as_tensor(np.asarray(quaternions), dtype=torch.float32).reshape(count, 4),
        width=torch.full((count,), 5.0),
        label=torch.full((count,), label),
    )


# Quaternions and the loss -------------------------------------------------------------------


def test_quaternion_product_and_flip_match_scipy():
    a, b = Rotation.random(5, random_state=1), Rotation.random(5, random_state=2)
    product = multiply(torch.tensor(a.as_quat()), torch.tensor(b.as_quat())).numpy()
    assert np.allclose(np.abs(np.sum(product * (a * b).as_quat(), axis=1)), 1.0)
    # q_π = q ⊗ [0, 0, 1, 0] is q turned by π about its own (grasp) z axis.
    turned = (a * Rotation.from_euler("z", np.pi)).as_quat()
    assert np.allclose(np.abs(np.sum(flipped(torch.tensor(a.as_quat())).numpy() * turned, axis=1)), 1.0)
    assert np.allclose(
        multiply(torch.tensor(a.as_quat()), torch.tensor([0.0, 0, 1, 0])).numpy(),
        flipped(torch.tensor(a.as_quat())).numpy(),
    )


def test_rotation_loss_is_zero_for_both_symmetric_targets_only():
    target = torch.tensor(Rotation.random(8, random_state=3).as_quat(), dtype=torch.float32)
    assert torch.allclose(rotation_loss(target, target), torch.zeros(8), atol=1e-6)
    assert torch.allclose(rotation_loss(flipped(target), target), torch.zeros(8), atol=1e-6)
    assert torch.allclose(rotation_loss(-flipped(target), target), torch.zeros(8), atol=1e-6)
    other = Rotation.from_quat(target.numpy()) * Rotation.from_euler("z", np.pi / 2)
    assert torch.all(rotation_loss(torch.tensor(other.as_quat(), dtype=torch.float32), target) > 0.2)
    tilted = Rotation.from_quat(target.numpy()) * Rotation.from_euler("x", 0.3)
    assert torch.all(rotation_loss(torch.tensor(tilted.as_quat(), dtype=torch.float32), target) > 0.01)


def random_output(batch: int = 2, requires_grad: bool = False):
    torch.manual_seed(0)
    quality = torch.rand(batch, 1, N, N, N) * 0.98 + 0.01
    rotation = torch.nn.functional.normalize(torch.randn(batch, 4, N, N, N), dim=1)
    width = torch.rand(batch, 1, N, N, N) * 8
    return tuple(t.requires_grad_(requires_grad) for t in (quality, rotation, width))


def small_batch() -> Batch:
    quaternions = Rotation.random(3, random_state=4).as_quat()
    a = Sample(torch.zeros(N, N, N), labels_of([[1, 2, 3], [39, 0, 20]], quaternions[:2]), VOXEL)
    b = Sample(torch.zeros(N, N, N), labels_of([[5, 6, 7]], quaternions[2:], label=0.0), VOXEL)
    return collate([a, b])


def test_gather_reads_output_at_label_voxels_of_their_scene():
    batch = small_batch()
    quality, rotation, width = random_output()
    predictions = gather((quality, rotation, width), batch)
    expected = [(0, 1, 2, 3), (0, 39, 0, 20), (1, 5, 6, 7)]
    for n, (b, i, j, k) in enumerate(expected):
        assert predictions.quality[n] == quality[b, 0, i, j, k]
        assert torch.equal(predictions.quaternion[n], rotation[b, :, i, j, k])
        assert predictions.width[n] == width[b, 0, i, j, k]


def test_loss_only_reads_labelled_voxels():
    batch = small_batch()
    output = random_output(requires_grad=True)
    loss = vgn_loss(gather(output, batch), batch)
    loss.backward()
    labelled = torch.zeros(2, N, N, N, dtype=torch.bool)
    labelled[0, 1, 2, 3] = labelled[0, 39, 0, 20] = labelled[1, 5, 6, 7] = True
    for tensor in output:
        gradient = tensor.grad.abs().sum(dim=1)
        assert torch.all(gradient[~labelled] == 0), "no gradient may reach unlabelled voxels"
    assert torch.all(output[0].grad[:, 0][labelled] != 0)
    # Changing the output anywhere else leaves the loss as it was.
    changed = tuple(t.detach().clone() for t in output)
    changed[0][:, 0][~labelled] = 0.5
    changed[2][:, 0][~labelled] = 100.0
    assert vgn_loss(gather(changed, batch), batch) == pytest.approx(loss.item(), rel=1e-6)


def test_loss_terms():
    """A perfect prediction costs only the BCE; width and rotation count for positives only."""
    batch = small_batch()
    perfect = Predictions(batch.label * 0.999 + 0.0005, flipped(batch.quaternion), batch.width.clone())
    assert torch.all(per_label_loss(perfect, batch) < 2e-3)
    wide = Predictions(perfect.quality, perfect.quaternion, batch.width + 10.0)
    losses = per_label_loss(wide, batch) - per_label_loss(perfect, batch)
    assert torch.allclose(losses, batch.label * 0.01 * 100.0, atol=1e-4)


# Augmentation -------------------------------------------------------------------------------


def marked(labels: LabelSet) -> torch.Tensor:
    """A grid holding a distinct marker in each label's cell, and another one cell along
    each grasp's approach axis (the approaches below are axis-aligned)."""
    grid = torch.zeros(N, N, N)
    for n, (voxel, quaternion) in enumerate(zip(labels.voxel, labels.quaternion, strict=True)):
        grid[tuple(voxel)] = 1.0 + n
        grid[tuple(voxel + approach_step(quaternion))] = 100.0 + n
    return grid


def approach_step(quaternion: torch.Tensor) -> torch.Tensor:
    approach = Rotation.from_quat(quaternion.numpy()).apply([0.0, 0.0, 1.0])
    step = np.rint(approach).astype(np.int64)
    assert np.allclose(approach, step, atol=1e-5)
    return torch.from_numpy(step)


def cell_offset(quarter_turns: int) -> torch.Tensor:
    """Where a label's cell goes relative to the label after a turn: a grid cell describes
    the space around its centre (i + 0.5) × voxel while the label sits at i × voxel, so the
    half-voxel offset between them turns too: cell = label + R(½, ½) − ½."""
    half = Rotation.from_euler("z", quarter_turns * np.pi / 2).apply([0.5, 0.5, 0.5])
    return torch.from_numpy(np.rint(half - 0.5).astype(np.int64))


def assert_aligned(grid: torch.Tensor, labels: LabelSet, quarter_turns: int = 0) -> None:
    offset = cell_offset(quarter_turns)
    for n in range(len(labels)):
        cell = labels.voxel[n] + offset
        assert grid[tuple(cell)] == 1.0 + n, "the label's cell must carry its grid feature along"
        assert grid[tuple(cell + approach_step(labels.quaternion[n]))] == 100.0 + n, (
            "the grasp orientation must turn with the grid"
        )


# Side grasps approaching along +x, -y and +y, and a top-down one, at asymmetric voxels.
AXIS_GRASPS = labels_of(
    [[5, 9, 12], [30, 17, 8], [12, 33, 25], [21, 4, 30]],
    [
        Rotation.from_euler("y", np.pi / 2).as_quat(),  # z → +x
        Rotation.from_euler("x", np.pi / 2).as_quat(),  # z → -y
        Rotation.from_euler("zx", [0.7, -np.pi / 2]).as_quat(),  # z → +y, yawed
        TOP_DOWN.as_quat(),  # z → -z
    ],
)


@pytest.mark.parametrize("quarter_turns", [0, 1, 2, 3])
def test_rotation_moves_grid_labels_and_orientations_together(quarter_turns: int):
    grid = marked(AXIS_GRASPS)
    rotated, labels = rotate_z(grid, AXIS_GRASPS, quarter_turns)
    assert_aligned(rotated, labels, quarter_turns)
    turn = Rotation.from_euler("z", quarter_turns * np.pi / 2)
    expected = (turn * Rotation.from_quat(AXIS_GRASPS.quaternion.numpy())).as_quat()
    assert np.allclose(np.abs(np.sum(labels.quaternion.numpy() * expected, axis=1)), 1.0, atol=1e-6)
    assert torch.equal(labels.width, AXIS_GRASPS.width) and torch.equal(labels.label, AXIS_GRASPS.label)


def test_quarter_turn_is_positive_about_z():
    """One quarter turn maps +x to +y: a label at index (i, j) goes to (N-j, i) about the centre."""
    labels = labels_of([[30, 20, 5]], [Rotation.identity().as_quat()])
    _, turned = rotate_z(torch.zeros(N, N, N), labels, 1)
    assert turned.voxel.tolist() == [[N - 20, 30, 5]]


@pytest.mark.parametrize("quarter_turns", [1, 2, 3])
def test_rotated_labels_are_the_physically_rotated_grasps(quarter_turns: int):
    """Augmented labels equal the grasps of the scene turned about the workspace centre:
    round(R (p - c) + c) / voxel for positions p = index × voxel (detection's convention);
    those turned out of the grid are dropped."""
    voxels = [[5, 9, 12], [30, 17, 8], [12, 33, 25], [0, 4, 30], [39, 0, 2]]
    labels = labels_of(voxels, [Rotation.identity().as_quat()] * len(voxels))
    _, turned = rotate_z(torch.zeros(N, N, N), labels, quarter_turns)
    centre = np.array([N / 2, N / 2, 0.0])
    physical = (
        Rotation.from_euler("z", quarter_turns * np.pi / 2).apply(np.asarray(voxels, float) - centre) + centre
    )
    expected = np.rint(physical).astype(int)
    inside = np.all((expected >= 0) & (expected < N), axis=1)
    assert turned.voxel.tolist() == expected[inside].tolist()


@pytest.mark.parametrize("shift", [-4, -1, 3, 4])
def test_z_shift_moves_grid_and_labels_and_drops_leavers(shift: int):
    grid = marked(AXIS_GRASPS)
    shifted, labels = shift_z(grid, AXIS_GRASPS, shift)
    assert_aligned(shifted, labels)
    assert torch.equal(labels.voxel[:, 2], AXIS_GRASPS.voxel[:, 2] + shift)
    edge = labels_of([[3, 3, 0], [3, 3, N - 1]], [Rotation.identity().as_quat()] * 2)
    _, kept = shift_z(torch.zeros(N, N, N), edge, shift)
    assert len(kept) == 1 and 0 <= int(kept.voxel[0, 2]) < N
    assert torch.all(shifted[:, :, :shift] == 0) if shift > 0 else torch.all(shifted[:, :, N + shift :] == 0)


def test_random_augmentations_keep_alignment():
    grid = marked(AXIS_GRASPS)
    rng, twin = np.random.default_rng(7), np.random.default_rng(7)  # the twin replays the draws
    for _ in range(12):
        augmented, labels = random_augment(grid, AXIS_GRASPS, rng, max_shift=3)
        quarter_turns = int(twin.integers(4))
        twin.integers(-3, 4)
        assert len(labels) == len(AXIS_GRASPS)
        assert_aligned(augmented, labels, quarter_turns)


# Data: labels, grids, cache, split ----------------------------------------------------------


def test_labels_map_to_voxels_and_drop_outside():
    rows = np.array(
        [
            [0, 0, 0, 1, 3 * VOXEL, 7 * VOXEL + 1e-6, 39 * VOXEL, 0.03, 1],
            [0, 0, 0, 2, 0.0, 0.0, 0.0, 0.0, 0],  # unnormalised quaternion
            [0, 0, 0, 1, 40 * VOXEL, 0.1, 0.1, 0.03, 1],  # index 40: outside
            [0, 0, 0, 1, -0.01, 0.1, 0.1, 0.03, 0],
        ]
    )
    labels, dropped = LabelSet.from_rows(rows, VOXEL, N)
    assert dropped == 2 and labels.voxel.tolist() == [[3, 7, 39], [0, 0, 0]]
    assert labels.width[0] == pytest.approx(4.0) and labels.label.tolist() == [1.0, 0.0]
    assert torch.allclose(labels.quaternion[1], torch.tensor([0.0, 0, 0, 1]))


def test_training_grids_equal_service_grids(dataset: RawDataset, core: PlanningService, tmp_path: Path):
    scenes, _ = load_scenes([dataset.root], N, 2.0, cache_root=tmp_path)
    for scene in scenes[:2]:
        views = dataset.read_scene(scene.scene_id)
        session = core.create_session(SessionCreate()).session_id
        for depth, pose in zip(views.depth, views.camera_poses, strict=True):
            core.add_frame(session, depth, pose, SMALL, 2.0)
        assert np.array_equal(scene.source.load(), core.grid(session))
        assert np.array_equal(scene.source.load(), scene.source.cached())


def test_grid_cache_is_used_and_corrupt_files_rebuilt(dataset: RawDataset, tmp_path: Path):
    scenes, summaries = load_scenes([dataset.root], N, 2.0, cache_root=tmp_path / "cache")
    assert prepare_grids(scenes, progress=False) == len(scenes)
    files = sorted(Path(summaries[0].cache).glob("*.npz"))
    assert [f.stem for f in files] == [s.scene_id for s in scenes]
    assert prepare_grids(scenes, progress=False) == 0, "the second load reads the cache"
    original = scenes[0].source.load()
    scenes[0].source.cache_path.write_bytes(b"not an npz")
    assert scenes[0].source.cached() is None
    assert prepare_grids(scenes, progress=False) == 1
    assert np.array_equal(scenes[0].source.cached(), original)
    assert not list(Path(summaries[0].cache).glob(".*.tmp")), "no temp files left behind"
    # Another setup or resolution gets another key, so it never reads these files.
    setup = dataset.setup
    assert cache_key(setup, 40, 2.0) != cache_key(setup, 48, 2.0)
    assert cache_key(setup, 40, 2.0) != cache_key(DatasetSetup(size=0.4, intrinsics=SMALL), 40, 2.0)


def test_split_is_by_scene_and_fixed_by_seed(dataset: RawDataset, tmp_path: Path):
    scenes, summaries = load_scenes([dataset.root], N, 2.0, cache_root=tmp_path)
    assert summaries[0].scenes == 4 and summaries[0].outside_grid == 4
    assert summaries[0].grasps == 4 * 6 and summaries[0].positives == 4 * 3
    train, val = split_scenes(scenes, 0.1, seed=1)
    assert len(val) >= 1 and len(train) + len(val) == 4
    assert {s.key for s in train}.isdisjoint({s.key for s in val})
    assert [s.key for s in split_scenes(scenes, 0.1, seed=1)[1]] == [s.key for s in val]
    assert split_scenes(scenes, 0.0, seed=1)[1] == []
    # Each scene's side depends only on (seed, scene): a grown dataset keeps the old split.
    more = make_dataset(tmp_path / "more", scenes=40)
    grown, _ = load_scenes([more.root], N, 2.0, cache_root=tmp_path)
    big_train, big_val = split_scenes(grown, 0.3, seed=2)
    small_train, small_val = split_scenes(grown[:25], 0.3, seed=2)
    assert {s.key for s in small_val} <= {s.key for s in big_val}
    assert 4 <= len(big_val) <= 20, "about 30 % held out"


def test_training_subsets_are_nested_and_keep_the_data_order(tmp_path: Path):
    """Learning-curve points must train on growing versions of the same scenes."""
    more = make_dataset(tmp_path / "more", scenes=30)
    scenes, _ = load_scenes([more.root], N, 2.0, cache_root=tmp_path)
    keys = [s.key for s in scenes]
    subsets = {n: [s.key for s in subsample_scenes(scenes, n, seed=3)] for n in (5, 12, 30, 100)}
    assert [len(subsets[n]) for n in (5, 12, 30, 100)] == [5, 12, 30, 30]
    assert set(subsets[5]) < set(subsets[12]) < set(subsets[30]) == set(keys)
    assert subsets[12] == [k for k in keys if k in set(subsets[12])], "original order kept"
    assert subsets[12] != keys[:12], "a hash-chosen subset, not simply the first scenes"
    assert subsample_scenes(scenes, None, seed=3) == scenes
    with pytest.raises(ValueError, match="at least one scene"):
        subsample_scenes(scenes, 0, seed=3)


# Metrics ------------------------------------------------------------------------------------


def test_metrics_count_at_threshold_and_measure_errors():
    batch = small_batch()  # labels 1, 1, 0
    turned = Rotation.from_quat(batch.quaternion.numpy()) * Rotation.from_euler("x", np.radians(10))
    predictions = Predictions(
        quality=torch.tensor([0.95, 0.5, 0.92]),
        quaternion=torch.tensor(turned.as_quat(), dtype=torch.float32),
        width=batch.width + 2.0,
    )
    metrics = MetricAccumulator()
    metrics.update(predictions, batch, per_label_loss(predictions, batch))
    result = metrics.result()
    assert result["accuracy"] == pytest.approx(1 / 3)
    assert result["precision"] == pytest.approx(0.5) and result["recall"] == pytest.approx(0.5)
    assert result["rotation_error_deg"] == pytest.approx(10.0, abs=1e-3)
    assert result["width_error_mm"] == pytest.approx(2 * VOXEL * 1e3)
    assert float(rotation_error_deg(flipped(batch.quaternion), batch.quaternion).max()) < 0.1
    # On this mix (2 positives, 1 negative) and as it would be on balanced classes (TPR / (TPR + FPR)).
    assert result["curve"]["0.50"] == {
        "precision": pytest.approx(2 / 3),
        "recall": 1.0,
        "balanced_precision": 0.5,
    }
    assert result["curve"]["0.90"] == {
        "precision": 0.5,
        "recall": 0.5,
        "balanced_precision": pytest.approx(1 / 3),
    }
    losses = per_label_loss(predictions, batch)
    assert result["balanced_loss"] == pytest.approx(0.5 * (float(losses[:2].mean()) + float(losses[2])))
    assert MetricAccumulator().result()["precision"] is None


def test_the_progress_table_shows_the_loss_that_picks_the_best_epoch():
    """The best epoch is the one of least balanced validation loss: the table prints it."""
    entry = {
        "epoch": 2,
        "train": {"loss": 0.31},
        "val": {"loss": 0.2609, "balanced_loss": 0.4432},
        "seconds": 12.0,
    }
    titles, line = report.header(validation=True).split(), report.row(entry).split()
    assert "bal" in titles and "0.4432" in line and "0.2609" in line
    assert line.index("0.4432") == line.index("0.2609") + 1


def test_the_operating_threshold_is_chosen_on_the_real_mix():
    curve = {
        "0.50": {"precision": 0.40, "recall": 0.9, "balanced_precision": 0.85},
        "0.80": {"precision": 0.62, "recall": 0.5, "balanced_precision": 0.93},
        "0.90": {"precision": 0.81, "recall": 0.2, "balanced_precision": 0.97},
        "0.95": {"precision": None, "recall": 0.0, "balanced_precision": None},
    }
    chosen = choose_threshold(curve, target_precision=0.6)
    assert chosen["threshold"] == 0.8 and chosen["target_reached"], "lowest threshold with precision >= 0.6"
    assert choose_threshold(curve, 0.8)["threshold"] == 0.9, "balanced precision does not count"
    fallback = choose_threshold(curve, 0.99)
    assert fallback["threshold"] == 0.9 and not fallback["target_reached"], (
        "the most precise when none reaches"
    )


# The whole run ------------------------------------------------------------------------------


@pytest.fixture
def one_thread():
    """Torch on one thread: on a shared 2-core box, 2 OpenMP threads slow down ~4x when
    another process takes a core, and one thread costs little here."""
    threads = torch.get_num_threads()
    yield
    torch.set_num_threads(threads)


def test_train_resume_and_serve(dataset: RawDataset, tmp_path: Path, capsys, one_thread):
    out = tmp_path / "models" / "vgn.safetensors"
    base = ["--data", str(dataset.root), "--out", str(out), "--cache", str(tmp_path / "cache")]
    base += [
        "--batch-scenes",
        "2",
        "--val-fraction",
        "0.25",
        "--no-progress",
        "--lr",
        "1e-3",
        "--threads",
        "1",
    ]
    assert main([*base, "--epochs", "1"]) == 0
    card = json.loads(out.with_suffix(".card.json").read_text())
    training = card["training"]
    assert out.is_file() and card["epochs"] == 1 and training["train_scenes"] + training["val_scenes"] == 4
    assert card["datasets"][0]["scenes"] == 4 and card["datasets"][0]["positives"] == 12
    assert card["command"].startswith("vgn-train --data") and card["code_version"]["package"]
    first = card["history"][0]
    assert math.isfinite(first["train"]["loss"]) and math.isfinite(first["val"]["loss"])

    assert main([*base, "--epochs", "2"]) == 2, "an existing checkpoint needs --resume or --fresh"
    assert "--resume" in capsys.readouterr().err

    assert main([*base, "--epochs", "2", "--resume", "--seed", "5"]) == 2, "another run's checkpoint"
    assert "seed" in capsys.readouterr().err

    assert main([*base, "--epochs", "2", "--resume"]) == 0
    state = torch.load(checkpoint_path(out), weights_only=True)
    assert state["epoch"] == 2 and [e["epoch"] for e in state["history"]] == [1, 2]
    assert state["history"][0] == first, "resuming keeps the earlier epochs instead of restarting"
    card = json.loads(out.with_suffix(".card.json").read_text())
    losses = [e["train"]["loss"] for e in card["history"]]
    assert card["epochs"] == 2 and all(map(math.isfinite, losses)) and losses[-1] < losses[0]
    assert card["metrics"]["best"]["epoch"] in (1, 2) and card["metrics"]["final"]["epoch"] == 2
    assert "best epoch" in capsys.readouterr().out

    load_vgn(out)  # strict
    planner = GraspPlanner.from_path(out, device="cpu")
    assert planner.card is not None and planner.card["matches_weights"] and planner.card["epochs"] == 2
    choice = (
        planner.card["threshold_choice"] if "threshold_choice" in planner.card else card["threshold_choice"]
    )
    assert planner.default_threshold == card["threshold"] == choice["threshold"], "no --threshold: auto"
    assert "unbalanced" in choice["rule"] or "could not choose" in choice["rule"]
    assert card["training"]["copies_per_epoch"] == 1 and card["history"][-1]["steps"] >= 2
    assert out.with_suffix(".curves.png").is_file() and card["learning_curves"] == "vgn.curves.png"

    # Choosing the operating threshold afterwards rewrites the card, not the training.
    assert main([*base, "--epochs", "2", "--resume", "--threshold", "0.7"]) == 0
    rewritten = json.loads(out.with_suffix(".card.json").read_text())
    assert rewritten["threshold"] == 0.7 and rewritten["history"] == card["history"]
    assert GraspPlanner.from_path(out, device="cpu").default_threshold == 0.7
    assert planner.ready and planner.infer(np.zeros((N, N, N), np.float32)).quality.shape == (N, N, N)


def test_a_resumed_run_ends_where_an_uninterrupted_one_does(dataset: RawDataset, tmp_path: Path, one_thread):
    """Resuming restores the optimiser's moments, not only the weights (lose them and the
    third epoch drifts from the uninterrupted run's); order, augmentations and label subsets
    come from streams seeded by seed and epoch, so they repeat too."""

    def run(out: Path, *extra: str) -> int:
        args = ["--data", str(dataset.root), "--out", str(out), "--cache", str(tmp_path / "cache")]
        args += ["--batch-scenes", "1", "--val-fraction", "0.25", "--no-progress", "--threads", "1"]
        return main([*args, "--lr", "1e-3", "--threshold", "0.9", *extra])

    straight, resumed = tmp_path / "straight" / "vgn.safetensors", tmp_path / "resumed" / "vgn.safetensors"
    assert run(straight, "--epochs", "3") == 0
    assert run(resumed, "--epochs", "1") == 0
    assert run(resumed, "--epochs", "3", "--resume") == 0
    a = torch.load(checkpoint_path(straight), weights_only=True)
    b = torch.load(checkpoint_path(resumed), weights_only=True)
    assert a["epoch"] == b["epoch"] == 3
    for name, tensor in a["model"].items():
        assert torch.equal(tensor, b["model"][name]), f"{name} differs after resuming"
    losses = [[e["train"]["loss"] for e in state["history"]] for state in (a, b)]
    assert losses[0] == losses[1]


def test_fine_tuning_starts_from_the_given_weights(dataset: RawDataset, tmp_path: Path, capsys, one_thread):
    torch.manual_seed(3)
    start = tmp_path / "start.safetensors"
    save_vgn(VGN(), start)
    out = tmp_path / "tuned.safetensors"
    args = ["--data", str(dataset.root), "--out", str(out), "--cache", str(tmp_path / "cache")]
    args += ["--epochs", "1", "--val-fraction", "0", "--no-progress", "--threads", "1", "--threshold", "0.9"]

    assert main([*args, "--init", str(tmp_path / "missing.safetensors")]) == 2
    assert "--init" in capsys.readouterr().err
    not_vgn = tmp_path / "other.pt"
    torch.save({"weight": torch.zeros(3)}, not_vgn)
    assert main([*args, "--init", str(not_vgn)]) == 2
    assert "VGN" in capsys.readouterr().err

    assert main([*args, "--init", str(start), "--lr", "1e-9"]) == 0
    before, after = load_vgn(start).state_dict(), load_vgn(out).state_dict()
    drift = max(float((before[k] - after[k]).abs().max()) for k in before)
    assert drift < 1e-6, "a vanishing learning rate leaves the initial weights in place"
    init = json.loads(card_path(out).read_text())["training"]["init"]
    assert init["path"] == str(start) and init["weights_id"] == weights_id(start)

    random_start = tmp_path / "random.safetensors"
    assert main([*args, "--lr", "1e-9", "--out", str(random_start)]) == 0
    other = load_vgn(random_start).state_dict()
    assert max(float((before[k] - other[k]).abs().max()) for k in before) > 1e-3, "no --init: random weights"


def test_the_options_default_to_the_run_settings_defaults(tmp_path: Path):
    """One place for each default: what vgn-train does unasked is what TrainConfig says."""
    args = build_parser().parse_args(["--data", str(tmp_path), "--out", str(tmp_path / "w.safetensors")])
    from_cli, from_config = (
        config_from_args(args),
        TrainConfig(data=[tmp_path], out=tmp_path / "w.safetensors"),
    )
    for field in fields(TrainConfig):
        assert getattr(from_cli, field.name) == getattr(from_config, field.name), field.name


def test_card_summary_needs_a_card_that_belongs_to_the_weights(tmp_path: Path):
    weights = tmp_path / "vgn.safetensors"
    torch.manual_seed(0)
    save_vgn(VGN(), weights)
    assert card_summary(weights) is None, "weights without a card are fine, they just say nothing"
    card_path(weights).write_text("{not json")
    assert card_summary(weights) is None, "an unreadable card must not stop the service"
    card_path(weights).write_text(
        json.dumps({"model": {"weights_id": "0" * 12}, "datasets": [{"scenes": 3}]})
    )
    summary = card_summary(weights)
    assert summary is not None and summary["scenes"] == 3
    assert not summary["matches_weights"], "a card copied beside other weights is flagged"


def test_card_summary_reports_the_epoch_that_shipped_and_the_executed_grasps(tmp_path: Path):
    weights = tmp_path / "vgn.safetensors"
    torch.manual_seed(0)
    save_vgn(VGN(), weights)
    best = {"epoch": 2, "steps": 20, "val": {"loss": 0.3}}
    final = {"epoch": 3, "steps": 30, "val": {"loss": 0.4}}
    executed = {"settings": {"scene": "pile"}, "rounds": 5, "success_rate": 0.6, "outcomes": {"success": 3}}
    card = {"model": {"weights_id": weights_id(weights)}, "metrics": {"final": final, "best": best}}
    card_path(weights).write_text(json.dumps({**card, "executed_grasps": executed}))
    summary = card_summary(weights)
    assert summary is not None and summary["matches_weights"]
    assert (summary["epoch"], summary["steps"], summary["validation"]) == (2, 20, {"loss": 0.3})
    assert summary["executed_grasps"]["success_rate"] == 0.6
    assert summary["executed_grasps"]["settings"] == {"scene": "pile"}
    card_path(weights).write_text(json.dumps({**card, "metrics": {"final": final}}))
    summary = card_summary(weights)
    assert summary is not None and summary["epoch"] == 3, "older cards without a best epoch show the last"
    assert summary["executed_grasps"] is None
