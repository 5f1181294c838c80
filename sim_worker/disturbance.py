"""Disturbances: the scene changes between the plan and the grasp.

A robot's plan goes stale when something moves after it looked: a person reaches in, a
neighbour topples, the object slides. ``Disturber`` reproduces that in the simulator: with
probability ``probability`` per grasp attempt, at a seeded moment of the approach, the object
the grasp aims at is pushed a few centimetres across the table or lifted and dropped onto the
pile. Open loop executes the stale grasp; a closed loop has to notice.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation

from sim_worker.world import WORKSPACE_SIZE, World

PUSH_DISTANCE = (0.03, 0.06)  # m, across the table
PUSH_YAW_DEG = 30.0  # the object also turns by up to this about the vertical
DROP_HEIGHT = (0.05, 0.10)  # m above where it was
DROP_SHARE = 0.25  # of the disturbances; the others are pushes
#: The moment, as a share of the approach's 2 mm steps: within its first half, so the hand has
#: not reached the object yet.
MOMENT = (0.05, 0.5)
#: A pushed object may not end up interpenetrating another body by more than this.
MAX_PENETRATION = 0.002
WORKSPACE_MARGIN = 0.03  # m: a pushed object's centre stays this far inside the workspace
PUSH_TRIES = 8


@dataclass(frozen=True)
class PlannedDisturbance:
    """What will happen in one attempt, drawn before the approach so it is the same for open
    and closed loop on the same scene."""

    step_share: float  # when, as a share of the approach
    kind: Literal["push", "drop"]
    distance: float  # push distance or drop height, metres
    angle: float  # push direction about world z, radians
    yaw: float  # turn about world z, radians

    def step(self, count: int) -> int:
        """The approach step (1-based, of ``count``) after which the object moves."""
        return max(1, min(count, int(round(self.step_share * count))))


@dataclass(frozen=True)
class Disturbance:
    """What did happen: which body moved, how, and how far its centre went (metres)."""

    body: int
    kind: Literal["push", "drop"]
    moved: float


class Disturber:
    """Draws and applies disturbances from its own seeded stream."""

    def __init__(self, probability: float, rng: np.random.Generator) -> None:
        if not 0.0 <= probability <= 1.0:
            raise ValueError(f"disturbance probability must be in [0, 1], got {probability}")
        self.probability = probability
        self.rng = rng

    def draw(self) -> PlannedDisturbance | None:
        """This attempt's disturbance, or None (every draw uses the stream alike either way)."""
        happens, share, kind, push, drop, angle, yaw = self.rng.random(7)
        if happens >= self.probability:
            return None
        dropped = kind < DROP_SHARE
        return PlannedDisturbance(
            step_share=MOMENT[0] + share * (MOMENT[1] - MOMENT[0]),
            kind="drop" if dropped else "push",
            distance=float(
                np.interp(drop if dropped else push, (0, 1), DROP_HEIGHT if dropped else PUSH_DISTANCE)
            ),
            angle=float(angle * 2 * np.pi),
            yaw=float(np.deg2rad((2 * yaw - 1) * PUSH_YAW_DEG)),
        )

    def apply(self, world: World, planned: PlannedDisturbance, target: np.ndarray) -> Disturbance | None:
        """Move the object nearest ``target`` (the grasp position) as ``planned``; None when the
        table is empty. A push that would bury the object in another body (the hand included)
        is tried in other directions and becomes a drop when none is free."""
        body = nearest_object(world, target)
        if body is None:
            return None
        position, orientation = world.object_pose(body)
        turned = (Rotation.from_euler("z", planned.yaw) * Rotation.from_quat(orientation)).as_quat()
        kind = planned.kind
        if kind == "push":
            for attempt in range(PUSH_TRIES):
                angle = planned.angle + attempt * 2 * np.pi / PUSH_TRIES
                moved = position + planned.distance * np.array([np.cos(angle), np.sin(angle), 0.0])
                moved[2] += 0.002  # just off the table, so it settles instead of starting in contact
                if inside_workspace(moved) and placed_freely(world, body, moved, turned):
                    break
            else:
                kind = "drop"
        if kind == "drop":
            height = planned.distance if planned.kind == "drop" else DROP_HEIGHT[0]
            moved = position + np.array([0.0, 0.0, height])
            world.p.resetBasePositionAndOrientation(body, moved.tolist(), turned.tolist())
        world.p.resetBaseVelocity(body, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
        return Disturbance(body, kind, float(np.linalg.norm(moved - position)))


def nearest_object(world: World, point: np.ndarray) -> int | None:
    """The object whose bounding box is closest to ``point`` (0 inside it); None if none."""
    best, best_distance = None, np.inf
    for body in world.objects:
        lower, upper = world.aabb(body)
        distance = float(np.linalg.norm(np.maximum(np.maximum(lower - point, point - upper), 0.0)))
        if distance < best_distance:
            best, best_distance = body, distance
    return best


def inside_workspace(position: np.ndarray) -> bool:
    """Whether a centre lies inside the workspace's footprint, with a margin."""
    low, high = WORKSPACE_MARGIN, WORKSPACE_SIZE - WORKSPACE_MARGIN
    return bool(low <= position[0] <= high and low <= position[1] <= high)


def placed_freely(world: World, body: int, position: np.ndarray, orientation: np.ndarray) -> bool:
    """Put ``body`` at the pose and keep it there when it overlaps no other body by more than
    ``MAX_PENETRATION``; otherwise put it back and say so."""
    before = world.object_pose(body)
    world.p.resetBasePositionAndOrientation(body, position.tolist(), orientation.tolist())
    world.p.performCollisionDetection()
    for other in range(world.p.getNumBodies()):
        other_id = world.p.getBodyUniqueId(other)
        if other_id == body:
            continue
        for contact in world.p.getClosestPoints(body, other_id, 0.0):
            if contact[8] < -MAX_PENETRATION:
                world.p.resetBasePositionAndOrientation(body, before[0].tolist(), before[1].tolist())
                return False
    return True
