"""A free-floating parallel-jaw gripper whose base frame is the grasp frame (docs/conventions.md).

The hand is a gripper description (vgn_contract/grippers/, or a user's file; default ``franka``): its
URDF (the one it names, else one built from its boxes: sim_worker/hand_urdf.py), opening, finger
depth, closing force and pre-grasp distance all come from there."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pybullet

from sim_worker.hand_urdf import hand_urdf
from sim_worker.world import World
from vgn_contract.geometry import pose_from_matrix
from vgn_contract.gripper_description import GripperDescription, default_gripper

#: The default simulated hand: ``franka``, the hand of every dataset and result so far.
HAND: GripperDescription = default_gripper()
#: Which hand made a label (the default hand's; a run records its own hand's ``version``). Datasets
#: record it, and data of different versions is never mixed: a label says what *this* hand can do.
#: ``box-v1`` was the earlier 12 mm box-finger hand.
GRIPPER_VERSION = HAND.version
#: How far (in 2 mm waypoints) a contact-stopped approach may back off to stop pressing.
MAX_BACK_OFF_STEPS = 3
#: Where the gripper waits between grasps: far outside the workspace and every camera's view.
PARKED_POSITION = (0.15, 0.15, 10.0)


@dataclass(frozen=True)
class GripperSpec:
    """The simulated hand's parameters: geometry and closing force from its description ``hand``
    (``finger_force`` left unset: the description's closing force), friction and motion as in
    VGN's simulation, the same for every hand."""

    hand: GripperDescription = HAND
    finger_force: float | None = None  # N per finger while closing
    finger_friction: float = 1.0
    #: Rubber pads: a compliant contact (N/m, N·s/m) instead of a rigid one, so a pad yields a
    #: few millimetres under the closing force and grips with an area rather than a point.
    pad_contact_stiffness: float = 3.0e4
    pad_contact_damping: float = 1.0e2
    #: Torsional friction of the pads about the contact normal (m: torque per newton of normal
    #: force). PyBullet's default, 0, lets an object pivot freely about the closing axis.
    pad_spinning_friction: float = 0.0
    hold_force: float = 300.0  # N of the constraint that carries the hand
    close_duration: float = 0.5  # s
    step_length: float = 0.002  # m per motion step
    speed: float = 0.10  # m/s of motion

    def __post_init__(self) -> None:
        if self.finger_force is None:
            object.__setattr__(self, "finger_force", self.hand.force.closing)

    @property
    def max_opening(self) -> float:
        """The fully open width (m): the hand approaches with it."""
        return self.hand.max_opening

    @property
    def finger_depth(self) -> float:
        """From the grasp frame's origin to the fingertips along the approach (m)."""
        return self.hand.finger_depth

    @property
    def pregrasp_distance(self) -> float:
        """How far (m) back along the approach the open hand starts."""
        return self.hand.pregrasp_distance


class Gripper:
    """The hand is a dynamic body carried by a fixed constraint (so it pushes and is pushed
    like VGN's); fingers are prismatic joints coupled by a gear so they close symmetrically."""

    def __init__(self, world: World, spec: GripperSpec = GripperSpec()) -> None:
        self.world, self.spec = world, spec
        p = world.p
        self.body = p.loadURDF(str(hand_urdf(spec.hand)), PARKED_POSITION, (0, 0, 0, 1))
        self.interrupted = False  # the last move_to was stopped by its on_waypoint
        names = {p.getJointInfo(self.body, j)[1].decode(): j for j in range(p.getNumJoints(self.body))}
        self.fingers = (names["left_finger_joint"], names["right_finger_joint"])
        self.use_spec(spec)
        gear = p.createConstraint(
            self.body,
            self.fingers[0],
            self.body,
            self.fingers[1],
            pybullet.JOINT_GEAR,
            [0, 1, 0],
            [0, 0, 0],
            [0, 0, 0],
        )
        p.changeConstraint(gear, gearRatio=-1, erp=0.1, maxForce=50)
        self.constraint = p.createConstraint(
            self.body, -1, -1, -1, pybullet.JOINT_FIXED, [0, 0, 0], [0, 0, 0], PARKED_POSITION
        )
        #: What the last approach that stopped on contact touched (body ids).
        self.last_contact: set[int] = set()
        self.last_contact_position = np.zeros(3)
        self.steps_per_motion = max(1, round(spec.step_length / spec.speed / world.config.timestep))
        self.park()

    def use_spec(self, spec: GripperSpec) -> None:
        """Give the hand ``spec``'s pad contact and, from the next reset or close, its finger force:
        a benchmark compares hands on one saved state. Call it after ``World.restore_state``, which
        does not restore contact parameters. Motion settings stay those the hand was made with, and
        the hand itself: another description needs a new ``Gripper``."""
        if spec.hand != self.spec.hand:
            raise ValueError(
                f"this gripper is the {self.spec.hand.name!r} hand: make a new one for {spec.hand.name!r}"
            )
        self.spec = spec
        for finger in self.fingers:
            self.world.p.changeDynamics(
                self.body,
                finger,
                lateralFriction=spec.finger_friction,
                contactStiffness=spec.pad_contact_stiffness,
                contactDamping=spec.pad_contact_damping,
                spinningFriction=spec.pad_spinning_friction,
            )

    # Placement ----------------------------------------------------------------------------
    def reset(self, pose: np.ndarray, opening: float | None = None) -> None:
        """Teleport the hand so its grasp frame is at ``pose`` (4×4 in the world), fingers
        opened to ``opening`` (default: fully), without stepping physics."""
        p = self.world.p
        position, orientation = pose_from_matrix(pose)
        p.resetBasePositionAndOrientation(self.body, position, orientation)
        p.resetBaseVelocity(self.body, [0, 0, 0], [0, 0, 0])
        self._hold(position, orientation)
        half = 0.5 * (self.spec.max_opening if opening is None else opening)
        for finger in self.fingers:
            p.resetJointState(self.body, finger, half)
            p.setJointMotorControl2(
                self.body,
                finger,
                pybullet.POSITION_CONTROL,
                targetPosition=half,
                force=self.spec.finger_force,
            )

    def park(self) -> None:
        """Move the hand out of the scene, so it neither shows in renders nor touches objects."""
        pose = np.eye(4)
        pose[:3, 3] = PARKED_POSITION
        self.reset(pose)

    def _hold(self, position: np.ndarray, orientation: np.ndarray) -> None:
        self.world.p.changeConstraint(
            self.constraint, position, jointChildFrameOrientation=orientation, maxForce=self.spec.hold_force
        )

    # State --------------------------------------------------------------------------------
    def pose(self) -> np.ndarray:
        """The hand's grasp frame now, 4×4 world."""
        position, orientation = self.world.p.getBasePositionAndOrientation(self.body)
        from vgn_contract.geometry import matrix_from_pose

        return matrix_from_pose(np.asarray(position), np.asarray(orientation))

    def opening(self) -> float:
        """Current distance between the inner finger faces, metres."""
        return float(sum(self.world.p.getJointState(self.body, f)[0] for f in self.fingers))

    def position(self) -> np.ndarray:
        """Where the grasp frame's origin is now (world, metres)."""
        return np.asarray(self.world.p.getBasePositionAndOrientation(self.body)[0])

    def touching(self) -> set[int]:
        """Bodies in contact with the hand or fingers (after ``performCollisionDetection``)."""
        return {c[2] for c in self.world.p.getContactPoints(bodyA=self.body) if c[2] != self.body}

    def collides_now(self) -> bool:
        """Contact at the current placement, found without stepping physics."""
        self.world.p.performCollisionDetection()
        return bool(self.touching())

    def bodies_between_fingers(self) -> set[int]:
        """Bodies touched by both fingers: what the gripper holds."""
        p = self.world.p
        left = {c[2] for c in p.getContactPoints(bodyA=self.body, linkIndexA=self.fingers[0])}
        right = {c[2] for c in p.getContactPoints(bodyA=self.body, linkIndexA=self.fingers[1])}
        return (left & right) - {self.body}

    # Motion -------------------------------------------------------------------------------
    def move_to(
        self,
        target: np.ndarray,
        abort_on_contact: bool,
        abort_below_opening: float | None = None,
        on_waypoint: Callable[[int, int], bool] | None = None,
    ) -> bool:
        """Move the hand in a straight line to ``target`` (4×4 world), orientation fixed, in
        2 mm steps at 10 cm/s. Returns True when it stopped early: on contact (with
        ``abort_on_contact``), when the fingers closed below ``abort_below_opening``, or when
        ``on_waypoint(n, count)``, called after each of the ``count`` steps, returned True
        (``interrupted`` is then set: a closed loop changed its mind)."""
        self.interrupted = False
        start = self.pose()[:3, 3]
        _, orientation = pose_from_matrix(target)
        goal = target[:3, 3]
        count = max(1, int(np.ceil(np.linalg.norm(goal - start) / self.spec.step_length)))
        for n in range(1, count + 1):
            self._hold(start + (goal - start) * n / count, orientation)
            self.world.step(self.steps_per_motion)
            if abort_on_contact and self.touching():
                self.last_contact, self.last_contact_position = self.touching(), self.position()
                self._back_off(start, goal, n, count, orientation)
                return True
            if abort_below_opening is not None and self.opening() < abort_below_opening:
                return True
            if on_waypoint is not None and on_waypoint(n, count):
                self.interrupted = True
                return True
        return False

    def _back_off(
        self, start: np.ndarray, goal: np.ndarray, n: int, count: int, orientation: np.ndarray
    ) -> None:
        """A guarded move's stop: the arm backs off along its path, a waypoint at a time and at
        most ``MAX_BACK_OFF_STEPS``, until the hand no longer presses on anything, and holds
        there, as a robot's contact-triggered stop does. Pressing on with the full holding
        force instead pins the fingers by friction, so they never close."""
        for back in range(1, MAX_BACK_OFF_STEPS + 1):
            self._hold(start + (goal - start) * max(0, n - back) / count, orientation)
            self.world.step(self.steps_per_motion)
            if not self.touching():
                return

    def sweep_is_clear(self, target: np.ndarray) -> bool:
        """Teleport the hand along the straight line to ``target`` in 2 mm steps without
        stepping physics, and stop at the first contact. Returns True when the whole path is
        free (the hand then rests at ``target``): the outcome of a dynamic approach that
        treats any contact as failure, at a fraction of its cost."""
        start = self.pose()
        goal = target[:3, 3]
        count = max(1, int(np.ceil(np.linalg.norm(goal - start[:3, 3]) / self.spec.step_length)))
        opening = self.opening()
        for n in range(1, count + 1):
            pose = target.copy()
            pose[:3, 3] = start[:3, 3] + (goal - start[:3, 3]) * n / count
            self.reset(pose, opening)
            if self.collides_now():
                self.last_contact, self.last_contact_position = self.touching(), self.position()
                return False
        return True

    def close(self, stop_when_empty: float | None = None) -> None:
        """Close both fingers with the set force for ``close_duration`` seconds.

        With ``stop_when_empty`` (an opening in metres), stop early once the fingers are
        closer than that: they met nothing, and more closing cannot change the outcome."""
        for finger in self.fingers:
            self.world.p.setJointMotorControl2(
                self.body, finger, pybullet.POSITION_CONTROL, targetPosition=0.0, force=self.spec.finger_force
            )
        total = round(self.spec.close_duration / self.world.config.timestep)
        chunk = 8
        for _ in range(0, total, chunk):
            self.world.step(chunk)
            if stop_when_empty is not None and self.opening() < stop_when_empty:
                return
