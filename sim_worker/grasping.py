"""Executing one grasp in simulation, VGN's protocol (docs/conventions.md, "Grasp execution")."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum

import numpy as np

from sim_worker.gripper import Gripper
from sim_worker.world import World

LIFT_DISTANCE = 0.10  # m
#: Beyond this angle from straight down, lifting goes along world z instead of back along the approach.
STEEP_APPROACH = np.pi / 3


class Outcome(str, Enum):
    """How an attempt ended. Failures are told apart so a benchmark says *why* grasps fail."""

    SUCCESS = "success"
    #: The open hand at the pre-grasp pose already touched something.
    PREGRASP_COLLISION = "pregrasp_collision"
    #: The approach touched something and contact was not allowed (labelling): not closed.
    APPROACH_COLLISION = "approach_collision"
    #: The approach stopped on contact before the grasp pose, the hand closed there and held nothing.
    APPROACH_CONTACT = "approach_contact"
    #: The hand reached the grasp pose and closed on nothing.
    NOTHING_HELD = "nothing_held"
    #: Something was between the fingers after closing but not after the lift.
    SLIPPED = "slipped"
    #: A closed loop stopped the approach before the hand closed (the scene changed): no attempt.
    INTERRUPTED = "interrupted"


#: The failure classes of a benchmark table, in the order they are shown.
FAILURE_OUTCOMES = (
    Outcome.APPROACH_CONTACT,
    Outcome.NOTHING_HELD,
    Outcome.SLIPPED,
    Outcome.PREGRASP_COLLISION,
    Outcome.APPROACH_COLLISION,
)


@dataclass
class GraspTrial:
    """What happened: ``label`` is 1 when an object was lifted and held.

    When the approach stopped on contact, ``contact_bodies`` are the bodies the hand touched
    and ``contact_distance`` how far (m) before the grasp pose it stopped. ``closed_on`` are the
    objects the closed hand touched: what a failed grasp was on, to tell which objects fail."""

    outcome: Outcome
    width: float  # finger opening at the end (m); the max opening after a collision
    grasped_body: int | None
    sim_steps: int
    seconds: float
    contact_bodies: tuple[int, ...] = ()
    contact_distance: float | None = None
    closed_on: tuple[int, ...] = ()

    @property
    def label(self) -> int:
        """The dataset's label: 1 for a success, 0 for every kind of failure."""
        return int(self.outcome is Outcome.SUCCESS)


def translated(pose: np.ndarray, offset_in_pose_frame: np.ndarray) -> np.ndarray:
    """``pose`` moved by ``offset_in_pose_frame``, given along the pose's own axes."""
    moved = pose.copy()
    moved[:3, 3] = pose[:3, 3] + pose[:3, :3] @ np.asarray(offset_in_pose_frame, dtype=np.float64)
    return moved


def retreat_pose(grasp_pose: np.ndarray) -> np.ndarray:
    """Where to lift to: back along the approach for top-down-ish grasps, else straight up."""
    approach = grasp_pose[:3, 2]
    angle = np.arccos(np.clip(approach @ np.array([0.0, 0.0, -1.0]), -1.0, 1.0))
    if angle > STEEP_APPROACH:
        lifted = grasp_pose.copy()
        lifted[2, 3] += LIFT_DISTANCE
        return lifted
    return translated(grasp_pose, [0.0, 0.0, -LIFT_DISTANCE])


def execute_grasp(
    world: World,
    gripper: Gripper,
    grasp_pose: np.ndarray,
    allow_contact: bool = True,
    remove_grasped: bool = True,
    fast: bool = False,
    on_waypoint: Callable[[int, int], bool] | None = None,
    on_contact: Callable[[], bool] | None = None,
    on_lift: Callable[[int, int], None] | None = None,
) -> GraspTrial:
    """Try a grasp whose frame is ``grasp_pose`` (4×4, world; +z approach, y closing axis).

    Spawn open at the pre-grasp 5 cm back along the approach (contact there fails), move
    straight in, stopping on contact (a failure unless ``allow_contact``), close, lift 10 cm,
    and succeed when something is still between the fingers. The grasped object is removed
    when ``remove_grasped``; the gripper is parked afterwards either way. ``fast`` (labelling,
    with ``allow_contact=False``) gives the same outcomes for less physics.

    ``on_waypoint(n, count)`` runs after each 2 mm step of the approach; when it returns True the
    hand stops there, open, and the trial ends ``INTERRUPTED`` (no grasp attempt).
    ``on_contact()`` runs when the approach stopped on contact; True ends the trial so too.
    ``on_lift(n, count)`` runs after each step of the lift, to watch how a held object is lost."""
    if fast and allow_contact:
        raise ValueError("fast execution sweeps the approach kinematically: it needs allow_contact=False")
    started, first_step = time.perf_counter(), world.sim_time

    contact: tuple[tuple[int, ...], float] | None = None
    closed_on: tuple[int, ...] = ()

    def finish(outcome: Outcome, width: float, body: int | None = None) -> GraspTrial:
        gripper.park()
        steps = round((world.sim_time - first_step) / world.config.timestep)
        bodies, distance = contact if contact else ((), None)
        seconds = time.perf_counter() - started
        return GraspTrial(outcome, width, body, steps, seconds, bodies, distance, closed_on)

    pregrasp_distance = gripper.spec.pregrasp_distance
    gripper.reset(translated(grasp_pose, [0.0, 0.0, -pregrasp_distance]))
    if gripper.collides_now():
        contact = (tuple(sorted(gripper.touching())), pregrasp_distance)
        return finish(Outcome.PREGRASP_COLLISION, gripper.spec.max_opening)
    if fast:
        stopped_on_contact = not gripper.sweep_is_clear(grasp_pose)
    else:
        stopped_on_contact = gripper.move_to(grasp_pose, abort_on_contact=True, on_waypoint=on_waypoint)
        if gripper.interrupted:
            return finish(Outcome.INTERRUPTED, gripper.opening())
    if stopped_on_contact:
        distance = float(np.linalg.norm(grasp_pose[:3, 3] - gripper.last_contact_position))
        contact = (tuple(sorted(gripper.last_contact)), round(distance, 4))
        if not allow_contact:
            return finish(Outcome.APPROACH_COLLISION, gripper.spec.max_opening)
        if on_contact is not None and on_contact():
            return finish(Outcome.INTERRUPTED, gripper.opening())
    empty = gripper.spec.hand.held_opening
    gripper.close(stop_when_empty=empty if fast else None)
    closed_on = tuple(sorted(gripper.touching() & set(world.objects)))
    closed_on_something = gripper.opening() > empty and bool(
        gripper.bodies_between_fingers() & set(world.objects)
    )
    if not closed_on_something:
        missed = Outcome.APPROACH_CONTACT if stopped_on_contact else Outcome.NOTHING_HELD
        return finish(missed, gripper.opening())

    def lifting(n: int, count: int) -> bool:
        if on_lift is not None:
            on_lift(n, count)
        return False  # a lift is never interrupted

    gripper.move_to(
        retreat_pose(grasp_pose), abort_on_contact=False, abort_below_opening=empty if fast else None,
        on_waypoint=lifting if on_lift is not None else None,
    )  # fmt: skip
    width = gripper.opening()
    held = gripper.bodies_between_fingers() & set(world.objects)
    if width <= empty or not held:
        return finish(Outcome.SLIPPED, width)
    body = min(held)
    if remove_grasped:
        world.remove_object(body)
    return finish(Outcome.SUCCESS, width, body)
