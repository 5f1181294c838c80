"""Turn averaging: VGN's grasp quality and orientation averaged over the grid turned about gravity.

VGN trains with the scene turned by quarter turns about the workspace z axis, so a well
trained network scores and orients a grasp the same whichever way the scene is turned; where
it does not, the four answers disagree and their mean is the steadier estimate. Turning the
grid is ``np.rot90`` over its x, y axes. Network outputs sit at grasp positions ``index × voxel``
(docs/conventions.md), which a quarter turn about the workspace centre takes from (i, j) to
(N - j, i): one index away from where ``rot90`` moves the grid's cells, the same rule the
training augmentation applies to its labels. Voxels that a turn takes off the grid (a row;
for the half turn a row and a column) keep the answers of the turns that keep them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol

import numpy as np


class RotationReader(Protocol):
    """Orientations of one grid that are computed where they are read, not stored whole."""

    def rotation_at(self, i: np.ndarray, j: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """(4, M) unit quaternions ``[x, y, z, w]`` at the M voxels (i, j, depth)."""
        ...


#: One grid's orientations: a (4, N, N, N) array, or a reader that computes them on demand.
RotationField = np.ndarray | RotationReader


def rotations_at(field: RotationField, i: np.ndarray, j: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """(4, M) orientations of ``field`` at the M voxels (i, j, depth)."""
    if isinstance(field, np.ndarray):
        return field[:, i, j, depth]
    return field.rotation_at(i, j, depth)


#: Quarter turns about +z whose network outputs are averaged: 0°, 90°, 180°, 270°.
TURNS = (0, 1, 2, 3)


def turned_grids(grid: np.ndarray) -> np.ndarray:
    """(4, N, N, N): ``grid`` turned by each of :data:`TURNS` quarter turns about +z."""
    return np.stack([np.rot90(grid, k, axes=(0, 1)) for k in TURNS])


def turned_index(n: int, quarter_turns: int) -> tuple[np.ndarray, np.ndarray]:
    """Where each grasp position (i, j) of an N-wide grid lands after ``quarter_turns``
    quarter turns about +z: two (N, N) index arrays, values outside [0, N) off the grid."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    for _ in range(quarter_turns % 4):
        i, j = n - j, i
    return i, j


def _turned_view(field: np.ndarray, quarter_turns: int) -> tuple[tuple[slice, slice], np.ndarray]:
    """Where an (N, N, N) output of the grid turned by ``quarter_turns`` lands in the unturned
    grasp positions: the (i, j) region the turn keeps on the grid, and a view of ``field``
    holding those positions' values in the region's order."""
    # The slices below are turned_index's rule, (i, j) -> (N - j, i) per quarter turn, as views
    # (4x faster than gathering with the index arrays); the tests check them against it.
    n = field.shape[0]
    every, rest = slice(None), slice(1, None)
    reverse = slice(n - 1, 0, -1)  # field rows N-1 .. 1, read for i (or j) = 1 .. N-1
    turns = quarter_turns % 4
    if turns == 0:
        return (every, every), field
    if turns == 1:  # values[i, j] = field[N - j, i], j >= 1
        return (every, rest), field[reverse].swapaxes(0, 1)
    if turns == 2:  # values[i, j] = field[N - i, N - j], i, j >= 1
        return (rest, rest), field[reverse, reverse]
    return (rest, every), field[:, reverse].swapaxes(0, 1)  # values[i, j] = field[j, N - i], i >= 1


def average_turned_quality(qualities: Sequence[np.ndarray]) -> np.ndarray:
    """(N, N, N) mean quality, in the unturned grid's voxels, of the four (N, N, N) network
    qualities on :func:`turned_grids` (each voxel averages the turns that keep it on the grid)."""
    first = qualities[0]
    total = np.zeros(first.shape, dtype=np.float64)
    count = np.zeros(first.shape[:2] + (1,), dtype=np.float64)
    for k, quality in zip(TURNS, qualities, strict=True):
        region, view = _turned_view(quality, k)
        total[region] += view  # added in place, without a zero-filled copy of each turn
        count[region] += 1.0
    return (total / count).astype(first.dtype)


def average_turned_rotation(
    rotations: Sequence[RotationField], where: np.ndarray | None = None, n: int | None = None
) -> np.ndarray:
    """(4, N, N, N) mean grasp orientation, in the unturned grid's frame and voxels, of the
    four network rotations (quaternions ``[x, y, z, w]``) on :func:`turned_grids`, each an
    array or read on demand (``n``, the grid's width, is needed when the first is read so).

    Each turn's quaternion is read at the turned grasp position and turned back about z. A
    quaternion and its negative are one rotation, and a grasp turned by π about its approach is
    the same grasp, so each is first replaced by whichever of those four forms lies nearest the
    unturned grid's own prediction; the mean of the aligned forms, normalised, is the result.

    ``where`` ((N, N, N) bool) limits the averaging to those voxels, e.g. the ones detection
    reads: elsewhere the result is the unturned grid's prediction when that is an array, and
    zero otherwise.
    """
    reference = rotations[0]
    if isinstance(reference, np.ndarray):
        n = reference.shape[-1]
    elif n is None:
        raise ValueError("the grid's width n is needed when the unturned rotations are read on demand")
    shape = (n, n, n)
    i, j, depth = np.nonzero(np.ones(shape, dtype=bool) if where is None else where)
    chosen_reference = rotations_at(reference, i, j, depth).astype(np.float32, copy=False)
    total = chosen_reference.copy()
    for k, field in zip(TURNS[1:], rotations[1:], strict=True):
        turned_i, turned_j = (index[i, j] for index in turned_index(n, k))
        on_grid = (turned_i >= 0) & (turned_i < n) & (turned_j >= 0) & (turned_j < n)
        turned = np.zeros_like(chosen_reference)
        turned[:, on_grid] = rotations_at(field, turned_i[on_grid], turned_j[on_grid], depth[on_grid])
        total += _aligned_back(turned, chosen_reference, k)
    if isinstance(reference, np.ndarray):
        averaged = reference.copy()
    else:
        averaged = np.zeros((4, *shape), dtype=np.float32)
    averaged[:, i, j, depth] = total / np.maximum(np.linalg.norm(total, axis=0), 1e-12)
    return averaged


def _aligned_back(turned: np.ndarray, reference: np.ndarray, quarter_turns: int) -> np.ndarray:
    """Quaternions (4, ...) of the grid turned by ``quarter_turns``, already read at the
    reference's positions (zeros where off the grid, which then add nothing), turned back about
    z and put in the form (sign, and π about the approach) nearest ``reference``. The two
    quaternion products are written out in numpy (faster here than the training's torch
    helpers in ``training.quaternions``, which the tests check them against)."""
    x, y, z, w = turned
    # Turned back: about_z(-k π/2) ⊗ q, written out (the rotation has only z and w parts).
    sine, cosine = math.sin(-quarter_turns * math.pi / 4), math.cos(-quarter_turns * math.pi / 4)
    back = np.stack(
        [cosine * x - sine * y, cosine * y + sine * x, cosine * z + sine * w, cosine * w - sine * z]
    )
    turned_about_approach = np.stack([back[1], -back[0], back[3], -back[2]])  # back ⊗ [0, 0, 1, 0]
    plain_agreement = np.einsum("q...,q...->...", back, reference)
    turned_agreement = np.einsum("q...,q...->...", turned_about_approach, reference)
    use_turned = np.abs(turned_agreement) > np.abs(plain_agreement)
    chosen = np.where(use_turned, turned_about_approach, back)
    sign = np.sign(np.where(use_turned, turned_agreement, plain_agreement))
    return chosen * sign
