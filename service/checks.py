"""The checks a planned grasp must pass, chained in one place, with other poses for those they drop.

The network answers one orientation per location. When the clearance or the grip check drops it,
the location is often still graspable: turned about its approach the fingers meet two faces
squarely, tilted the palm misses a neighbour, stepped back the fingertips miss the table. So each
dropped grasp is tried again in the poses of :data:`ALTERNATIVES`; the network never scored these,
so a pose counts only when the grip check sees both fingers grip at the square grip
(``GripConfig.preferred_alignment``), and the squarest replaces the grasp with the location's
quality. Without this a look whose few confident locations fail a check offers nothing, and the
robot stops with objects on the table. Frames: docs/conventions.md (tilts turn about the pads).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from service.clearance import (
    ClearanceConfig,
    above_table_outside,
    approach_is_clear,
    continued_past_sides,
    fingers_inside,
)
from service.grip import GripConfig, GripMeasure, measure_grip, support_height
from service.hands import active_hand
from vgn_contract.schemas import Grasp

#: Alternative hand poses tried for a dropped grasp, as (turn about the approach, tilt of the
#: approach about the closing axis) in degrees and a step back along the approach in metres: turns
#: (the fingers meet other faces at the same place), tilts (the hand comes in from beside an
#: obstacle) and steps back (the fingertips stop short of the table under a flat object).
ALTERNATIVES = (
    (20, 0, 0.0), (-20, 0, 0.0), (45, 0, 0.0), (-45, 0, 0.0), (90, 0, 0.0),
    (0, 20, 0.0), (0, -20, 0.0), (90, 20, 0.0), (90, -20, 0.0),
    (0, 0, 0.01), (90, 0, 0.01), (0, 0, 0.02),
)  # fmt: skip
#: How far short of the grasp pose (m) the fingertips may meet the support plane, and how close to
#: it (in voxels) a surface point counts as the plane's: the TSDF places a table within a fraction
#: of a voxel. The distance is the hand's own: the check grows the hand by its margin, whose
#: fingertips meet the plane that much sooner (:func:`contact_tolerances`).
SUPPORT_CONTACT_TOLERANCE = 0.01
SUPPORT_BAND_VOXELS = 0.25
#: At most this many dropped grasps (the best ranked) are tried again: each costs
#: ``len(ALTERNATIVES)`` more checked poses.
MAX_RETRIED = 6


@dataclass(frozen=True)
class Checked:
    """Grasps after the checks, in their ranked order, with what happened to the others:
    ``workspace_dropped`` (open fingers outside the workspace cube), ``clearance_dropped`` (the
    approach hits the observed surface) and ``grip_dropped`` count grasps each stage dropped for good,
    each grasp in the first stage that drops it (None where the stage did not run: the workspace bound
    runs with the clearance check), ``replaced`` those that pass only in an alternative pose."""

    grasps: list[Grasp]
    clearance_dropped: int | None
    grip_dropped: int | None
    replaced: int
    workspace_dropped: int | None = None


def check_grasps(
    grasps: list[Grasp],
    surface: np.ndarray | None,
    grid: np.ndarray | None,
    voxel_size: float,
    workspace_pose: np.ndarray,
    workspace_size: float,
    grip_config: GripConfig = GripConfig(),  # noqa: B008 (frozen: one shared default is safe)
    alternatives: bool = True,
    clearance: ClearanceConfig = ClearanceConfig(),  # noqa: B008 (frozen: one shared default is safe)
    past_sides: bool = True,
) -> Checked:
    """Run the clearance check on ``surface`` (world-frame points; None: not run) and the grip check
    on ``grid`` (the network's input; None: not run) over ``grasps`` (world frame, best first),
    trying :data:`ALTERNATIVES` for the dropped ones when ``alternatives``. The clearance check (its
    settings ``clearance``) also drops grasps whose open fingers reach outside the workspace cube
    (``workspace_size``, m), and takes the surface to go on past the cube's sides where it meets them
    unless told not to (``past_sides``)."""
    if not grasps or (surface is None and grid is None):
        return Checked(list(grasps), _count(surface, 0), _count(grid, 0), 0, _count(surface, 0))
    seen = observed_for_checks(
        surface, grid, voxel_size, workspace_pose, workspace_size, clearance, past_sides=past_sides
    )
    positions = np.array([g.position for g in grasps], dtype=np.float64)
    orientations = Rotation.from_quat([g.orientation for g in grasps])
    inside, approach_clear, measure = _stages(positions, orientations, seen)
    clear = inside & approach_clear
    passes = clear & _grip_passes(measure, len(grasps), grip_config)
    chosen: list[Grasp | None] = [g if ok else None for g, ok in zip(grasps, passes, strict=True)]
    square = np.zeros(len(grasps), dtype=bool) if measure is None else measure.square(grip_config)
    alternative = np.zeros(len(grasps), dtype=bool)
    # Only the grip check can vouch for a pose the network never scored: without it, no alternatives.
    retried = (
        np.flatnonzero(~passes)[:MAX_RETRIED] if alternatives and grid is not None else np.zeros(0, dtype=int)
    )
    if len(retried):
        owner, alt_positions, alt_orientations = _alternative_poses(positions[retried], orientations[retried])
        # The grip check first: it is the cheaper one and drops most poses, so the clearance check
        # (the costly one, over every surface point) runs only on the poses it vouches for.
        alt_measure = _grip_measure(alt_positions, alt_orientations, seen)
        alt_square = alt_measure.square(grip_config)
        alt_passes = alt_square & (alt_measure.known > 0.0).all(axis=1)  # square implies passing
        vouched = np.flatnonzero(alt_passes)
        if surface is not None and len(vouched):
            alt_passes[vouched] = _clear(alt_positions[vouched], alt_orientations[vouched], seen)
        for slot, index in enumerate(retried):
            candidates = np.flatnonzero(alt_passes & (owner == slot))
            if not len(candidates):
                continue
            best = candidates[_squarest(alt_measure, candidates)]
            chosen[index] = _moved(
                grasps[index], alt_positions[best], alt_orientations[best], alt_measure, best
            )
            square[index] = alt_square[best]
            alternative[index] = True
    kept_mask = np.array([g is not None for g in chosen])
    if grid is not None and (square & kept_mask).any():
        kept_mask &= square  # where some grasps grip squarely, only those
    dropped = ~kept_mask
    by_workspace = int((~inside & dropped).sum()) if surface is not None else None
    by_clearance = int((inside & ~approach_clear & dropped).sum()) if surface is not None else None
    by_grip = int((clear & dropped).sum()) if grid is not None else None
    kept = [g for g, keep in zip(chosen, kept_mask, strict=True) if keep and g is not None]
    return Checked(kept, by_clearance, by_grip, int((alternative & kept_mask).sum()), by_workspace)


def passes_checks(
    positions: np.ndarray,
    orientations: np.ndarray,
    surface: np.ndarray | None,
    grid: np.ndarray | None,
    voxel_size: float,
    workspace_pose: np.ndarray,
    workspace_size: float,
    grip_config: GripConfig = GripConfig(),  # noqa: B008 (frozen: one shared default is safe)
) -> np.ndarray:
    """(G,) bool: which grasps (world-frame positions and [x, y, z, w] orientations) pass the
    chain :func:`check_grasps` starts with, each judged alone in its own pose: clear of
    ``surface`` with its fingers in the workspace cube, gripping on ``grid`` (None: not run).
    A teacher labelling what the service would drop asks this."""
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    if not len(positions):
        return np.zeros(0, dtype=bool)
    seen = observed_for_checks(surface, grid, voxel_size, workspace_pose, workspace_size)
    rotations = Rotation.from_quat(np.asarray(orientations, dtype=np.float64).reshape(-1, 4))
    clear, measure = _judge(positions, rotations, seen)
    return clear & _grip_passes(measure, len(positions), grip_config)


def clear_of(
    grasps: list[Grasp],
    points: np.ndarray,
    grid: np.ndarray | None,
    voxel_size: float,
    workspace_pose: np.ndarray,
    workspace_size: float,
    clearance: ClearanceConfig = ClearanceConfig(),  # noqa: B008 (frozen: one shared default is safe)
    spacing: float | None = None,
    past_sides: bool = True,
) -> list[Grasp]:
    """The ``grasps`` whose open hand's approach misses ``points`` (world frame, ``spacing`` m apart;
    default ``voxel_size``), judged as :func:`check_grasps` judges its surface with ``clearance``: the
    support plane (found on ``grid``; None: none) may meet the fingertips in the approach's last
    :data:`SUPPORT_CONTACT_TOLERANCE`. The surface's antipodal pairs are cleared so against the fine
    cloud they were found on, whose 2.5 mm surface shows what brushes past the fingers between the
    grid's 7.5 mm crossings. ``past_sides`` as :func:`check_grasps` takes it."""
    if not grasps:
        return []
    seen = observed_for_checks(np.asarray(points, dtype=np.float64).reshape(-1, 3), grid, voxel_size, workspace_pose,
                               workspace_size, clearance, spacing, past_sides)  # fmt: skip
    positions = np.array([g.position for g in grasps], dtype=np.float64)
    clear = approach_is_clear_of(positions, np.array([g.orientation for g in grasps], dtype=np.float64), seen)
    return [g for g, ok in zip(grasps, clear, strict=True) if ok]


def _count(check_input: np.ndarray | None, dropped: int) -> int | None:
    return None if check_input is None else dropped


@dataclass(frozen=True)
class ObservedScene:
    """What a request's grasps are judged against, worked out once for all their poses: the world
    frame surface (None: no clearance check) with each point's contact tolerance, the grid (None:
    no grip check), the workspace, the support plane's height (None: none found, or no grid) and the
    clearance check's settings."""

    surface: np.ndarray | None
    tolerance: np.ndarray | None
    grid: np.ndarray | None
    voxel_size: float
    to_workspace: np.ndarray
    workspace_size: float
    support: float | None
    clearance: ClearanceConfig = ClearanceConfig()  # noqa: RUF009 (frozen: one shared default is safe)


def observed_for_checks(
    surface: np.ndarray | None,
    grid: np.ndarray | None,
    voxel_size: float,
    workspace_pose: np.ndarray,
    workspace_size: float,
    clearance: ClearanceConfig = ClearanceConfig(),  # noqa: B008 (frozen: one shared default is safe)
    spacing: float | None = None,
    past_sides: bool = True,
) -> ObservedScene:
    """What grasps are judged against; ``surface``'s points lie ``spacing`` m apart (default: the
    grid's crossings, ``voxel_size``) and, with ``past_sides`` (the service's way but for its last
    resort, where nothing clears so), go on past the cube's sides where they meet them."""
    to_workspace = np.linalg.inv(np.asarray(workspace_pose, dtype=np.float64))
    support = None if grid is None else support_height(grid, voxel_size)
    tolerance = None
    if surface is not None and past_sides:
        floor = None if support is None else support + SUPPORT_BAND_VOXELS * voxel_size
        beyond = continued_past_sides(surface, to_workspace, workspace_size, spacing or voxel_size, floor)
        surface = np.vstack([surface, beyond]) if len(beyond) else surface
    if surface is not None and support is not None:
        tolerance = contact_tolerances(surface, to_workspace, support, voxel_size, clearance.margin)
    return ObservedScene(
        surface, tolerance, grid, voxel_size, to_workspace, workspace_size, support, clearance
    )


def _judge(
    positions: np.ndarray, orientations: Rotation, seen: ObservedScene
) -> tuple[np.ndarray, GripMeasure | None]:
    """Clearance (G,) bool (all True without a surface) and the grip measure (None without a grid)."""
    inside, approach_clear, measure = _stages(positions, orientations, seen)
    return inside & approach_clear, measure


def _stages(
    positions: np.ndarray, orientations: Rotation, seen: ObservedScene
) -> tuple[np.ndarray, np.ndarray, GripMeasure | None]:
    """Each stage's verdict apart, so an answer can say which dropped a grasp: fingers inside the
    cube (G,) bool and a clear approach (G,) bool (both all True without a surface), and the grip
    measure (None without a grid)."""
    inside = approach_clear = np.ones(len(positions), dtype=bool)
    if seen.surface is not None:
        quaternions = orientations.as_quat()
        inside = fingers_inside(positions, quaternions, seen.to_workspace, seen.workspace_size)
        approach_clear = approach_is_clear_of(positions, quaternions, seen)
    measure = None if seen.grid is None else _grip_measure(positions, orientations, seen)
    return inside, approach_clear, measure


def _clear(positions: np.ndarray, orientations: Rotation, seen: ObservedScene) -> np.ndarray:
    """(G,) bool: the open hand's approach misses the surface and its fingers stay in the cube."""
    quaternions = orientations.as_quat()
    inside = fingers_inside(positions, quaternions, seen.to_workspace, seen.workspace_size)
    return inside & approach_is_clear_of(positions, quaternions, seen)


def approach_is_clear_of(positions: np.ndarray, quaternions: np.ndarray, seen: ObservedScene) -> np.ndarray:
    """(G,) bool: the open hand's approach misses the surface, and the table where it goes on past the
    cube's sides. The support plane may meet the hand in the last :data:`SUPPORT_CONTACT_TOLERANCE`
    of the approach (:func:`contact_tolerances`): fingertips on the table stop a guarded approach
    there, around a flat object."""
    clear = approach_is_clear(
        seen.surface, positions, quaternions, seen.clearance, point_tolerance=seen.tolerance
    )
    return clear & above_table_past_sides(positions, quaternions, seen)


def above_table_past_sides(positions: np.ndarray, quaternions: np.ndarray, seen: ObservedScene) -> np.ndarray:
    """(G,) bool: the open hand stays above the support plane where it goes on past the cube's sides
    (all True where no plane was found). The plane's points stand for a table up to their band lower,
    and the hand may meet it as late in the approach as it may meet them."""
    if seen.support is None:
        return np.ones(len(positions), dtype=bool)
    lowest = seen.support - SUPPORT_BAND_VOXELS * seen.voxel_size
    last = support_tolerance(seen.voxel_size, seen.clearance.margin)
    return above_table_outside(
        positions, quaternions, seen.to_workspace, seen.workspace_size, lowest, seen.clearance, first=last
    )


def contact_tolerances(
    surface: np.ndarray, to_workspace: np.ndarray, support: float, voxel_size: float, margin: float
) -> np.ndarray:
    """(M,) the clearance check's contact tolerance (m) for each surface point (world frame):
    on the support plane (``support``, workspace z), :data:`SUPPORT_CONTACT_TOLERANCE` for the hand
    as built, so plus the ``margin`` the check grows it by (a guarded approach stops when the real
    fingertips, not the grown ones, meet the table) and the band the plane's points lie in (they
    stand for a table up to that much lower). The usual tolerance elsewhere."""
    height = surface @ to_workspace[2, :3] + to_workspace[2, 3]  # workspace z: up
    on_support = np.abs(height - support) < SUPPORT_BAND_VOXELS * voxel_size
    return np.where(on_support, support_tolerance(voxel_size, margin), ClearanceConfig().contact_tolerance)


def support_tolerance(voxel_size: float, margin: float) -> float:
    """How far short of the grasp pose (m) the hand grown by ``margin`` may meet the support plane."""
    return SUPPORT_CONTACT_TOLERANCE + margin + SUPPORT_BAND_VOXELS * voxel_size


def _grip_measure(positions: np.ndarray, orientations: Rotation, seen: ObservedScene) -> GripMeasure:
    """The grip check's measure of world-frame grasps on the workspace-frame grid."""
    to_workspace = seen.to_workspace
    local_positions = positions @ to_workspace[:3, :3].T + to_workspace[:3, 3]
    local = Rotation.from_matrix(to_workspace[:3, :3]) * orientations
    return measure_grip(seen.grid, seen.voxel_size, local_positions, local.as_quat(), support=seen.support)


def _grip_passes(measure: GripMeasure | None, count: int, config: GripConfig) -> np.ndarray:
    return np.ones(count, dtype=bool) if measure is None else measure.passes(config)


def _squarest(measure: GripMeasure, rows: np.ndarray) -> int:
    """Which of ``rows`` (poses whose both fingers the check sees) grips most squarely: the highest
    alignment of its worse finger."""
    return int(np.argmax(measure.alignment[rows].min(axis=1)))


def _alternative_poses(
    positions: np.ndarray, orientations: Rotation
) -> tuple[np.ndarray, np.ndarray, Rotation]:
    """Every pose of :data:`ALTERNATIVES` for each grasp: the owning grasp's slot (K,), positions
    (K, 3) and orientations, grasp by grasp in the order of the table."""
    table = np.asarray(ALTERNATIVES, dtype=np.float64)
    turns = Rotation.from_euler("ZY", table[:, :2], degrees=True)  # turn about z, then tilt about the new y
    count, per = len(positions), len(table)
    owner = np.repeat(np.arange(count), per)
    base = orientations[owner]
    moved = base * Rotation.concatenate([turns] * count)
    # The pivot stays where it was (p' = p + R c - R' c), then the hand steps back along its approach.
    step_back = np.tile(table[:, 2], count)[:, None] * moved.apply([0.0, 0.0, 1.0])
    pivot = np.array([0.0, 0.0, active_hand().pad_middle])  # the hand turns about the middle of its pads
    new_positions = positions[owner] + base.apply(pivot) - moved.apply(pivot) - step_back
    return owner, new_positions, moved


def _moved(
    grasp: Grasp, position: np.ndarray, orientation: Rotation, measure: GripMeasure, row: int
) -> Grasp:
    """``grasp`` in another pose, its opening measured where the fingers met the surface."""
    width = grasp.width
    if (measure.known[row] == 1.0).all() and (measure.contact[row] == 1.0).all():
        max_opening = active_hand().max_opening
        width = float(np.clip(max_opening - measure.reach[row].sum(), 0.0, max_opening))
    return grasp.model_copy(
        update={
            "position": position.tolist(),
            "orientation": orientation.as_quat().tolist(),
            "approach": orientation.apply([0.0, 0.0, 1.0]).tolist(),
            "width": width,
        }
    )
