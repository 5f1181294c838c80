"""The simulated hand from a gripper description: the franka hand is the shipped URDF unchanged, and
a hand without one (robotiq-2f85, a user's file) is built from its boxes and grasps like any other."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import numpy as np
import pybullet
import pytest
from scipy.spatial.transform import Rotation

from client.cli import gripper_argument
from sim_worker.grasping import Outcome, execute_grasp
from sim_worker.gripper import Gripper, GripperSpec
from sim_worker.hand_urdf import REPOSITORY, hand_urdf, mirrored, urdf_text
from sim_worker.world import TABLE_Z, SimObject, World
from vgn_contract.geometry import matrix_from_pose
from vgn_contract.gripper_description import (
    BUILTIN_DIR,
    GripperDescription,
    GripperDescriptionError,
    builtin_gripper,
    default_gripper,
    parse_gripper,
)

DOWN = Rotation.from_euler("x", np.pi)  # approach straight down, fingers closing along world ±y
ACROSS = Rotation.from_euler("z", 90, degrees=True) * DOWN  # fingers closing along world ±x
ROBOTIQ = builtin_gripper("robotiq-2f85")
SHIPPED_URDF = REPOSITORY / "sim_worker" / "assets" / "gripper.urdf"


@pytest.fixture(autouse=True)
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Built URDFs go to a folder of the test's own."""
    folder = tmp_path / "cache"
    monkeypatch.setenv("VGN_CACHE_DIR", str(folder))
    return folder


@pytest.fixture
def world():
    with World(renderer="tiny") as w:
        yield w


def add_box(world: World, half_extents: tuple[float, float, float], xy=(0.15, 0.15)) -> int:
    shape = world.p.createCollisionShape(pybullet.GEOM_BOX, halfExtents=list(half_extents))
    body = world.p.createMultiBody(0.1, shape, -1, [xy[0], xy[1], TABLE_Z + half_extents[2] + 0.001])
    world.p.changeDynamics(body, -1, lateralFriction=world.config.object_friction)
    world.objects[body] = SimObject(body, None, 1.0)
    world.wait_for_rest()
    return body


def over_the_box(hand: GripperDescription, rotation: Rotation, into: float = 0.03) -> np.ndarray:
    """A grasp over a 5 cm box at (0.15, 0.15) whose fingertips reach ``into`` metres down its sides."""
    top = TABLE_Z + 0.05
    return matrix_from_pose(np.array([0.15, 0.15, top - into + hand.finger_depth]), rotation.as_quat())


# The franka hand is the shipped one -------------------------------------------------------------
def parsed(text: str) -> dict:
    """What a URDF says of the dynamics and geometry: each link's mass and collision boxes
    (xyz, rpy, size), each joint's type, parent, child, origin, axis and limits."""
    robot = ElementTree.fromstring(text)

    def numbers(element: ElementTree.Element | None, attribute: str, default: str = "0 0 0") -> tuple:
        return tuple(
            float(v) for v in (element.get(attribute, default) if element is not None else default).split()
        )

    links = {
        link.get("name"): {
            "mass": float(link.find("inertial/mass").get("value")),
            "inertial_origin": numbers(link.find("inertial/origin"), "xyz"),
            "boxes": sorted(
                (
                    numbers(c.find("origin"), "xyz"),
                    numbers(c.find("origin"), "rpy"),
                    numbers(c.find("geometry/box"), "size"),
                )
                for c in link.findall("collision")
            ),
        }
        for link in robot.findall("link")
    }
    joints = {
        joint.get("name"): {
            "type": joint.get("type"),
            "parent": joint.find("parent").get("link"),
            "child": joint.find("child").get("link"),
            "origin": numbers(joint.find("origin"), "xyz"),
            "axis": numbers(joint.find("axis"), "xyz"),
            "limit": tuple(
                float(joint.find("limit").get(k)) for k in ("lower", "upper", "effort", "velocity")
            ),
        }
        for joint in robot.findall("joint")
    }
    return {"links": links, "joints": joints}


def test_the_franka_hand_loads_the_shipped_urdf_and_its_spec_is_todays():
    franka = default_gripper()
    assert hand_urdf(franka) == SHIPPED_URDF
    spec = GripperSpec()
    assert spec.hand is franka
    assert (spec.max_opening, spec.finger_depth, spec.pregrasp_distance, spec.finger_force) == (
        0.08,
        0.05,
        0.05,
        20.0,
    )
    assert franka.version == "franka-v2", "existing data and recipes name this hand"


def test_the_franka_description_is_what_the_shipped_urdf_holds():
    """Every box, both masses, the opening and the closing force, as the file states them."""
    franka = default_gripper()
    shipped = parsed(SHIPPED_URDF.read_text())
    palm = shipped["links"]["palm"]
    assert palm["mass"] == franka.mass.palm
    assert palm["boxes"] == [(franka.palm.centre, (franka.palm.tilt, 0.0, 0.0), franka.palm.size)]
    for link, boxes in (
        ("left_finger", franka.fingers),
        ("right_finger", [mirrored(b) for b in franka.fingers]),
    ):
        assert shipped["links"][link]["mass"] == franka.mass.finger
        expected = sorted((b.centre, (b.tilt, 0.0, 0.0), b.size) for b in boxes)
        assert shipped["links"][link]["boxes"] == expected
    for joint in shipped["joints"].values():
        lower, upper, effort, _ = joint["limit"]
        assert (lower, upper) == (franka.opening.min / 2, franka.opening.max / 2)
        assert effort == franka.force.closing


def test_the_urdf_built_from_the_franka_description_equals_the_shipped_one():
    """Link geometry, masses, centres of mass and joints (limits included) agree to the last digit;
    only the inertia tensors, which the shipped file rounds, are the builder's own."""
    assert parsed(urdf_text(default_gripper())) == parsed(SHIPPED_URDF.read_text())


def dynamics(gripper: Gripper) -> list[tuple]:
    """What PyBullet simulates of a hand: per link its mass, friction, contact and collision shapes,
    per finger joint its type, limits and axis."""
    p, body = gripper.world.p, gripper.body
    links = [-1, *range(p.getNumJoints(body))]
    rows = []
    for link in links:
        info = p.getDynamicsInfo(body, link)
        shapes = [
            np.round(np.hstack([s[3], s[5], s[6]]), 9).tolist() for s in p.getCollisionShapeData(body, link)
        ]
        rows.append((link, info[0], info[1], info[6], info[7], info[9], info[10], sorted(shapes)))
    for joint in range(p.getNumJoints(body)):
        info = p.getJointInfo(body, joint)
        rows.append((info[1], info[2], info[8], info[9], info[10], info[13], info[16]))
    return rows


def test_a_built_franka_hand_simulates_as_the_shipped_one(world):
    built = default_gripper().model_copy(update={"urdf": None})
    shipped, rebuilt = Gripper(world), Gripper(world, GripperSpec(hand=built))
    assert dynamics(shipped) == dynamics(rebuilt)
    body = add_box(world, (0.025, 0.025, 0.025))
    state = world.save_state()
    widths = []
    for gripper in (shipped, rebuilt):
        world.restore_state(state)
        gripper.use_spec(gripper.spec)  # restore_state keeps no contact parameters
        trial = execute_grasp(world, gripper, over_the_box(gripper.spec.hand, DOWN), remove_grasped=False)
        assert trial.outcome is Outcome.SUCCESS and trial.grasped_body == body
        widths.append(trial.width)
    assert widths[0] == pytest.approx(widths[1], abs=1e-4)


# robotiq-2f85: built from its boxes ---------------------------------------------------------------
def test_the_robotiq_hand_is_built_in_the_cache_keyed_by_its_description(cache: Path):
    path = hand_urdf(ROBOTIQ)
    assert path.parent == cache / "grippers" and path.name == f"robotiq-2f85-{ROBOTIQ.digest[:16]}.urdf"
    assert path.read_text() == urdf_text(ROBOTIQ)
    written = path.stat().st_mtime_ns
    assert hand_urdf(ROBOTIQ) == path and path.stat().st_mtime_ns == written, "an up-to-date file is kept"
    wider = ROBOTIQ.model_copy(update={"opening": ROBOTIQ.opening.model_copy(update={"max": 0.09})})
    assert hand_urdf(wider) != path, "another hand, another file"
    assert not list(path.parent.glob("*.tmp")), "written atomically, nothing left behind"
    joints = parsed(path.read_text())["joints"]
    assert {j["limit"][:3] for j in joints.values()} == {(0.0, 0.0425, ROBOTIQ.force.closing)}


def test_the_robotiq_hand_opens_to_its_stroke(world):
    gripper = Gripper(world, GripperSpec(hand=ROBOTIQ))
    limits = {world.p.getJointInfo(gripper.body, f)[8:10] for f in gripper.fingers}
    assert limits == {(0.0, ROBOTIQ.max_opening / 2)}
    gripper.reset(matrix_from_pose(np.array([0.15, 0.15, 0.3]), DOWN.as_quat()))
    world.step(50)
    assert gripper.opening() == pytest.approx(0.085, abs=1e-4), "open: the 85 mm stroke"
    np.testing.assert_allclose(gripper.position(), [0.15, 0.15, 0.3], atol=2e-3)


def test_the_robotiq_hand_closes_on_a_5cm_block_and_lifts_it(world):
    body = add_box(world, (0.025, 0.025, 0.025))
    trial = execute_grasp(world, Gripper(world, GripperSpec(hand=ROBOTIQ)), over_the_box(ROBOTIQ, DOWN))
    assert trial.outcome is Outcome.SUCCESS and trial.grasped_body == body
    assert trial.width == pytest.approx(0.05, abs=0.003), "closed on the 5 cm block"


def test_the_robotiq_hand_cannot_close_around_a_10cm_block(world):
    body = add_box(world, (0.025, 0.05, 0.025))  # 10 cm along the closing axis: wider than 85 mm
    gripper = Gripper(world, GripperSpec(hand=ROBOTIQ))
    trial = execute_grasp(world, gripper, over_the_box(ROBOTIQ, DOWN))
    assert trial.outcome is Outcome.APPROACH_CONTACT and trial.label == 0, "a pad lands on the block"
    assert body in world.objects and body in trial.contact_bodies
    across = execute_grasp(world, gripper, over_the_box(ROBOTIQ, ACROSS))
    assert across.outcome is Outcome.SUCCESS, "the same block across its 5 cm side fits"


# A user's own description ----------------------------------------------------------------------------
def test_a_users_description_file_executes_a_grasp(world, tmp_path: Path, cache: Path):
    data = json.loads((BUILTIN_DIR / "robotiq-2f85.json").read_text())
    data |= {"name": "my-hand", "version": "my-hand-v1", "description": "a narrower 2F-85"}
    data["opening"]["max"] = 0.07
    data["force"]["closing"] = 30.0
    path = tmp_path / "my-hand.json"
    path.write_text(json.dumps(data))
    hand = gripper_argument(str(path))  # as --gripper reads it
    gripper = Gripper(world, GripperSpec(hand=hand))
    assert gripper.spec.finger_force == 30.0 and gripper.opening() == pytest.approx(0.07, abs=1e-6)
    assert list((cache / "grippers").glob("my-hand-*.urdf"))
    body = add_box(world, (0.025, 0.025, 0.025))
    trial = execute_grasp(world, gripper, over_the_box(hand, DOWN))
    assert trial.outcome is Outcome.SUCCESS and trial.grasped_body == body


def test_a_hand_to_build_needs_its_masses():
    data = json.loads((BUILTIN_DIR / "robotiq-2f85.json").read_text())
    del data["mass"]
    with pytest.raises(GripperDescriptionError, match='"mass"'):
        hand_urdf(parse_gripper(data))


def test_a_gripper_keeps_its_hand():
    with World(renderer="tiny") as world:
        gripper = Gripper(world)
        with pytest.raises(ValueError, match="make a new one"):
            gripper.use_spec(GripperSpec(hand=ROBOTIQ))
