"""Do two grasp lists agree? The acceptance check for faster forms of the network: every
grasp of the reference's top ``k`` must have a counterpart in the candidate's list at most
one voxel away, turned by at most a few degrees and with nearly the same quality.

Ranks may swap between grasps whose qualities differ by less than the quality tolerance, so
a counterpart is looked for among all the candidate's grasps, and the candidate's top ``k``
is checked against the reference's list the same way (both directions).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from client.schemas import Grasp


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
    reference: Sequence[Grasp], candidate: Sequence[Grasp], tolerance: Tolerance, k: int = 10
) -> list[str]:
    """Why the two lists' top ``k`` disagree; empty when they agree. A grasp whose quality
    is within the tolerance of the cut-off may be missing from the other side's list."""

    def report(top: Sequence[Grasp], pool: Sequence[Grasp], side: str, cutoff: float) -> list[str]:
        return [
            f"{side} grasp at {np.round(g.position, 4).tolist()} q={g.quality:.3f} has no counterpart"
            for g in unmatched(top, pool, tolerance)
            if g.quality > cutoff + tolerance.quality
        ]

    cutoff = lambda grasps: grasps[-1].quality if grasps else 0.0  # noqa: E731
    return report(reference[:k], candidate, "reference", cutoff(candidate)) + report(
        candidate[:k], reference, "candidate", cutoff(reference)
    )
