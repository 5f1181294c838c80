"""Scenes of one or more raw VGN datasets as training samples: a grid plus all its labels.

VGN trained on one labelled voxel per sample; here a sample is a whole scene, so one
forward pass serves every labelled voxel of it. Scenes of a batch are stacked and their
labels concatenated with a scene index, which the loss uses to gather predictions.
"""

from __future__ import annotations

import hashlib
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from multiprocessing import get_context
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset
from tqdm import tqdm

from sim_worker.objects import default_cache_dir
from training.augment import Placement, balanced_subset, draw_height, draw_shift
from training.distill import SoftTargets
from training.grids import GridSource, cache_dir, cache_key, ensure_cached
from training.labels import LabelSet
from training.observations import ObservationSettings, open_cache, render_cache
from training.recipe_shards import RecipeFolder
from training.shards import ShardFolder, dequantize
from vgn_data.dataset import RawDataset
from vgn_data.files import remove_stale_temporaries


@dataclass(frozen=True, eq=False)
class PackedGrid:
    """A scene's grid from a packed shard: kept quantised in memory, dequantised on use."""

    quantised: np.ndarray

    def load(self) -> np.ndarray:
        """The grid as float32, dequantised from the shard's bytes."""
        return dequantize(self.quantised)

    def is_cached(self) -> bool:
        """Always: a packed grid needs no fusing (the ``GridSource`` interface)."""
        return True

    def build(self) -> np.ndarray:
        """The same as ``load``: there is nothing to fuse."""
        return self.load()


@dataclass(frozen=True, eq=False)
class RenderedObservations:
    """A recipe scene's cached observations (row ``row`` of a shard's memory-mapped
    (S, K, N, N, N) cache): ``load`` gives the first, ``draw`` one of the K at random."""

    grids: np.ndarray
    row: int

    def load(self) -> np.ndarray:
        """The first observation (the original one when the cache holds it), as float32."""
        return dequantize(np.asarray(self.grids[self.row, 0]))

    def draw(self, rng: np.random.Generator) -> np.ndarray:
        """One of the scene's observations, drawn uniformly, as float32."""
        return dequantize(np.asarray(self.grids[self.row, int(rng.integers(self.grids.shape[1]))]))

    def is_cached(self) -> bool:
        """Always: the cache was rendered before training (``vgn-data render``)."""
        return True

    def build(self) -> np.ndarray:
        """The same as ``load``."""
        return self.load()


@dataclass(frozen=True)
class Scene:
    """One scene: where its grid comes from and its labels (voxel units)."""

    dataset: int
    scene_id: str
    source: GridSource | PackedGrid | RenderedObservations
    labels: LabelSet
    voxel_size: float

    @property
    def key(self) -> str:
        """Unique across the datasets of a run: ``<dataset index>/<scene id>``."""
        return f"{self.dataset}/{self.scene_id}"


@dataclass
class DatasetSummary:
    """What one raw dataset contributed, for logs and the model card."""

    path: str
    size: float
    scenes: int
    grasps: int
    positives: int
    negatives: int
    outside_grid: int
    scenes_without_labels: int
    missing_scene_files: int
    cache: str
    #: The version of the hand that labelled it (generation.json's or the manifest's ``gripper``);
    #: ``None``: not recorded (data made elsewhere).
    gripper: str | None = None

    def count(self, labels: LabelSet) -> None:
        """Count one scene that trains, with its labels."""
        positives = int(labels.label.sum())
        self.scenes += 1
        self.grasps += len(labels)
        self.positives += positives
        self.negatives += len(labels) - positives

    def as_dict(self) -> dict:
        """The summary as JSON-ready fields for the model card."""
        return asdict(self)


def load_scenes(
    data_dirs: list[Path],
    resolution: int,
    max_depth: float,
    cache_root: Path | None = None,
    observations: ObservationSettings | None = None,
    workers: int = 0,
    progress: bool = False,
    sources: tuple[str, ...] | None = None,
) -> tuple[list[Scene], list[DatasetSummary]]:
    """Scenes with at least one label inside the grid, in a stable order, and per-dataset counts.

    A folder is a raw dataset, a folder of scene recipes (``manifest.json`` format 2: the
    observations ``observations`` asks for are rendered into ``cache_root`` first, where
    missing) or of grid shards (format 1; its grids were fused when packed). ``sources``: of a
    recipe folder only these streams of scenes (``ValueError`` for a name no recipe folder has).
    Raises ``FileNotFoundError`` for a folder that is none of them.
    """
    scenes: list[Scene] = []
    summaries: list[DatasetSummary] = []
    found: set[str] = set()
    for index, data_dir in enumerate(data_dirs):
        if RecipeFolder(Path(data_dir)).exists():
            settings = observations or ObservationSettings()
            rendered, summary, names = _load_recipes(index, Path(data_dir), resolution, max_depth, settings,
                                                     cache_root, workers, progress, sources)  # fmt: skip
            scenes += rendered
            summaries.append(summary)
            found |= names
            continue
        if ShardFolder(Path(data_dir)).exists():
            packed, summary = _load_packed(index, Path(data_dir), resolution, max_depth)
            scenes += packed
            summaries.append(summary)
            continue
        dataset = RawDataset(Path(data_dir))
        setup = dataset.setup
        voxel_size = setup.size / resolution
        key = cache_key(setup, resolution, max_depth)
        grids_dir = cache_dir(dataset.root, cache_root, resolution, key)
        ids, rows = dataset.grasps()
        summary = DatasetSummary(str(dataset.root.resolve()), setup.size, 0, 0, 0, 0, 0, 0, 0, str(grids_dir),
                                 gripper=dataset.generation().get("gripper"))  # fmt: skip
        for scene_id, scene_rows in _group_rows(ids, rows):
            if not (dataset.scenes_dir / f"{scene_id}.npz").is_file():
                summary.missing_scene_files += 1
                continue
            labels = _admit(summary, scene_rows, voxel_size, resolution)
            if labels is None:
                continue
            source = GridSource(dataset, scene_id, grids_dir / f"{scene_id}.npz", resolution, max_depth, key)
            scenes.append(Scene(index, scene_id, source, labels, voxel_size))
        summaries.append(summary)
    missing = sorted(set(sources or ()) - found)
    if missing:
        raise ValueError(f"no recipe folder among {', '.join(map(str, data_dirs))} has the source(s) "
                         f"{', '.join(missing)}; it has: {', '.join(sorted(found)) or 'none'}")  # fmt: skip
    return scenes, summaries


def _check_grid(folder: Path, manifest: dict, resolution: int, max_depth: float) -> None:
    """Refuse a folder whose data was made for another grid or depth cut-off than this run's."""
    if manifest["resolution"] != resolution or manifest["max_depth"] != max_depth:
        raise ValueError(
            f"{folder} holds data for resolution {manifest['resolution']} and depth cut-off "
            f"{manifest['max_depth']} m; this run asks for {resolution} and {max_depth} m"
        )


def _admit(summary: DatasetSummary, rows: np.ndarray, voxel_size: float, resolution: int) -> LabelSet | None:
    """A scene's labels inside the grid, counted in ``summary``; None (counted too) when none are."""
    labels, outside = LabelSet.from_rows(rows, voxel_size, resolution)
    summary.outside_grid += outside
    if not len(labels):
        summary.scenes_without_labels += 1
        return None
    summary.count(labels)
    return labels


def _load_packed(
    index: int, folder: Path, resolution: int, max_depth: float
) -> tuple[list[Scene], DatasetSummary]:
    """Scenes of a shard folder (every shard's sha256 checked) and its counts."""
    shards = ShardFolder(folder)
    manifest = shards.manifest()
    _check_grid(folder, manifest, resolution, max_depth)
    size = float(manifest["setup"]["size"])
    voxel_size = size / resolution
    summary = DatasetSummary(str(folder.resolve()), size, 0, 0, 0, 0, 0, 0, 0, "packed shards",
                             gripper=manifest.get("gripper"))  # fmt: skip
    scenes: list[Scene] = []
    for shard in shards.load(verify=True):
        for scene_id, grid, rows in zip(shard.scene_ids, shard.grids, shard.rows_by_scene(), strict=True):
            labels = _admit(summary, rows, voxel_size, resolution)
            if labels is not None:
                scenes.append(Scene(index, str(scene_id), PackedGrid(grid), labels, voxel_size))
    return scenes, summary


def _load_recipes(
    index: int,
    folder: Path,
    resolution: int,
    max_depth: float,
    settings: ObservationSettings,
    cache_root: Path | None,
    workers: int,
    progress: bool,
    sources: tuple[str, ...] | None = None,
) -> tuple[list[Scene], DatasetSummary, set[str]]:
    """Scenes of a recipe folder (of ``sources``, or all) with their rendered observations (rendered
    now where missing), and the names of every source the folder has."""
    recipes = RecipeFolder(folder)
    manifest = recipes.manifest()
    _check_grid(folder, manifest, resolution, max_depth)
    shards = recipes.load(verify=True)
    names = {shard.source for shard in shards}
    shards = [shard for shard in shards if sources is None or shard.source in sources]
    cache = Path(cache_root) if cache_root is not None else default_cache_dir() / "observations"
    bar = tqdm(total=sum(len(shard.scene_ids) for shard in shards), desc="observations", unit="scene",
               disable=not progress, leave=False)  # fmt: skip
    try:
        paths = render_cache(folder, cache, settings, max(1, workers), progress=bar.update, shards=shards)
    finally:
        bar.close()
    size = float(manifest["setup"]["size"])
    voxel_size = size / resolution
    summary = DatasetSummary(str(folder.resolve()), size, 0, 0, 0, 0, 0, 0, 0, str(cache),
                             gripper=manifest.get("gripper"))  # fmt: skip
    scenes: list[Scene] = []
    for shard, path in zip(shards, paths, strict=True):
        grids = open_cache(path, len(shard.scene_ids), settings)
        for row, (scene_id, rows) in enumerate(zip(shard.scene_ids, shard.labels_by_scene(), strict=True)):
            labels = _admit(summary, rows, voxel_size, resolution)
            if labels is not None:
                scenes.append(Scene(index, scene_id, RenderedObservations(grids, row), labels, voxel_size))
    return scenes, summary, names


def _group_rows(ids: list[str], rows: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """Rows of each scene id, ids sorted."""
    if not ids:
        return []
    names, inverse = np.unique(np.asarray(ids), return_inverse=True)
    order = np.argsort(inverse, kind="stable")
    bounds = np.searchsorted(inverse[order], np.arange(len(names) + 1))
    return [(str(name), rows[order[bounds[n] : bounds[n + 1]]]) for n, name in enumerate(names)]


def split_scenes(scenes: list[Scene], val_fraction: float, seed: int) -> tuple[list[Scene], list[Scene]]:
    """Train and validation scenes, split by scene (never by grasp) and fixed by ``seed``.

    A scene is held out when a hash of (seed, its key) falls below ``val_fraction``, so the
    choice does not depend on the other scenes: a dataset that grows keeps its old split.
    At least one scene is held out when ``val_fraction`` > 0 and there are two or more.
    """
    if not 0.0 <= val_fraction < 1.0:
        raise ValueError(f"val_fraction must be in [0, 1), got {val_fraction}")
    draws = [_uniform_hash(seed, scene.key) for scene in scenes]
    held_out = [draw < val_fraction for draw in draws]
    if val_fraction > 0 and len(scenes) >= 2 and not any(held_out):
        held_out[int(np.argmin(draws))] = True
    train = [s for s, out in zip(scenes, held_out, strict=True) if not out]
    val = [s for s, out in zip(scenes, held_out, strict=True) if out]
    return train, val


def subsample_scenes(scenes: list[Scene], count: int | None, seed: int) -> list[Scene]:
    """The ``count`` scenes with the lowest hash of (seed, key), in their original order.

    Subsets are nested: the scenes kept at one size are kept at every larger size, and a scene
    added to the dataset later joins only where its hash ranks, so learning curves over
    dataset sizes compare growing versions of the same data.
    """
    if count is None or count >= len(scenes):
        return list(scenes)
    if count < 1:
        raise ValueError(f"a training subset needs at least one scene, got {count}")
    ranks = sorted(range(len(scenes)), key=lambda n: _uniform_hash(seed + 1, scenes[n].key))
    kept = set(ranks[:count])
    return [scene for n, scene in enumerate(scenes) if n in kept]


def _uniform_hash(seed: int, key: str) -> float:
    """A number in [0, 1) fixed by (seed, key), uniform over keys."""
    digest = hashlib.sha256(f"{seed}:{key}".encode()).digest()
    return int.from_bytes(digest[:8], "big") / 2**64


def prepare_grids(scenes: list[Scene], workers: int = 0, progress: bool = True) -> int:
    """Fuse and cache every grid not cached yet; returns how many were built.

    With ``workers`` > 0 the fusion runs in that many spawned processes (Open3D and torch
    do not like being forked mid-run).
    """
    sources = [scene.source for scene in scenes if isinstance(scene.source, GridSource)]
    for folder in {source.cache_path.parent for source in sources}:
        remove_stale_temporaries(folder, recursive=False)
    bar = tqdm(total=len(sources), desc="grids", unit="scene", disable=not progress, leave=False)
    built = 0
    if workers > 0 and len(sources) > 1:
        with ProcessPoolExecutor(workers, mp_context=get_context("spawn")) as pool:
            for was_built in pool.map(ensure_cached, sources, chunksize=8):
                built += was_built
                bar.update()
    else:
        for source in sources:
            built += ensure_cached(source)
            bar.update()
    bar.close()
    return built


@dataclass
class Sample:
    """One scene drawn for a batch: its (possibly augmented) grid, labels and voxel size in
    metres, and the teacher's soft labels placed the same way when distilling."""

    grid: torch.Tensor
    labels: LabelSet
    voxel_size: float
    soft: LabelSet | None = None


class SceneDataset(Dataset[Sample]):
    """Scenes as (grid, labels) samples, each scene ``copies`` times per epoch.

    Every draw is fixed by (seed, epoch, index), so runs and resumes repeat exactly. With
    ``balance`` a draw keeps all positives and as many random negatives; ``augment`` is
    ``"height"`` (a quarter-turn and a random height over the label-preserving range, VGN's),
    ``"shift"`` (a quarter-turn and a ±4 voxel shift) or ``None``. ``soft`` (one per scene)
    adds ``soft_per_draw`` of a teacher's soft labels to every draw, moved with the grid. With
    ``fresh_observations`` a recipe scene shows one of its rendered observations at random at
    every draw (else always its first).
    """

    def __init__(
        self,
        scenes: list[Scene],
        augment: str | None,
        seed: int,
        copies: int = 1,
        balance: bool = False,
        soft: list[SoftTargets] | None = None,
        soft_per_draw: int = 512,
        fresh_observations: bool = False,
    ) -> None:
        if augment not in (None, "height", "shift"):
            raise ValueError(f"augment must be 'height', 'shift' or None, got {augment!r}")
        if soft is not None and len(soft) != len(scenes):
            raise ValueError(f"{len(soft)} soft targets for {len(scenes)} scenes")
        self.scenes = scenes
        self.augment = augment
        self.seed = seed
        self.copies = copies
        self.balance = balance
        self.soft = soft
        self.soft_per_draw = soft_per_draw
        self.fresh_observations = fresh_observations
        self.epoch = 0

    def __len__(self) -> int:
        return len(self.scenes) * self.copies

    def __getitem__(self, index: int) -> Sample:
        scene_index = index % len(self.scenes)
        scene = self.scenes[scene_index]
        rng = np.random.default_rng([self.seed, self.epoch, index])
        if self.fresh_observations and isinstance(scene.source, RenderedObservations):
            grid = torch.from_numpy(
                scene.source.draw(np.random.default_rng([self.seed, self.epoch, index, 1]))
            )
        else:
            grid = torch.from_numpy(scene.source.load())
        labels = scene.labels
        if not (self.augment or self.balance or self.soft is not None):
            return Sample(grid, labels, scene.voxel_size)
        if self.balance:
            labels = balanced_subset(labels, rng)
        placement: Placement | None = None
        if self.augment == "height":
            placement = draw_height(labels, grid.shape[2], rng)
        elif self.augment == "shift":
            placement = draw_shift(rng)
        if placement is not None:
            grid, labels = placement.apply(grid, labels)
        soft = None
        if self.soft is not None:
            soft = self.soft[scene_index].draw(self.soft_per_draw, rng)
            if placement is not None:
                soft = placement.apply_labels(soft, grid.shape[0])
        return Sample(grid, labels, scene.voxel_size, soft)


@dataclass
class Batch:
    """Scenes stacked for one forward pass and their labels flattened.

    grids (B, 1, N, N, N); per label: scene (L,) index into the batch, voxel (L,) flat index
    into N³, quaternion (L, 4), width (L,) voxels, label (L,), voxel_size (L,) metres. The
    ``soft_*`` fields hold a teacher's soft labels the same way (K of them; empty when the
    run does not distil): scene, flat voxel, quality, quaternion, width.
    """

    grids: torch.Tensor
    scene: torch.Tensor
    voxel: torch.Tensor
    quaternion: torch.Tensor
    width: torch.Tensor
    label: torch.Tensor
    voxel_size: torch.Tensor
    soft_scene: torch.Tensor
    soft_voxel: torch.Tensor
    soft_quality: torch.Tensor
    soft_quaternion: torch.Tensor
    soft_width: torch.Tensor

    def __len__(self) -> int:
        """Number of labels."""
        return int(self.scene.shape[0])

    def pin_memory(self) -> Batch:
        """Page-locked copies, so ``to(cuda)`` can overlap with compute (DataLoader calls this)."""
        return Batch(*(getattr(self, name).pin_memory() for name in self.__dataclass_fields__))

    def to(self, device: torch.device) -> Batch:
        """The batch on ``device``; non-blocking, so a pinned batch copies while the GPU computes."""
        return Batch(
            *(getattr(self, name).to(device, non_blocking=True) for name in self.__dataclass_fields__)
        )


def _flatten(label_sets: list[LabelSet], n: int) -> tuple[torch.Tensor, torch.Tensor]:
    """(scene index, flat voxel index into N³) of every label of the batch's label sets."""
    scene = torch.cat([torch.full((len(s),), b, dtype=torch.long) for b, s in enumerate(label_sets)])
    voxel = torch.cat([s.voxel for s in label_sets])
    return scene, (voxel[:, 0] * n + voxel[:, 1]) * n + voxel[:, 2]


def collate(samples: list[Sample]) -> Batch:
    """Stack grids and concatenate labels with the index tensors the loss gathers with."""
    n = samples[0].grid.shape[0]
    grids = torch.stack([s.grid for s in samples])[:, None]
    scene, flat = _flatten([s.labels for s in samples], n)
    soft = [s.soft if s.soft is not None else _NO_LABELS for s in samples]
    soft_scene, soft_flat = _flatten(soft, n)
    return Batch(
        grids=grids.contiguous(),
        scene=scene,
        voxel=flat,
        quaternion=torch.cat([s.labels.quaternion for s in samples]),
        width=torch.cat([s.labels.width for s in samples]),
        label=torch.cat([s.labels.label for s in samples]),
        voxel_size=torch.cat(
            [torch.full((len(s.labels),), s.voxel_size, dtype=torch.float32) for s in samples]
        ),
        soft_scene=soft_scene,
        soft_voxel=soft_flat,
        soft_quality=torch.cat([s.label for s in soft]),
        soft_quaternion=torch.cat([s.quaternion for s in soft]),
        soft_width=torch.cat([s.width for s in soft]),
    )


#: The soft labels of a draw without a teacher.
_NO_LABELS = LabelSet(
    voxel=torch.zeros((0, 3), dtype=torch.long),
    quaternion=torch.zeros((0, 4)),
    width=torch.zeros(0),
    label=torch.zeros(0),
)


def make_loader(
    dataset: SceneDataset, batch_scenes: int, shuffle: bool, epoch: int, workers: int = 0
) -> DataLoader:
    """Batches of ``batch_scenes`` scenes; the order is fixed by (seed, epoch)."""
    dataset.epoch = epoch
    order = list(range(len(dataset)))
    if shuffle:
        order = np.random.default_rng([dataset.seed, epoch]).permutation(len(dataset)).tolist()
    return DataLoader(
        dataset,
        batch_size=batch_scenes,
        sampler=order,
        collate_fn=collate,
        num_workers=workers,
        pin_memory=torch.cuda.is_available(),
    )
