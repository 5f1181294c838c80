"""Do two grasp lists agree? The acceptance check for faster forms of the network: every
grasp of the reference's top ``k`` must have a counterpart in the candidate's list at most
one voxel away, turned by at most a few degrees and with nearly the same quality.

Ranks may swap between near-equal qualities, so counterparts are looked for in the whole
list, in both directions. Where two neighbouring voxels nearly tie, non-maximum suppression
may keep one in the reference and the other in the candidate; with ``neighbour_swaps`` such
a pair is excused, and the caller must then check that the two networks' outputs agree voxel
by voxel (:func:`voxelwise_disagreements`), which makes the swap a tie and not an error.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from vgn_contract.schemas import Grasp


@dataclass(frozen=True)
class Tolerance:
    """How far two grasps may differ and still count as the
    same: position (metres), angle (degrees) and quality."""

    position_m: float
    angle_deg: float = 5.0
    quality: float = 0.02


def grasp_angle_deg(a: Grasp, b: Grasp) -> float:
    """Angle between two grasp orientations, counting a half-turn about the approach (z)
    axis as the same grasp (the fingers are symmetric)."""
    ra, rb = Rotation.from_quat(a.orientation), Rotation.from_quat(b.orientation)
    flipped = rb * Rotation.from_euler("z", np.pi)
    return float(np.degrees(min((ra.inv() * rb).magnitude(), (ra.inv() * flipped).magnitude())))


def matches(a: Grasp, b: Grasp, tolerance: Tolerance) -> bool:
    """Whether ``b`` is ``a`` within ``tolerance`` in position,
    quality and angle (up to the fingers' half-turn)."""
    close = np.linalg.norm(np.subtract(a.position, b.position)) <= tolerance.position_m + 1e-9
    return bool(
        close
        and abs(a.quality - b.quality) <= tolerance.quality
        and grasp_angle_deg(a, b) <= tolerance.angle_deg
    )


def unmatched(top: Sequence[Grasp], pool: Sequence[Grasp], tolerance: Tolerance) -> list[Grasp]:
    """Grasps of ``top`` with no counterpart in ``pool``."""
    return [g for g in top if not any(matches(g, other, tolerance) for other in pool)]


def disagreements(
    reference: Sequence[Grasp],
    candidate: Sequence[Grasp],
    tolerance: Tolerance,
    k: int = 10,
    neighbour_swaps: bool = False,
) -> list[str]:
    """Why the two lists' top ``k`` disagree; empty when they agree. A grasp whose quality
    is within the tolerance of the cut-off may be missing from the other side's list. With
    ``neighbour_swaps``, an unmatched reference grasp and an unmatched candidate grasp at most
    one voxel apart with qualities within the tolerance excuse each other (see the module)."""
    cutoff = lambda grasps: grasps[-1].quality if grasps else 0.0  # noqa: E731
    missing = [
        g
        for g in unmatched(reference[:k], candidate, tolerance)
        if g.quality > cutoff(candidate) + tolerance.quality
    ]
    extra = [
        g
        for g in unmatched(candidate[:k], reference, tolerance)
        if g.quality > cutoff(reference) + tolerance.quality
    ]
    if neighbour_swaps:
        missing, extra = _without_swaps(missing, extra, tolerance)

    def describe(side: str, g: Grasp) -> str:
        return f"{side} grasp at {np.round(g.position, 4).tolist()} q={g.quality:.3f} has no counterpart"

    return [describe("reference", g) for g in missing] + [describe("candidate", g) for g in extra]


def _without_swaps(
    missing: list[Grasp], extra: list[Grasp], tolerance: Tolerance
) -> tuple[list[Grasp], list[Grasp]]:
    """``missing`` and ``extra`` less the pairs that are a neighbour swap (each grasp pairs once)."""
    left = list(extra)
    kept = []
    for g in missing:
        partner = next(
            (
                h
                for h in left
                if np.linalg.norm(np.subtract(g.position, h.position)) <= tolerance.position_m + 1e-9
                and abs(g.quality - h.quality) <= tolerance.quality
            ),
            None,
        )
        if partner is None:
            kept.append(g)
        else:
            left.remove(partner)
    return kept, left


def voxelwise_disagreements(
    reference: Sequence[np.ndarray], candidate: Sequence[np.ndarray], mask: np.ndarray, tolerance: Tolerance
) -> list[str]:
    """Where two networks' raw outputs (quality (N³), rotation quaternions (4, N³), ...) differ
    beyond ``tolerance`` at the voxels of ``mask``: quality, and the angle between the
    orientations (up to the fingers' half-turn, as for grasps). Empty when they agree."""
    quality_ref, rotation_ref = np.asarray(reference[0])[mask], np.asarray(reference[1])[:, mask].T
    quality_cand, rotation_cand = np.asarray(candidate[0])[mask], np.asarray(candidate[1])[:, mask].T
    problems = []
    worst_quality = float(np.abs(quality_ref - quality_cand).max(initial=0.0))
    if worst_quality > tolerance.quality:
        problems.append(f"quality differs by up to {worst_quality:.4f} at the masked voxels")
    if len(rotation_ref):
        ra, rb = Rotation.from_quat(rotation_ref), Rotation.from_quat(rotation_cand)
        flipped = rb * Rotation.from_euler("z", np.pi)
        angles = np.degrees(np.minimum((ra.inv() * rb).magnitude(), (ra.inv() * flipped).magnitude()))
        if angles.max() > tolerance.angle_deg:
            problems.append(f"orientation differs by up to {angles.max():.2f} deg at the masked voxels")
    return problems


def network_outputs(network: torch.nn.Module, grid: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quality (N³), rotation (4, N³) and width (N³) of a VGN-shaped ``network`` on one (N, N, N)
    grid, float32 numpy: what the checks above compare."""
    with torch.inference_mode():
        quality, rotation, width = network(torch.from_numpy(grid)[None, None])
    return quality[0, 0].float().numpy(), rotation[0].float().numpy(), width[0, 0].float().numpy()
