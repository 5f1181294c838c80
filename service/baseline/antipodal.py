"""A geometric 6-DOF antipodal grasp planner on the fused point cloud (GPD-style sampling).

Candidates are sampled on the world-frame cloud with outward normals (``SceneVolume.cloud``):
seeded surface points give the closing axis (their normal), approach directions are spread
around it, and each candidate must hold enough points between the jaws, pass an antipodal
test on the jaw points' normals and leave the fingers, the palm and the table clear (the steps
and their constants are in the comment below). The same cloud always gives the same grasps.
Scores are geometric, in [0, 1], not success probabilities; non-maximum suppression keeps the
best of grasps within 1 cm and 20° of each other. Frames: docs/conventions.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from vgn_contract.gripper_description import GripperDescription, default_gripper
from vgn_contract.schemas import Grasp

if TYPE_CHECKING:
    from service.vgn.detection import DetectionConfig

# The steps, per seed:
# 1. ``seeds`` surface points whose normal neither points down (n_z > -0.1) nor up more steeply than
#    the friction cone (n_z < cos ``friction_angle``: their opposite face would look down, which a
#    camera above a table seldom sees; the table top is such a point) are drawn with a seeded
#    generator.
# 2. The closing axis y is the seed's normal, so the seed lies on the +y jaw. ``approaches``
#    approach directions z are spread evenly around y, starting from the one closest to straight
#    down; x = y × z.
# 3. For each of a few depths (fingertips 5–45 mm past the seed along z) the points in the closing
#    region (|x| <= half the pad's width, 0 <= z <= the finger depth, within the opening towards -y)
#    are collected. With at least ``min_points`` of them, the closed width is their y-extent + 2 mm
#    (reject above the maximum opening, and where the y-extent is no more than the hand's held
#    opening: the closed hand would count as holding nothing) and the hand is centred on them along y.
# 4. Antipodal test: the points within 3 mm of each jaw that face it (n · y > 0 at the +y jaw, < 0 at
#    the -y jaw: the far side of a thin wall faces away) must have a mean normal within
#    ``friction_angle`` of the jaw's outward direction (+y, -y). The mean, not each point: on a
#    curved face the normals about the contact tilt both ways and cancel, on a slanted face not.
# 5. Collision test against the cloud (the table is part of it): no point may lie in either finger
#    (box fingers :data:`FINGER_THICKNESS` thick along y, as wide as the pad along x, the finger depth
#    long) or in the palm box (:data:`PALM_HALF_X` deep along x, as wide and tall as the hand's palm,
#    behind the finger bases), and no corner of the hand may come within 5 mm of the lowest cloud
#    point. Of the valid depths the deepest is kept. The hand is the gripper description's (default
#    ``franka``: 2 cm wide, 5 cm long fingers, a 0.04 x 0.20 x 0.06 m palm, 8 cm opening); its
#    fingers and palm depth are the baseline's own simpler box model.
# Score: ``antipodality * (1 - 0.05 * width / max opening) * (0.9 + 0.1 * downness)``, antipodality being the
# mean |n · y| of the jaw points (1: both contacts exactly opposed) and downness max(0, -approach_z)
# (1: straight down); a clean top-down antipodal grasp scores about 0.93-0.97, a side grasp ~0.1
# less. Non-maximum suppression counts a π turn about the approach axis as the same grasp.

#: The baseline's box fingers are this thick along y (m) and its palm this half deep along x (m),
#: whatever the hand: a simpler collision model than the description's stepped fingers.
FINGER_THICKNESS = 0.012
PALM_HALF_X = 0.02
WIDTH_MARGIN = 0.002
JAW_TOLERANCE = 0.003
TABLE_CLEARANCE = 0.005


@dataclass(frozen=True)
class Jaws:
    """The hand as the baseline models it (m): opening, finger length along the approach, half the
    finger width along x, the palm's half width along y and its height along z, the opening at which
    it holds nothing; ``near`` and ``reach`` are balls about a seed holding every point the fingers and
    the palm of a hand placed for that seed can touch."""

    max_opening: float
    finger_depth: float
    finger_half_width: float
    palm_half_y: float
    palm_depth: float
    held_opening: float

    def near(self, depths: tuple[float, ...]) -> tuple[float, float]:
        """The fingers' neighbourhood of a seed for fingertips ``depths`` past it: a ball this far (m)
        from the seed towards -y, of this radius (m). It holds the cylinder along -y the fingers can
        reach: from a finger's thickness beyond the seed to a finger's thickness beyond the maximum
        opening, and as far around the closing axis as a finger reaches along z and across x."""
        length = self.max_opening + 2 * (FINGER_THICKNESS + WIDTH_MARGIN)
        along_z = max(max(depths), self.finger_depth - min(depths))
        return length / 2 - FINGER_THICKNESS - WIDTH_MARGIN, math.hypot(
            length / 2, self.finger_half_width, along_z
        )

    @property
    def reach(self) -> float:
        """Radius (m) of the palm's neighbourhood of a seed."""
        return math.sqrt(
            0.045**2 + (self.palm_half_y + self.max_opening) ** 2 + (self.palm_depth + self.finger_depth) ** 2
        )


def jaws_of(hand: GripperDescription) -> Jaws:
    """The baseline's model of ``hand``: its opening, finger depth, pad width, palm and held opening."""
    return Jaws(
        hand.max_opening,
        hand.finger_depth,
        hand.pad_box.half[0],
        hand.palm.half[1],
        hand.palm.size[2],
        hand.held_opening,
    )


@dataclass(frozen=True)
class AntipodalConfig:
    """Sampling and filtering knobs. ``crop_min``/``crop_max`` are corners of a box in the
    workspace frame (metres), applied to grasp positions; ``approach`` is a world-frame
    direction and ``max_approach_angle_rad`` its cone half-angle in radians."""

    seeds: int = 500
    approaches: int = 8
    depths: tuple[float, ...] = (0.005, 0.015, 0.025, 0.035, 0.045)
    random_seed: int = 0
    min_points: int = 5
    friction_angle: float = math.radians(30.0)
    nms_distance: float = 0.01
    nms_angle: float = math.radians(20.0)
    threshold: float = 0.0
    max_grasps: int | None = None
    crop_min: tuple[float, float, float] | None = None
    crop_max: tuple[float, float, float] | None = None
    approach: tuple[float, float, float] | None = None
    max_approach_angle_rad: float | None = None


def plan_antipodal(
    cloud: np.ndarray,
    workspace_pose: np.ndarray,
    config: AntipodalConfig = AntipodalConfig(),
    hand: GripperDescription | None = None,
) -> list[Grasp]:
    """Antipodal grasps on ``cloud`` ((M, 6) world points + outward unit normals), best first, for
    ``hand`` (default: the default gripper description).

    ``workspace_pose`` (4×4 workspace → world) only serves the crop box.
    """
    jaws = jaws_of(hand or default_gripper())
    cloud = np.asarray(cloud, dtype=np.float64).reshape(-1, 6)
    if len(cloud) < config.min_points:
        return []
    points, normals = cloud[:, :3], cloud[:, 3:]
    normals = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    floor = points[:, 2].min() + TABLE_CLEARANCE
    # Step 1's seeds: neither facing down nor up more steeply than the friction cone.
    candidates = np.flatnonzero((normals[:, 2] > -0.1) & (normals[:, 2] < math.cos(config.friction_angle)))
    if not len(candidates):
        return []
    rng = np.random.default_rng(config.random_seed)
    seeds = rng.choice(candidates, size=min(config.seeds, len(candidates)), replace=False)
    tree = cKDTree(points)
    offset, radius = jaws.near(config.depths)
    # One query for every seed's neighbourhood (the fingers' ball about it, step 3).
    neighbourhoods = tree.query_ball_point(points[seeds] - offset * normals[seeds], radius)
    found = []  # (quality, position, rotation matrix, width)
    for seed, near in zip(seeds, neighbourhoods, strict=True):
        found.extend(
            _grasps_at_seed(points, normals, seed, np.asarray(near, dtype=np.intp), floor, config, jaws)
        )
    if not found:
        return []
    quality = np.array([f[0] for f in found])
    positions = np.array([f[1] for f in found])
    rotations = np.array([f[2] for f in found])
    widths = np.array([f[3] for f in found])
    keep = _filters(quality, positions, rotations, workspace_pose, config)
    order = np.flatnonzero(keep)[np.argsort(-quality[keep], kind="stable")]
    selected = _nms(order, positions, rotations, config)
    if config.max_grasps is not None:
        selected = selected[: config.max_grasps]
    quaternions = Rotation.from_matrix(rotations[selected]).as_quat() if selected else np.zeros((0, 4))
    return [
        Grasp(
            position=positions[i].tolist(),
            orientation=quaternions[n].tolist(),
            approach=rotations[i][:, 2].tolist(),
            width=float(widths[i]),
            quality=float(np.clip(quality[i], 0.0, 1.0)),
        )
        for n, i in enumerate(selected)
    ]


def _gathered(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For an (A, S) ``mask``, (A, M) column indices of each row's true entries in their order, padded
    to the longest row, and (A, M) which of them are real: every approach's slab as one array."""
    counts = mask.sum(axis=1)
    order = np.argsort(~mask, axis=1, kind="stable")[:, : max(int(counts.max()), 1)]
    return order, np.arange(order.shape[1]) < counts[:, None]


def _grasps_at_seed(
    points: np.ndarray,
    normals: np.ndarray,
    seed: int,
    near: np.ndarray,
    floor: float,
    config: AntipodalConfig,
    jaws: Jaws,
) -> list[tuple[float, np.ndarray, np.ndarray, float]]:
    """The best valid depth for each approach direction around one seed, every approach at once
    (arrays (A, D, M): approaches, depths, the points of each approach's slab); ``near`` indexes the
    points of the fingers' neighbourhood of the seed."""
    max_opening, finger_depth, finger_half_width = jaws.max_opening, jaws.finger_depth, jaws.finger_half_width
    origin, y = points[seed], normals[seed]
    cos_cone = math.cos(config.friction_angle)
    rel, near_normals = points[near] - origin, normals[near]
    py, ny = rel @ y, near_normals @ y  # n · y is the same for every approach
    opposite = (ny <= -cos_cone) & (py >= -max_opening) & (py <= 0.0)
    if not opposite.any():  # nothing to close on: no antipodal grasp from this seed
        return []
    down = np.array([0.0, 0.0, -1.0])
    a0 = down - (down @ y) * y
    if np.linalg.norm(a0) < 1e-6:  # a vertical normal: any perpendicular will do
        a0 = _cross(y, np.array([1.0, 0.0, 0.0]))
    a0 /= np.linalg.norm(a0)
    v = _cross(y, a0)
    pu, pv = rel @ a0, rel @ v
    nu, nv = near_normals @ a0, near_normals @ v
    angles = np.arange(config.approaches) * (2 * np.pi / config.approaches)
    c, s = np.cos(angles)[:, None], np.sin(angles)[:, None]  # (A, 1)
    slab, real = _gathered(np.abs(c * pv - s * pu) <= finger_half_width)  # x = y × z, z = c a0 + s v
    pz = np.take_along_axis(c * pu + s * pv, slab, axis=1)[:, None, :]  # (A, 1, M)
    qy, qn, qa, qv = (values[slab][:, None, :] for values in (py, ny, nu, nv))
    tips = np.asarray(config.depths)[:, None]  # (D, 1) fingertip offset past the seed along z
    along = (pz <= tips) & (pz >= tips - finger_depth) & real[:, None, :]  # between finger bases and tips
    closing = along & (qy >= -max_opening - WIDTH_MARGIN) & (qy <= WIDTH_MARGIN / 2)
    count = closing.sum(axis=2)
    y_max = np.where(closing, qy, -np.inf).max(axis=2)
    y_min = np.where(closing, qy, np.inf).min(axis=2)
    width = y_max - y_min + WIDTH_MARGIN
    valid = (count >= config.min_points) & (width <= max_opening) & (width - WIDTH_MARGIN > jaws.held_opening)
    if not valid.any():
        return []
    centre = np.where(valid, (y_max + y_min) / 2, 0.0)
    half = np.where(valid, width / 2, 0.0)
    # The cheap tests first: fingers clear of the points, then above the table; then the antipodal test.
    offset = np.abs(qy - centre[..., None])
    fingers = along & (offset >= half[..., None]) & (offset <= half[..., None] + FINGER_THICKNESS)
    valid &= ~fingers.any(axis=2)
    z_axes = c * a0 + s * v  # (A, 3)
    x_axes = c * v - s * a0  # y × z
    valid &= _lowest_z(origin, x_axes, y, z_axes, centre, half, tips[:, 0], jaws) >= floor
    if not valid.any():
        return []
    hi_jaw = closing & (qy >= y_max[..., None] - JAW_TOLERANCE) & (qn > 0.0)
    lo_jaw = closing & (qy <= y_min[..., None] + JAW_TOLERANCE) & (qn < 0.0)
    hi_n, lo_n = np.maximum(hi_jaw.sum(axis=2), 1), np.maximum(lo_jaw.sum(axis=2), 1)
    valid &= _mean_normal_cosine(hi_jaw, qn, qa, qv) >= cos_cone
    valid &= _mean_normal_cosine(lo_jaw, -qn, qa, qv) >= cos_cone
    if not valid.any():
        return []
    # The palm's (larger) neighbourhood, for the approaches still valid.
    live = np.flatnonzero(valid.any(axis=1))
    far_rel = points - origin  # the ball spans most of a workspace: a mask beats a tree query
    far_rel = far_rel[np.einsum("ij,ij->i", far_rel, far_rel) <= jaws.reach**2]
    fu, fy, fv = far_rel @ a0, far_rel @ y, far_rel @ v
    in_x, in_real = _gathered(np.abs(c[live] * fv - s[live] * fu) <= PALM_HALF_X)
    fz = np.take_along_axis(c[live] * fu + s[live] * fv, in_x, axis=1)[:, None, :]
    base = tips - finger_depth
    palm = (
        (fz < base)
        & (fz >= base - jaws.palm_depth)
        & (np.abs(fy[in_x][:, None, :] - centre[live][..., None]) <= jaws.palm_half_y)
        & in_real[:, None, :]
    )
    valid[live] &= ~palm.any(axis=2)
    results = []
    for a in np.flatnonzero(valid.any(axis=1)):
        d = np.flatnonzero(valid[a])[-1]  # the deepest valid placement
        normal_y = np.abs(qn[a, 0])
        antipodality = 0.5 * (
            (hi_jaw[a, d] * normal_y).sum() / hi_n[a, d] + (lo_jaw[a, d] * normal_y).sum() / lo_n[a, d]
        )
        position = origin + centre[a, d] * y + (tips[d, 0] - finger_depth) * z_axes[a]
        downness = max(0.0, -z_axes[a, 2])
        quality = antipodality * (1 - 0.05 * width[a, d] / max_opening) * (0.9 + 0.1 * downness)
        results.append((quality, position, np.column_stack([x_axes[a], y, z_axes[a]]), width[a, d]))
    return results


def grips_antipodally(
    cloud: np.ndarray,
    positions: np.ndarray,
    rotations: np.ndarray,
    hand: GripperDescription | None = None,
    friction_angle: float = AntipodalConfig.friction_angle,
) -> np.ndarray:
    """(G,) bool: which grasps (world positions (G, 3), rotation matrices (G, 3, 3)) close on faces of
    ``cloud`` ((M, 6) world points + outward unit normals) that pass step 4's antipodal test within
    ``friction_angle``, where their fingers are: another planner's grasp judged as this one judges its
    own. The closing region is the pads' slab (|x| <= half the pad's width, 0 <= z <= the finger depth)
    within the open hand; points within :data:`TABLE_CLEARANCE` of the lowest cloud point belong to the
    support and do not count (fingertips may rest on it)."""
    jaws = jaws_of(hand or default_gripper())
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    rotations = np.asarray(rotations, dtype=np.float64).reshape(-1, 3, 3)
    cloud = np.asarray(cloud, dtype=np.float64).reshape(-1, 6)
    result = np.zeros(len(positions), dtype=bool)
    if not len(positions) or not len(cloud):
        return result
    cloud = cloud[cloud[:, 2] >= cloud[:, 2].min() + TABLE_CLEARANCE]
    points, normals = cloud[:, :3], cloud[:, 3:]
    normals = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    cos_cone = math.cos(friction_angle)
    half_open = jaws.max_opening / 2 + WIDTH_MARGIN
    radius = math.sqrt(jaws.finger_half_width**2 + half_open**2 + (jaws.finger_depth / 2) ** 2)
    middles = positions + rotations[:, :, 2] * (jaws.finger_depth / 2)
    for g, near in enumerate(cKDTree(points).query_ball_point(middles, radius)):
        local = (points[near] - positions[g]) @ rotations[g]  # world -> grasp frame
        closing = (
            (np.abs(local[:, 0]) <= jaws.finger_half_width)
            & (np.abs(local[:, 1]) <= half_open)
            & (local[:, 2] >= 0.0)
            & (local[:, 2] <= jaws.finger_depth)
        )
        if closing.sum() < AntipodalConfig.min_points:
            continue
        qy = local[closing, 1]
        nx, ny, nz = (normals[near][closing] @ rotations[g]).T  # in the grasp frame
        hi = ((qy >= qy.max() - JAW_TOLERANCE) & (ny > 0.0))[None]
        lo = ((qy <= qy.min() + JAW_TOLERANCE) & (ny < 0.0))[None]
        result[g] = (
            hi.any()
            and lo.any()
            and _mean_normal_cosine(hi, ny, nx, nz)[0] >= cos_cone
            and _mean_normal_cosine(lo, -ny, nx, nz)[0] >= cos_cone
        )
    return result


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a × b`` for two 3-vectors: ``np.cross`` costs more than the rest of a seed's set-up."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _mean_normal_cosine(jaw: np.ndarray, ny: np.ndarray, nu: np.ndarray, nv: np.ndarray) -> np.ndarray:
    """Per depth, the cosine between the mean normal of the ``jaw`` points and +y (``ny``, ``nu``,
    ``nv``: the normals' components along y and two axes across it): a curved face's tilts about
    the contact cancel, a slanted face's do not."""
    count = np.maximum(jaw.sum(axis=-1), 1)
    my, mu, mv = ((jaw * n).sum(axis=-1) / count for n in (ny, nu, nv))
    return my / np.maximum(np.sqrt(my**2 + mu**2 + mv**2), 1e-12)


def _lowest_z(
    origin: np.ndarray,
    x_axis: np.ndarray,
    y_axis: np.ndarray,
    z_axis: np.ndarray,
    centre: np.ndarray,
    half: np.ndarray,
    tips: np.ndarray,
    jaws: Jaws,
) -> np.ndarray:
    """World z of the lowest corner of the fingers and palm, per approach and depth: the axes (3,) or
    (A, 3), ``centre`` and ``half`` (D,) or (A, D), ``tips`` (D,)."""
    finger_half_width, palm_half_y = jaws.finger_half_width, jaws.palm_half_y
    x_z, y_z, z_z = x_axis[..., 2:3], y_axis[..., 2:3], z_axis[..., 2:3]  # their world z, broadcast over D

    def box_min(
        x_lo: float | np.ndarray,
        x_hi: float | np.ndarray,
        y_lo: float | np.ndarray,
        y_hi: float | np.ndarray,
        z_lo: float | np.ndarray,
        z_hi: float | np.ndarray,
    ) -> np.ndarray:
        return (
            np.minimum(x_lo * x_z, x_hi * x_z)
            + np.minimum(y_lo * y_z, y_hi * y_z)
            + np.minimum(z_lo * z_z, z_hi * z_z)
        )

    base = tips - jaws.finger_depth
    hi_finger = box_min(
        -finger_half_width, finger_half_width, centre + half, centre + half + FINGER_THICKNESS, base, tips
    )
    lo_finger = box_min(
        -finger_half_width, finger_half_width, centre - half - FINGER_THICKNESS, centre - half, base, tips
    )
    palm = box_min(
        -PALM_HALF_X, PALM_HALF_X, centre - palm_half_y, centre + palm_half_y, base - jaws.palm_depth, base
    )
    return origin[2] + np.minimum(np.minimum(hi_finger, lo_finger), palm)


def _filters(
    quality: np.ndarray,
    positions: np.ndarray,
    rotations: np.ndarray,
    workspace_pose: np.ndarray,
    config: AntipodalConfig,
) -> np.ndarray:
    return (quality >= config.threshold) & in_region(positions, rotations[:, :, 2], workspace_pose, config)


def in_region(
    positions: np.ndarray,
    approaches: np.ndarray,
    workspace_pose: np.ndarray,
    config: AntipodalConfig | DetectionConfig,
) -> np.ndarray:
    """Which grasps ((G, 3) world positions, (G, 3) approach directions) lie in ``config``'s crop
    box (workspace frame) and approach cone; all where it sets neither."""
    keep = np.ones(len(positions), dtype=bool)
    if config.crop_min is not None or config.crop_max is not None:
        pose = np.asarray(workspace_pose, dtype=np.float64)
        local = (positions - pose[:3, 3]) @ pose[:3, :3]  # world → workspace
        if config.crop_min is not None:
            keep &= np.all(local >= np.asarray(config.crop_min), axis=1)
        if config.crop_max is not None:
            keep &= np.all(local <= np.asarray(config.crop_max), axis=1)
    if config.approach is not None and config.max_approach_angle_rad is not None:
        direction = np.asarray(config.approach, dtype=np.float64)
        direction /= np.linalg.norm(direction)
        cosine = np.clip(approaches @ direction, -1.0, 1.0)
        keep &= np.arccos(cosine) <= config.max_approach_angle_rad
    return keep


def _nms(
    order: np.ndarray, positions: np.ndarray, rotations: np.ndarray, config: AntipodalConfig
) -> list[int]:
    """Greedy suppression in quality order; a π turn about z is the same grasp."""
    flip = np.diag([-1.0, -1.0, 1.0])
    cos_limit = math.cos(config.nms_angle)
    kept: list[int] = []
    for i in order:
        if kept:
            near = np.linalg.norm(positions[kept] - positions[i], axis=1) <= config.nms_distance
            if near.any():
                relative = np.einsum("kji,jl->kil", rotations[kept][near], rotations[i])  # Rkᵀ Ri
                trace = np.trace(relative, axis1=1, axis2=2)
                trace_flip = np.trace(relative @ flip, axis1=1, axis2=2)
                cos_angle = (np.maximum(trace, trace_flip) - 1) / 2
                if np.any(cos_angle >= cos_limit):
                    continue
        kept.append(int(i))
    return kept
