"""Stable identities for grasps across re-plans of a changing or growing scene.

A closed loop plans again after every frame, and each plan is a fresh ranked list: the grasp a
robot is moving to has no name of its own. ``GraspTracker`` gives every grasp a ``track_id``
that it keeps while, plan after plan, a grasp stays within ``max_distance`` of where it was and
turns by at most ``max_angle`` (a half turn about the approach axis is the same grasp for a
parallel-jaw hand). The service's gRPC ``Track`` stream uses it; an HTTP loop can run one on
the client side, on the answers of ``GET /sessions/{id}/grasps``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from vgn_contract.schemas import Grasp

#: Defaults: two voxels of the default 7.5 mm workspace grid, and a few degrees.
DEFAULT_MAX_DISTANCE = 0.015
DEFAULT_MAX_ANGLE_DEG = 10.0


def grasp_angle(a: np.ndarray, b: np.ndarray) -> float:
    """Rotation angle (radians) between two [x, y, z, w] grasp orientations, the smaller of the
    two for a hand that is symmetric under a half turn about its approach (z) axis."""
    relative = Rotation.from_quat(a).inv() * Rotation.from_quat(b)
    flipped = relative * Rotation.from_euler("z", np.pi)
    return float(min(relative.magnitude(), flipped.magnitude()))


@dataclass
class _Track:
    track_id: int
    position: np.ndarray
    orientation: np.ndarray


class GraspTracker:
    """Matches each plan's grasps to the previous plan's and numbers them (ids start at 1).

    Matching is greedy on distance: the closest (previous, new) pair within both limits is
    joined first, so two new grasps never take one id. A grasp that matches nothing gets a new
    id; a track that finds no grasp in a plan ends (ids are never reused).
    """

    def __init__(
        self, max_distance: float = DEFAULT_MAX_DISTANCE, max_angle_deg: float = DEFAULT_MAX_ANGLE_DEG
    ) -> None:
        if not max_distance > 0 or not 0 < max_angle_deg <= 180:
            raise ValueError("max_distance must be > 0 m and max_angle_deg in (0, 180]")
        self.max_distance = max_distance
        self.max_angle = np.deg2rad(max_angle_deg)
        self._tracks: list[_Track] = []
        self._next_id = 1

    def update(self, grasps: Sequence[Grasp]) -> list[Grasp]:
        """``grasps`` (in their order) with ``track_id`` set; remembers them for the next plan."""
        positions = [np.asarray(g.position, dtype=np.float64) for g in grasps]
        orientations = [np.asarray(g.orientation, dtype=np.float64) for g in grasps]
        pairs = []
        for t, track in enumerate(self._tracks):
            for g, position in enumerate(positions):
                distance = float(np.linalg.norm(position - track.position))
                if (
                    distance <= self.max_distance
                    and grasp_angle(track.orientation, orientations[g]) <= self.max_angle
                ):
                    pairs.append((distance, t, g))
        track_of: dict[int, int] = {}
        taken: set[int] = set()
        for _, t, g in sorted(pairs):
            if g not in track_of and t not in taken:
                track_of[g] = self._tracks[t].track_id
                taken.add(t)
        tracked, tracks = [], []
        for g, grasp in enumerate(grasps):
            track_id = track_of.get(g)
            if track_id is None:
                track_id, self._next_id = self._next_id, self._next_id + 1
            tracks.append(_Track(track_id, positions[g], orientations[g]))
            tracked.append(grasp.model_copy(update={"track_id": track_id}))
        self._tracks = tracks
        return tracked

    def reset(self) -> None:
        """Forget the tracks (the scene was reset); ids keep counting up."""
        self._tracks = []
