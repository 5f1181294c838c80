"""Closing the visual loop in the clutter benchmark: watching while approaching, and scanning
while planning (docs/closed-loop.md).

``ApproachWatch`` (``clear-scene --closed-loop``): while the hand moves in, the fixed cameras
keep looking, and each look is compared, around the grasp and with the hand filtered out,
with what they saw when the grasp was planned. When the scene there changed, or the hand
touched something, the hand withdraws before closing and the robot looks and plans anew.

``WristScan`` (``clear-scene --scan wrist``): a wrist camera circles the scene while closing in,
each frame is fused and planned on, and the robot commits once the best grasp has stayed the
same for ``STABLE_PLANS`` plans, or at the arc's last frame. The frames lie a third of a turn
apart because a grasp needs its object seen from more than one side.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from client.http import VGNClient
from sim_worker.camera import WORKSPACE_CENTRE, Camera, camera_on_sphere
from vgn_contract.schemas import GraspResult
from vgn_contract.tracking import GraspTracker

#: The fixed cameras look every this many 2 mm approach steps: 0.1 s at 10 cm/s, 10 Hz.
WATCH_EVERY_STEPS = 5
#: A look counts as a change when, in some view, more than ``CHANGED_SHARE`` of the pixels that
#: saw the scene within ``CHANGE_RADIUS`` of the grasp when it was planned (and do not see the
#: hand now) moved in depth by more than ``CHANGED_DEPTH``.
CHANGE_RADIUS = 0.06
CHANGED_DEPTH = 0.01
CHANGED_SHARE = 0.15

#: The wrist camera's arc: frames a third of a turn apart about the scene, from a little
#: farther and more oblique to a little nearer and steeper, each looking at the workspace.
WRIST_FRAMES = 3
WRIST_SWEEP_DEG = 240.0  # azimuth from the first frame to the last
WRIST_DISTANCE = (0.62, 0.55)  # m from the workspace centre
WRIST_TILT_DEG = (35.0, 30.0)  # from the vertical
#: The scan stops once the best grasp has been the same grasp (track id) for this many plans.
STABLE_PLANS = 2


@dataclass
class ApproachWatch:
    """The closed loop of one grasp attempt (see the module docstring), passed as the
    approach's ``on_waypoint`` and ``on_contact``. ``reference`` holds the depth each of
    ``views`` saw when the grasp was planned; ``looks`` counts the looks."""

    camera: Camera
    views: list[np.ndarray]
    reference: list[np.ndarray]
    hand: int  # the gripper's body, filtered out of the depth
    target: np.ndarray  # the grasp position, world frame
    looks: int = 0
    changed: float = 0.0  # the largest share of changed pixels a look found

    def __call__(self, step: int, count: int) -> bool:
        """After approach step ``step`` of ``count``: look every ``WATCH_EVERY_STEPS`` steps
        and at the last one; True (stop) when the scene around the grasp changed."""
        if step % WATCH_EVERY_STEPS and step != count:
            return False
        return self.look()

    def __post_init__(self) -> None:
        # Where each view saw the scene near the grasp when it was planned, and the box around it.
        self._near = [
            near_target(self.camera, pose, depth, self.target)
            for pose, depth in zip(self.views, self.reference, strict=True)
        ]

    def look(self) -> bool:
        """Render every view and compare it with its reference; True when the scene changed."""
        self.looks += 1
        shares = []
        for pose, before, (near, box) in zip(self.views, self.reference, self._near, strict=True):
            if box is None:
                continue
            after = self.camera.render_depth(pose, hide=(self.hand,))[box]
            seen = near[box] & (after > 0)
            if seen.any():
                shares.append(float(np.mean(np.abs(after[seen] - before[box][seen]) > CHANGED_DEPTH)))
        self.changed = max([self.changed, *shares])
        return bool(shares) and max(shares) > CHANGED_SHARE


def near_target(
    camera: Camera, pose: np.ndarray, depth: np.ndarray, target: np.ndarray
) -> tuple[np.ndarray, tuple[slice, slice] | None]:
    """The pixels of a view whose back-projected point lies within ``CHANGE_RADIUS`` of
    ``target``, and the smallest box holding them (None when there are none)."""
    i = camera.intrinsics
    v, u = np.indices(depth.shape)
    rays = np.stack([(u - i.cx) / i.fx, (v - i.cy) / i.fy, np.ones(depth.shape)], axis=-1)
    points = (rays * depth[..., None]) @ pose[:3, :3].T + pose[:3, 3]
    near = (depth > 0) & (np.linalg.norm(points - target, axis=-1) < CHANGE_RADIUS)
    if not near.any():
        return near, None
    rows, cols = np.flatnonzero(near.any(axis=1)), np.flatnonzero(near.any(axis=0))
    return near, (slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1))


def wrist_arc(azimuth: float, frames: int = WRIST_FRAMES) -> list[np.ndarray]:
    """Camera poses (camera → world, OpenCV frame) of a wrist camera circling the scene from
    ``azimuth`` (radians about world z) through ``WRIST_SWEEP_DEG``: azimuth grows and distance
    and tilt shrink linearly along the arc."""
    distances = np.linspace(*WRIST_DISTANCE, frames)
    tilts = np.deg2rad(np.linspace(*WRIST_TILT_DEG, frames))
    azimuths = azimuth + np.deg2rad(np.linspace(0.0, WRIST_SWEEP_DEG, frames))
    return [
        camera_on_sphere(WORKSPACE_CENTRE, float(d), float(t), float(a))
        for d, t, a in zip(distances, tilts, azimuths, strict=True)
    ]


@dataclass(frozen=True)
class ScanResult:
    """The plan a scan stopped on, how many frames it fused and the integration time."""

    answer: GraspResult
    frames: int
    integration_ms: float


def wrist_scan(
    vgn: VGNClient,
    session_id: str,
    camera: Camera,
    arc: list[np.ndarray],
    query: dict,
    perturb: Callable[[np.ndarray], np.ndarray] | None = None,
) -> ScanResult:
    """Fuse the arc's frames one at a time, planning after each (grasps pass the request's
    quality threshold), and stop when the best grasp kept its track id over the last
    ``STABLE_PLANS`` plans, or at the arc's end. ``perturb`` turns a true camera pose into the
    one reported (pose error)."""
    tracker = GraspTracker()
    best_ids: list[int | None] = []
    integration_ms, answer = 0.0, None
    for count, pose in enumerate(arc, start=1):
        depth = camera.render_depth(pose)
        reported = pose if perturb is None else perturb(pose)
        integration_ms += vgn.add_frame(session_id, depth, reported).integration_ms
        answer = vgn.grasps(session_id, **query)
        tracked = tracker.update(answer.grasps)
        answer = answer.model_copy(update={"grasps": tracked})
        best_ids.append(tracked[0].track_id if tracked else None)
        recent = best_ids[-STABLE_PLANS:]
        if len(recent) == STABLE_PLANS and recent[0] is not None and len(set(recent)) == 1:
            return ScanResult(answer, count, integration_ms)
    assert answer is not None, "an arc has at least one frame"
    return ScanResult(answer, len(arc), integration_ms)


def elapsed_ms(started: float) -> float:
    """Milliseconds since ``started`` (``time.perf_counter()``), for the results."""
    return round((time.perf_counter() - started) * 1e3, 3)
