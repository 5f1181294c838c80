"""Clearance check: which grasps let the open hand reach them without touching observed geometry.

The executor (``sim_worker/grasping.py``, VGN's protocol) places the hand open at the maximum
opening 5 cm back along the approach and moves it straight to the grasp pose. A grasp is
*clear* when none of the hand's parts, swept along that path, comes near more than
``min_points - 1`` observed surface points; points between the fingers never count.

The hand is the session's gripper description (``vgn_contract.gripper_description``, by default
``franka``), every part a box in the grasp frame (docs/conventions.md), each swept box tested
exactly for the points inside its bounding box. Grasps are cleared against the coarse TSDF's zero
crossings (``SceneVolume.surface_points``, far cheaper than ``/cloud``), and against the fine
cloud too wherever a request reads it anyway (the surface's pairs are found on it)."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from service.hands import active_hand
from vgn_contract.gripper_description import GripperDescription
from vgn_contract.schemas import Grasp

#: (grasp, point) pairs moved into grasp frames at once (24 MB of float64 coordinates).
_CHUNK = 1 << 20


#: Where the clearance check's default margin leaves a look no grasp at all, the service answers with
#: what clears a hand grown by this much less rather than nothing (docs/concepts.md, "The clearance check").
FALLBACK_MARGIN = 0.002
#: Where the network's grasps are cleared on the fine cloud too, this many of its points (2.5 mm apart
#: where the grid's crossings lie 7.5 mm apart) veto one: with the grid's two, depth noise scattered
#: over the fine cloud vetoes grasps by the dozen (docs/concepts.md, "The clearance check").
NETWORK_FINE_MIN_POINTS = 10


#: The volume shows nothing past the cube's four side faces. Where observed surface meets one (comes
#: within this many of its point spacings of it: surface extraction leaves the outermost voxel and a
#: half bare), the check takes it to go on straight outwards for :data:`EDGE_REACH` (m), so that a hand
#: at the cube's edge stays clear of an object that sticks out of the cube (docs/concepts.md).
EDGE_BAND_SPACINGS = 2.0
EDGE_REACH = 0.06


@dataclass(frozen=True)
class ClearanceConfig:
    """Knobs of the check.

    ``margin`` (m) grows every box of the hand on all sides; ``min_points`` is how many surface
    points inside the swept hand veto a grasp (one stray point does not); ``opening`` (m) is
    the width the hand is open at while approaching and ``pregrasp_distance`` (m) how far back
    along the approach the approach starts (unset: the hand's); ``contact_tolerance`` (m): contact in the last
    this-many metres of the approach is allowed, since a guarded approach stops there and
    closes only that much short of the grasp pose (often still a success, e.g. fingertips
    meeting the table). How the defaults were chosen: docs/concepts.md, "The clearance check"."""

    margin: float = 0.004
    min_points: int = 2
    opening: float | None = None
    pregrasp_distance: float | None = None
    contact_tolerance: float = 0.005

    def __post_init__(self) -> None:
        if self.margin < 0 or self.min_points < 1 or self.contact_tolerance < 0:
            raise ValueError(f"invalid clearance settings {self}")
        if (self.opening is not None and self.opening < 0) or (self.pregrasp_distance or 0.0) < 0:
            raise ValueError(f"invalid clearance settings {self}")

    def approach(self, hand: GripperDescription) -> tuple[float, float]:
        """(opening, pre-grasp distance) of the approach with ``hand``: the set values, else the
        hand's; a ``ValueError`` when they do not fit it."""
        opening = hand.max_opening if self.opening is None else self.opening
        distance = hand.pregrasp_distance if self.pregrasp_distance is None else self.pregrasp_distance
        if opening > hand.max_opening or self.contact_tolerance > distance:
            raise ValueError(f"clearance settings {self} do not fit the gripper {hand.name!r}")
        return opening, distance


def hand_boxes(
    opening: float | None = None, margin: float = 0.0, hand: GripperDescription | None = None
) -> tuple[np.ndarray, ...]:
    """The hand (default: the active one, ``service.hands``) open at ``opening`` (default: fully)
    as boxes in the grasp frame: centres (B, 3), rotations (B, 3, 3) box → grasp frame and half
    extents (B, 3) grown by ``margin``. Palm first, then the left (+y) and right (-y) fingers'
    boxes in the description's order. Kept per (hand, opening, margin), read-only, since
    building them is a fair share of checking the few grasps of a request."""
    hand = hand or active_hand()
    return _hand_boxes(hand, hand.max_opening if opening is None else opening, margin)


@functools.lru_cache(maxsize=16)
def _hand_boxes(hand: GripperDescription, opening: float, margin: float) -> tuple[np.ndarray, ...]:
    half_opening = 0.5 * opening
    palm = hand.palm
    centres, rotations, halves = [palm.centre], [Rotation.from_euler("x", palm.tilt).as_matrix()], [palm.half]
    for side in (1.0, -1.0):
        for box in hand.fingers:
            x, y, z = box.centre
            centres.append((x, side * (y + half_opening), z))
            rotations.append(Rotation.from_euler("x", side * box.tilt).as_matrix())
            halves.append(box.half)
    boxes = (
        np.asarray(centres, dtype=np.float64),
        np.asarray(rotations, dtype=np.float64),
        np.asarray(halves, dtype=np.float64) + margin,
    )
    for array in boxes:
        array.setflags(write=False)
    return boxes


def approach_is_clear(
    points: np.ndarray,
    positions: np.ndarray,
    orientations: np.ndarray,
    config: ClearanceConfig = ClearanceConfig(),
    hand: GripperDescription | None = None,
    point_tolerance: np.ndarray | None = None,
) -> np.ndarray:
    """Which grasps the open ``hand`` (default: the active one) reaches without touching ``points``.

    Args:
        points: (M, 3) observed surface points, in the grasps' frame (the service: the world).
        positions: (G, 3) grasp frame origins, in the frame of ``points``.
        orientations: (G, 4) quaternions [x, y, z, w], grasp frame → the frame of ``points``.
        config: margin, vetoing point count, opening and approach length.
        hand: the gripper description whose boxes are swept; default the active hand.
        point_tolerance: (M,) contact tolerance (m) per point instead of ``config``'s one.

    Returns (G,) bool: fewer than ``config.min_points`` points in the hand swept in from the pre-grasp.
    """
    hand = hand or active_hand()
    opening, pregrasp_distance = config.approach(hand)
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    tolerance = None if point_tolerance is None else np.asarray(point_tolerance, dtype=np.float64).reshape(-1)
    if tolerance is not None and len(tolerance) != len(points):
        raise ValueError(f"{len(tolerance)} contact tolerances for {len(points)} points")
    clear = np.ones(len(positions), dtype=bool)
    if not len(positions) or len(points) < config.min_points:
        return clear
    rotations = Rotation.from_quat(np.asarray(orientations, dtype=np.float64).reshape(-1, 4)).as_matrix()
    centres, box_rotations, halves = hand_boxes(opening, config.margin, hand)
    # The swept hand's bounding box in the grasp frame: only points inside it are tested per box.
    corners = _box_corners(centres, box_rotations, halves)  # (B, 8, 3) grasp frame
    low = corners.min(axis=(0, 1)) - [0.0, 0.0, pregrasp_distance]
    high = corners.max(axis=(0, 1))
    direction = box_rotations[:, 2, :]  # the grasp frame's +z in each box's frame, (B, 3)
    intruding = np.zeros(len(positions), dtype=np.intp)
    step = max(1, _CHUNK // len(points))  # grasps per pass: bounds the memory on a big cloud
    for start in range(0, len(positions), step):
        rotation, position = rotations[start : start + step], positions[start : start + step]
        # Every point in every grasp's frame, (G, M, 3): (p - t) R = p R - t R.
        local = points @ rotation
        local -= np.einsum("gj,gji->gi", position, rotation)[:, None, :]
        grasp, point = np.nonzero(np.all((local >= low) & (local <= high), axis=2))
        if not len(grasp):
            continue
        in_box = np.einsum("bji,pbj->pbi", box_rotations, local[grasp, point][:, None, :] - centres[None])
        first = config.contact_tolerance if tolerance is None else tolerance[point][:, None]
        swept = _segment_hits_box(in_box, direction, halves, first, pregrasp_distance)
        intruding[start : start + step] += np.bincount(grasp[swept.any(axis=1)], minlength=len(position))
    return intruding < config.min_points


def _box_corners(centres: np.ndarray, rotations: np.ndarray, halves: np.ndarray) -> np.ndarray:
    """The 8 corners (B, 8, 3) of each box, in the frame the boxes are given in."""
    signs = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1], indexing="ij")).reshape(3, 8).T
    return centres[:, None, :] + np.einsum("bij,bkj->bki", rotations, signs[None] * halves[:, None, :])


def _segment_hits_box(
    start: np.ndarray, direction: np.ndarray, halves: np.ndarray, first_u: float | np.ndarray, last_u: float
) -> np.ndarray:
    """Whether ``start + u * direction`` lies in the box ``|x_i| <= halves_i`` for some u in
    [first_u, last_u] (slab test). ``start`` (P, B, 3), ``direction`` and ``halves`` (B, 3); (P, B) bool.

    A point p is in the hand at offset -u along the approach (the hand u back from the grasp
    pose) exactly when p + u z is in the hand at the grasp pose, hence the segment."""
    moving = np.abs(direction) > 1e-12
    safe = np.where(moving, direction, 1.0)
    first = (-halves - start) / safe
    second = (halves - start) / safe
    inside = np.abs(start) <= halves
    enter = np.where(moving, np.minimum(first, second), np.where(inside, -np.inf, np.inf))
    leave = np.where(moving, np.maximum(first, second), np.where(inside, np.inf, -np.inf))
    return np.maximum(enter.max(axis=-1), first_u) <= np.minimum(leave.min(axis=-1), last_u)


def _swept_box_edges() -> tuple[np.ndarray, np.ndarray]:
    """The edges of a box swept along a segment, as pairs of indices into its 16 corners (the 8 of
    :func:`_box_corners` at the start, then at the end): each end's 12, and the 8 corners' paths."""
    box = [(k, k | bit) for k in range(8) for bit in (1, 2, 4) if not k & bit]
    pairs = box + [(a + 8, b + 8) for a, b in box] + [(k, k + 8) for k in range(8)]
    return np.array([a for a, _ in pairs]), np.array([b for _, b in pairs])


_SWEPT_EDGES = _swept_box_edges()


def above_table_outside(
    positions: np.ndarray,
    orientations: np.ndarray,
    to_workspace: np.ndarray,
    size: float,
    table: float,
    config: ClearanceConfig = ClearanceConfig(),  # noqa: B008 (frozen: one shared default is safe)
    hand: GripperDescription | None = None,
    first: float = 0.0,
) -> np.ndarray:
    """(G,) bool: the open ``hand`` (grown by ``config.margin``), swept in from the pre-grasp to
    ``first`` m short of the grasp pose, stays above the table (workspace height ``table``) outside
    the workspace cube's footprint (side ``size``, ``to_workspace`` taking the grasps' frame to the
    cube's). The volume shows the table only inside the cube, but a table is a plane: a hand coming
    in low from beside the cube meets it there all the same.

    Each swept box is the convex hull of the box at the two ends of the sweep; its part below the
    table is spanned by its corners below it and the points where its edges (the box's at either end,
    and each corner's path) cross it, so it dips into the table outside the cube exactly when one of
    those does."""
    hand = hand or active_hand()
    opening, pregrasp_distance = config.approach(hand)
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    if not len(positions):
        return np.ones(0, dtype=bool)
    corners = _box_corners(*hand_boxes(opening, config.margin, hand))  # (B, 8, 3) grasp frame
    back = np.array([0.0, 0.0, 1.0])
    swept = np.concatenate([corners - first * back, corners - pregrasp_distance * back], axis=1)  # (B, 16, 3)
    # Grasp frame → the cube's frame in one step: its rotation applied to each grasp's.
    rotations = Rotation.from_quat(np.asarray(orientations, dtype=np.float64).reshape(-1, 4)).as_matrix()
    rotations = np.einsum("ij,gjk->gik", to_workspace[:3, :3], rotations)
    origins = positions @ to_workspace[:3, :3].T + to_workspace[:3, 3]
    local = origins[:, None, None, :] + np.einsum("gij,bkj->gbki", rotations, swept)  # (G, B, 16, 3)
    depth = local[..., 2] - table
    one, other = _SWEPT_EDGES
    near, far = depth[..., one], depth[..., other]
    crosses = (near < 0.0) != (far < 0.0)
    share = near / np.where(crosses, near - far, 1.0)
    crossing = local[..., one, :] + share[..., None] * (local[..., other, :] - local[..., one, :])

    def outside(points: np.ndarray) -> np.ndarray:
        return np.any((points[..., :2] < 0.0) | (points[..., :2] > size), axis=-1)

    under = (depth < 0.0) & outside(local)
    return ~(under.any(axis=(1, 2)) | (crosses & outside(crossing)).any(axis=(1, 2)))


def fingers_inside(
    positions: np.ndarray,
    orientations: np.ndarray,
    to_workspace: np.ndarray,
    size: float,
    hand: GripperDescription | None = None,
) -> np.ndarray:
    """(G,) bool: the open ``hand``'s (default: the active one) fingertips lie inside the workspace
    cube of side ``size`` (m), ``to_workspace`` (4×4) taking the grasps' frame to the cube's. Beyond
    the cube the volume shows nothing, so no check can vouch for the fingers there: on a table, a
    grasp at the cube's edge otherwise passes with its fingers in the table outside it."""
    hand = hand or active_hand()
    half, depth = 0.5 * hand.max_opening, hand.finger_depth
    tips = np.array([[0.0, half, depth], [0.0, -half, depth]])
    rotations = Rotation.from_quat(np.asarray(orientations, dtype=np.float64).reshape(-1, 4))
    ends = np.asarray(positions, dtype=np.float64).reshape(-1, 1, 3) + np.stack(
        [rotations.apply(t) for t in tips], 1
    )
    local = ends @ to_workspace[:3, :3].T + to_workspace[:3, 3]
    return np.all((local >= 0.0) & (local <= size), axis=(1, 2))


def continued_past_sides(
    points: np.ndarray, to_workspace: np.ndarray, size: float, spacing: float, floor: float | None
) -> np.ndarray:
    """(K, 3) world-frame points that carry ``points`` (world frame, ``spacing`` m apart) on straight
    out of the workspace cube (side ``size`` m, ``to_workspace`` taking the world to the cube's
    frame) where they meet one of its side faces (:data:`EDGE_BAND_SPACINGS`), every ``spacing``
    for :data:`EDGE_REACH`; points at workspace height ``floor`` or below (the support plane) are
    not carried on (None: every point is)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    local = points @ to_workspace[:3, :3].T + to_workspace[:3, 3]
    if floor is not None:
        local = local[local[:, 2] > floor]
    steps = np.arange(1, int(round(EDGE_REACH / spacing)) + 1) * spacing
    carried = []
    for axis in (0, 1):
        for face, outwards in ((0.0, -1.0), (size, 1.0)):
            edge = local[np.abs(local[:, axis] - face) < EDGE_BAND_SPACINGS * spacing]
            if not len(edge):
                continue
            copies = np.repeat(edge[None], len(steps), axis=0)
            copies[:, :, axis] = face + outwards * steps[:, None]
            carried.append(copies.reshape(-1, 3))
    if not carried:
        return np.zeros((0, 3))
    from_workspace = np.linalg.inv(to_workspace)
    beyond = np.concatenate(carried)
    return beyond @ from_workspace[:3, :3].T + from_workspace[:3, 3]


def clear_grasps(
    grasps: list[Grasp],
    points: np.ndarray,
    config: ClearanceConfig = ClearanceConfig(),
    workspace: tuple[np.ndarray, float] | None = None,
    hand: GripperDescription | None = None,
) -> list[Grasp]:
    """The ``grasps`` (world frame, order kept) whose approach with ``hand`` (default: the active
    one) is clear of ``points`` (world frame) and, given the ``workspace`` (its 4×4 pose in the
    world and its size), whose open fingers stay inside it (:func:`fingers_inside`)."""
    if not grasps:
        return []
    positions = np.array([g.position for g in grasps])
    orientations = np.array([g.orientation for g in grasps])
    clear = approach_is_clear(points, positions, orientations, config, hand)
    if workspace is not None:
        pose, size = workspace
        clear &= fingers_inside(
            positions, orientations, np.linalg.inv(np.asarray(pose, dtype=np.float64)), size, hand
        )
    return [g for g, ok in zip(grasps, clear, strict=True) if ok]
