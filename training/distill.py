"""Self-distillation of turn averaging: a trained model's turn-averaged output as dense soft targets.

Turn averaging (``service.vgn.turns``) makes a model's grasps markedly better, at four forward
passes a request; training a network to give that answer in one pass moves the gain into the
weights. The teacher is a trained model run on each training scene turned four ways; its
averaged quality, orientation and width become soft labels at every voxel where detection may
place a grasp (``grasp_region``), moved with the training augmentation like trial labels. With
``checks`` a grasp that fails the service's clearance or grip check gets quality 0, as the
service would drop it (each grasp judged alone; both checks read only the grid). Working the
targets out takes long on a large dataset, so a run saves them beside its checkpoint and a
resume reads them back while nothing they depend on changed (:func:`teaching_key`).
"""

from __future__ import annotations

import hashlib
import json
import multiprocessing
import zipfile
from collections import deque
from collections.abc import Iterable, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass
from itertools import pairwise
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from service.checks import passes_checks
from service.grid_surface import grid_surface_points
from service.planner import GraspPlanner, InferenceOptions
from service.vgn.checkpoint import weights_id
from service.vgn.detection import grasp_region
from training.labels import LabelSet
from vgn_data.files import atomic_writer


@dataclass(frozen=True)
class SoftTargets:
    """One scene's teacher answer at its grasp-region voxels, kept compact in memory.

    voxel (K, 3) uint8 grid indices; quality (K,) float16 in [0, 1]; quaternion (K, 4)
    float16 ``[x, y, z, w]``; width (K,) float16 in voxels.
    """

    voxel: np.ndarray
    quality: np.ndarray
    quaternion: np.ndarray
    width: np.ndarray

    def __len__(self) -> int:
        return int(self.voxel.shape[0])

    def draw(self, count: int, rng: np.random.Generator) -> LabelSet:
        """``count`` of the targets drawn without replacement (all when fewer), as a label set
        whose ``label`` is the teacher's soft quality."""
        chosen = np.sort(rng.permutation(len(self))[:count]) if count < len(self) else np.arange(len(self))
        quaternion = torch.from_numpy(self.quaternion[chosen].astype(np.float32))
        return LabelSet(
            voxel=torch.from_numpy(self.voxel[chosen].astype(np.int64)),
            quaternion=quaternion / quaternion.norm(dim=-1, keepdim=True),
            width=torch.from_numpy(self.width[chosen].astype(np.float32)),
            label=torch.from_numpy(self.quality[chosen].astype(np.float32)),
        )


#: Teacher qualities below this are not checked: such grasps stay far under any threshold, and
#: the checks' cost grows with the number of grasps.
CHECKED_QUALITY = 0.5


def soft_targets(teacher: GraspPlanner, grid: np.ndarray, voxel_size: float | None = None) -> SoftTargets:
    """The teacher's turn-averaged answer for one (N, N, N) grid at its grasp-region voxels;
    with ``voxel_size`` (m) quality is 0 where the clearance or grip check fails."""
    answer = turned_answer(teacher, grid)
    if voxel_size is not None:
        answer = answer.checked(failing_checks(grid, voxel_size, *answer.checked_inputs()))
    return answer.compact()


@dataclass(frozen=True)
class TurnedAnswer:
    """The teacher's turn-averaged answer at a grid's grasp-region voxels in full precision, as
    the checks read it, before it is made compact."""

    voxel: np.ndarray
    quality: np.ndarray
    quaternion: np.ndarray
    width: np.ndarray

    def checked_inputs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What :func:`failing_checks` reads after the grid and voxel size."""
        return self.voxel, self.quaternion, self.quality

    def checked(self, failing: np.ndarray) -> TurnedAnswer:
        """The answer with quality 0 where ``failing``."""
        return TurnedAnswer(self.voxel, np.where(failing, 0.0, self.quality), self.quaternion, self.width)

    def compact(self) -> SoftTargets:
        """The answer as stored for training: uint8 voxels, float16 values."""
        return SoftTargets(
            voxel=self.voxel.astype(np.uint8),
            quality=self.quality.astype(np.float16),
            quaternion=self.quaternion.astype(np.float16),
            width=self.width.astype(np.float16),
        )


def turned_answer(teacher: GraspPlanner, grid: np.ndarray) -> TurnedAnswer:
    """The teacher's turn-averaged quality, orientation and width at ``grid``'s grasp region."""
    output = teacher.infer(grid, turn_average=True)
    region = grasp_region(grid)
    voxel = np.argwhere(region)
    index = tuple(voxel.T)
    rotation = output.rotation_where(region)
    return TurnedAnswer(voxel, output.quality[index], rotation[(slice(None), *index)].T, output.width[index])


def failing_checks(
    grid: np.ndarray, voxel_size: float, voxel: np.ndarray, quaternion: np.ndarray, quality: np.ndarray
) -> np.ndarray:
    """(K,) bool: which grasps at ``voxel`` (K, 3) with orientations ``quaternion`` (K, 4,
    workspace frame) the service's clearance or grip check would drop; only those with
    ``quality`` of at least :data:`CHECKED_QUALITY` are checked."""
    failing = np.zeros(len(voxel), dtype=bool)
    checked = np.flatnonzero(quality >= CHECKED_QUALITY)
    if not len(checked):
        return failing
    positions = voxel[checked] * voxel_size  # grasp positions sit at index x voxel (docs/conventions.md)
    orientations = quaternion[checked].astype(np.float64)
    surface = grid_surface_points(grid, voxel_size)  # the grid is the workspace: its frame is the world's
    size = grid.shape[0] * voxel_size
    failing[checked] = ~passes_checks(positions, orientations, surface, grid, voxel_size, np.eye(4), size)
    return failing


def teach(
    weights: Path,
    grids: Sequence[object],
    device: str,
    progress: bool = True,
    voxel_sizes: Sequence[float] | None = None,
    workers: int = 0,
) -> list[SoftTargets]:
    """Soft targets of every scene from the weights at ``weights``, run as the service runs them
    (the fast form, in float32); ``grids`` are sources with ``load() -> (N, N, N) array``. With
    ``voxel_sizes`` (one per grid) the targets carry the clearance and grip checks; with
    ``workers`` >= 2 the checks, ten times the network's cost on a CPU, run in that many
    processes while the network answers the next scenes."""
    teacher = GraspPlanner.from_path(
        weights, device, InferenceOptions(precision="float32", batch_window_ms=0.0)
    )
    bar = tqdm(grids, desc="teacher", unit="scene", disable=not progress, leave=False)
    sizes = [None] * len(grids) if voxel_sizes is None else list(voxel_sizes)
    if len(sizes) != len(grids):
        raise ValueError(f"{len(grids)} grids but {len(sizes)} voxel sizes")
    if voxel_sizes is None or workers < 2:
        return [soft_targets(teacher, source.load(), size) for source, size in zip(bar, sizes, strict=True)]
    return _teach_checked_in_parallel(teacher, bar, sizes, workers)


def _teach_checked_in_parallel(
    teacher: GraspPlanner, grids: Iterable[object], sizes: list[float], workers: int
) -> list[SoftTargets]:
    """:func:`soft_targets` with checks for every grid, the checks in ``workers`` processes (spawned:
    the teacher may hold a GPU, which a forked process must not touch). At most a few scenes per
    process wait at a time, so the grids in flight stay few."""
    targets: list[SoftTargets] = []
    pending: deque[tuple[TurnedAnswer, Future[np.ndarray]]] = deque()
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(workers, mp_context=context) as pool:
        for source, size in zip(grids, sizes, strict=True):
            grid = source.load()
            answer = turned_answer(teacher, grid)
            pending.append((answer, pool.submit(failing_checks, grid, size, *answer.checked_inputs())))
            while len(pending) > 4 * workers or (pending and pending[0][1].done()):
                answer, failing = pending.popleft()
                targets.append(answer.checked(failing.result()).compact())
        targets.extend(answer.checked(failing.result()).compact() for answer, failing in pending)
    return targets


#: Bump when what a teacher's soft targets mean changes (the turn averaging, the checks, the
#: grasp region), so that saved targets stop matching.
TARGETS_FORMAT = 2


def teaching_key(weights: Path, grids: Sequence[object], voxel_sizes: Sequence[float] | None = None) -> str:
    """Hash of everything :func:`teach` reads: the teacher's weights, every grid's content in
    order, the voxel sizes the checks use, and :data:`TARGETS_FORMAT`. Reading each grid costs
    seconds where teaching costs minutes."""
    sizes = None if voxel_sizes is None else [float(size) for size in voxel_sizes]
    settings = {"format": TARGETS_FORMAT, "teacher": weights_id(Path(weights)),
                "checked_quality": CHECKED_QUALITY, "voxel_sizes": sizes}  # fmt: skip
    digest = hashlib.sha256()
    digest.update(json.dumps(settings, sort_keys=True).encode())
    for source in grids:
        digest.update(np.ascontiguousarray(source.load(), dtype=np.float32).tobytes())
    return digest.hexdigest()


def save_targets(path: Path, key: str, targets: Sequence[SoftTargets]) -> None:
    """Write every scene's targets to one file (atomically), under ``key``."""
    with atomic_writer(path) as stream:
        np.savez(
            stream,
            key=np.array(key),
            counts=np.array([len(target) for target in targets], dtype=np.int64),
            voxel=_joined([target.voxel for target in targets], (0, 3), np.uint8),
            quality=_joined([target.quality for target in targets], (0,), np.float16),
            quaternion=_joined([target.quaternion for target in targets], (0, 4), np.float16),
            width=_joined([target.width for target in targets], (0,), np.float16),
        )


def load_targets(path: Path, key: str) -> list[SoftTargets] | None:
    """The targets saved at ``path`` when they were saved under ``key``; None when the file is
    missing, damaged or was made from another teacher or other grids."""
    try:
        with np.load(path) as data:
            if str(data["key"]) != key:
                return None
            counts = data["counts"]
            arrays = [data[name] for name in ("voxel", "quality", "quaternion", "width")]
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return None
    bounds = np.concatenate([[0], np.cumsum(counts)])
    if any(len(array) != bounds[-1] for array in arrays):
        return None
    voxel, quality, quaternion, width = arrays
    return [
        SoftTargets(voxel[start:end], quality[start:end], quaternion[start:end], width[start:end])
        for start, end in pairwise(bounds.tolist())
    ]


def _joined(parts: list[np.ndarray], empty: tuple[int, ...], dtype: type) -> np.ndarray:
    return np.concatenate(parts) if parts else np.zeros(empty, dtype=dtype)
