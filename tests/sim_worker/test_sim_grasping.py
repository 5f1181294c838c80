"""Grasp execution on single objects with analytically known grasps (docs/conventions.md)."""

from __future__ import annotations

import numpy as np
import pybullet
import pytest
from scipy.spatial.transform import Rotation

from sim_worker.grasping import Outcome, execute_grasp, retreat_pose
from sim_worker.gripper import Gripper
from sim_worker.world import TABLE_Z, SimObject, World
from vgn_contract.geometry import matrix_from_pose

DOWN = Rotation.from_euler("x", np.pi)  # approach straight down, fingers closing along world ±y
SIDE = Rotation.from_euler("y", np.pi / 2)  # approach along world +x


@pytest.fixture
def world():
    with World(renderer="tiny") as w:
        yield w


def add_box(world: World, half_extents=(0.025, 0.025, 0.025), xy=(0.15, 0.15), mass=0.1) -> int:
    shape = world.p.createCollisionShape(pybullet.GEOM_BOX, halfExtents=list(half_extents))
    body = world.p.createMultiBody(mass, shape, -1, [xy[0], xy[1], TABLE_Z + half_extents[2] + 0.001])
    world.p.changeDynamics(body, -1, lateralFriction=world.config.object_friction)
    world.objects[body] = SimObject(body, None, 1.0)
    world.wait_for_rest()
    return body


def grasp(position, rotation: Rotation) -> np.ndarray:
    return matrix_from_pose(np.asarray(position), rotation.as_quat())


@pytest.mark.parametrize("yaw_deg", [0, 90])
def test_top_down_grasp_on_a_box_succeeds(world, yaw_deg):
    body = add_box(world)
    gripper = Gripper(world)
    rotation = Rotation.from_euler("z", yaw_deg, degrees=True) * DOWN
    trial = execute_grasp(world, gripper, grasp([0.15, 0.15, 0.12], rotation))
    assert trial.outcome is Outcome.SUCCESS and trial.label == 1
    assert trial.grasped_body == body and body not in world.objects
    assert trial.closed_on == (body,)
    assert trial.width == pytest.approx(0.05, abs=0.003), "closed on the 5 cm box"


def test_grasp_across_the_long_side_fails_when_wider_than_the_gripper(world):
    add_box(world, half_extents=(0.025, 0.06, 0.025))  # 12 cm along y: wider than the 8 cm opening
    # Fingertips reach 2 cm into the box's 5 cm height: a finger lands on the box top.
    trial = execute_grasp(world, Gripper(world), grasp([0.15, 0.15, 0.13], DOWN), allow_contact=False)
    assert trial.outcome is Outcome.APPROACH_COLLISION
    across = execute_grasp(
        world, Gripper(world), grasp([0.15, 0.15, 0.13], Rotation.from_euler("z", 90, degrees=True) * DOWN)
    )
    assert across.outcome is Outcome.SUCCESS, "the same box across its 5 cm side fits"


def test_side_grasp_on_a_tall_box_succeeds(world):
    add_box(world, half_extents=(0.02, 0.02, 0.05))
    trial = execute_grasp(world, Gripper(world), grasp([0.10, 0.15, 0.12], SIDE))
    assert trial.outcome is Outcome.SUCCESS


def test_pregrasp_colliding_with_the_table_fails_without_stepping(world):
    add_box(world)
    below_table = grasp([0.15, 0.15, TABLE_Z - 0.01], SIDE)
    trial = execute_grasp(world, Gripper(world), below_table)
    assert trial.outcome is Outcome.PREGRASP_COLLISION and trial.label == 0
    assert trial.sim_steps == 0
    assert len(world.objects) == 1


def test_empty_grasp_fails(world):
    add_box(world)
    trial = execute_grasp(world, Gripper(world), grasp([0.05, 0.05, 0.12], DOWN))
    assert trial.outcome is Outcome.NOTHING_HELD and trial.label == 0
    assert trial.width < 0.01
    assert trial.closed_on == ()


def test_a_plate_thinner_than_the_held_opening_holds_nothing_but_is_closed_on(world):
    """Fingers that close on a 5 mm plate stay within the held opening: nothing held, though the
    hand touched the plate, which the trial names so that such failures can be traced to it."""
    plate = add_box(world, half_extents=(0.0025, 0.03, 0.03))  # 5 mm thick along x, upright
    across = Rotation.from_euler("z", 90, degrees=True) * DOWN  # fingers close along world x
    trial = execute_grasp(world, Gripper(world), grasp([0.15, 0.15, 0.14], across))
    assert trial.outcome is Outcome.NOTHING_HELD
    assert trial.closed_on == (plate,)


def test_contact_during_approach_fails_when_not_allowed(world):
    add_box(world)
    # Fingertips would end 4 cm inside the table: the approach touches the table (and the box) first.
    deep = grasp([0.15, 0.15, 0.06], DOWN)
    strict = execute_grasp(world, Gripper(world), deep, allow_contact=False)
    assert strict.outcome is Outcome.APPROACH_COLLISION


def test_gripper_is_parked_after_a_trial(world):
    add_box(world)
    gripper = Gripper(world)
    execute_grasp(world, gripper, grasp([0.15, 0.15, 0.12], DOWN), remove_grasped=False)
    assert gripper.pose()[2, 3] > 5.0


def test_retreat_direction():
    top_down = grasp([0.1, 0.1, 0.1], DOWN)
    np.testing.assert_allclose(retreat_pose(top_down)[:3, 3], [0.1, 0.1, 0.2], atol=1e-9)
    side = grasp([0.1, 0.1, 0.1], SIDE)
    np.testing.assert_allclose(retreat_pose(side)[:3, 3], [0.1, 0.1, 0.2], atol=1e-9)
    tilted = grasp([0.1, 0.1, 0.1], Rotation.from_euler("y", 30, degrees=True) * DOWN)
    back = retreat_pose(tilted)[:3, 3] - [0.1, 0.1, 0.1]
    np.testing.assert_allclose(back, -0.1 * tilted[:3, 2], atol=1e-9)


@pytest.mark.parametrize(
    "position, rotation",
    [
        ([0.15, 0.15, 0.12], DOWN),  # good
        ([0.15, 0.15, 0.12], Rotation.from_euler("z", 45, degrees=True) * DOWN),  # diagonal: still fits
        ([0.05, 0.05, 0.12], DOWN),  # empty
        ([0.15, 0.15, 0.06], DOWN),  # approach hits the table
        ([0.15, 0.15, TABLE_Z - 0.01], SIDE),  # pre-grasp in the table
        ([0.15, 0.20, 0.08], DOWN),  # one finger on the box edge
    ],
)
def test_fast_labelling_gives_the_same_label(world, position, rotation):
    """Fast execution (kinematic approach, early stop) must not change what a label means."""
    add_box(world)
    gripper = Gripper(world)
    state = world.save_state()
    pose = grasp(position, rotation)
    slow = execute_grasp(world, gripper, pose, allow_contact=False, remove_grasped=False)
    world.restore_state(state)
    fast = execute_grasp(world, gripper, pose, allow_contact=False, remove_grasped=False, fast=True)
    assert fast.label == slow.label
    assert fast.sim_steps <= slow.sim_steps
    if slow.label:
        assert fast.width == pytest.approx(slow.width, abs=1e-3)


def test_an_approach_stopped_by_the_table_backs_off_closes_and_records_the_contact(world):
    add_box(world)
    # Fingertips would end 4 cm inside the table: the approach stops on it, 4 cm early.
    trial = execute_grasp(world, Gripper(world), grasp([0.15, 0.15, 0.06], DOWN), allow_contact=True)
    assert trial.contact_bodies == (world.table,)
    assert trial.contact_distance == pytest.approx(0.04, abs=0.003)
    assert trial.outcome is Outcome.SUCCESS, "a guarded stop does not pin the fingers to the table"


def test_closing_on_nothing_after_a_contact_stop_is_approach_contact(world):
    body = add_box(world, half_extents=(0.06, 0.06, 0.02))  # 12 cm square slab, top at z = 0.09
    # The pads land on the slab's top 3 cm before the grasp pose and close on nothing.
    trial = execute_grasp(world, Gripper(world), grasp([0.15, 0.15, 0.11], DOWN), allow_contact=True)
    assert trial.outcome is Outcome.APPROACH_CONTACT and trial.label == 0
    assert trial.contact_bodies == (body,)
    assert trial.contact_distance == pytest.approx(0.03, abs=0.003)


def test_an_object_too_heavy_to_lift_slips(world):
    add_box(world, mass=20.0)  # 196 N of weight against 2 x 20 N of grip with friction 1
    trial = execute_grasp(world, Gripper(world), grasp([0.15, 0.15, 0.12], DOWN))
    assert trial.outcome is Outcome.SLIPPED and trial.label == 0
    assert trial.contact_bodies == () and trial.contact_distance is None
    assert len(trial.closed_on) == 1, "the slipped box was between the fingers"
