"""Gripper descriptions: the built-in hands, the rules a file must keep, and the messages of a bad one."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest

from vgn_contract.gripper_description import (
    GripperDescriptionError,
    builtin_gripper,
    builtin_grippers,
    default_gripper,
    load_gripper,
    parse_gripper,
    read_gripper,
)

FRANKA_FILE = Path(__file__).resolve().parents[2] / "vgn_contract" / "grippers" / "franka.json"


def franka_data() -> dict:
    return json.loads(FRANKA_FILE.read_text())


def test_the_built_in_hands():
    assert builtin_grippers() == ("franka", "robotiq-2f85")
    assert default_gripper() is builtin_gripper("franka")
    robotiq = builtin_gripper("robotiq-2f85")
    assert robotiq.max_opening == 0.085 and robotiq.force.range == (20.0, 235.0)
    assert robotiq.sources, "a built-in hand says where its numbers come from"


def test_franka_is_the_hand_every_result_was_made_with():
    """The numbers the service and the simulator used before descriptions existed."""
    hand = default_gripper()
    assert (hand.version, hand.max_opening, hand.finger_depth, hand.pregrasp_distance) == (
        "franka-v2",
        0.08,
        0.05,
        0.05,
    )
    assert hand.force.closing == 20.0
    assert hand.palm.centre == (0.0, 0.0, -0.0345) and hand.palm.half == (0.03, 0.10, 0.03)
    assert [(b.centre, b.half, b.tilt) for b in hand.fingers] == [
        ((0.0, 0.0185, 0.0065), (0.011, 0.0075, 0.01), 0.0),
        ((0.0, 0.0159, 0.0239), (0.00875, 0.0035, 0.01175), 0.5236),
        ((0.0, 0.0076, 0.04075), (0.01, 0.0076, 0.00925), 0.0),
    ]
    assert hand.pad.contact_x == (-0.006, 0.0, 0.006) and hand.pad.contact_z == (0.035, 0.041, 0.047)


def test_a_file_by_path_and_a_name(tmp_path):
    data = franka_data() | {"name": "my-hand"}
    path = tmp_path / "my-hand.json"
    path.write_text(json.dumps(data))
    assert load_gripper(path).name == "my-hand"
    assert load_gripper(str(path)).name == "my-hand"
    assert load_gripper("franka").name == "franka"
    with pytest.raises(GripperDescriptionError, match="built in: franka, robotiq-2f85"):
        load_gripper("schunk")


def bad(change) -> str:
    """The message of the franka description after ``change(data)``."""
    data = copy.deepcopy(franka_data())
    change(data)
    with pytest.raises(GripperDescriptionError) as caught:
        parse_gripper(data, "hand.json")
    message = str(caught.value)
    assert message.startswith("hand.json: ")
    return message


def test_negative_or_zero_sizes_are_refused():
    assert "finger_depth: Input should be greater than 0" in bad(lambda d: d.update(finger_depth=-0.05))
    message = bad(lambda d: d["fingers"][0].update(size=[0.022, -0.015, 0.02]))
    assert "fingers.0: every side of a box must be positive" in message
    assert "opening.min: Input should be greater than or equal to 0" in bad(
        lambda d: d["opening"].update(min=-0.01)
    )


def test_an_opening_wider_than_the_palm_is_refused():
    message = bad(lambda d: d["opening"].update(max=0.25))
    assert "the fingers open wider (0.25 m) than the palm is wide (0.2 m)" in message


def test_missing_and_unknown_keys_are_named():
    assert "pregrasp_distance: Field required" in bad(lambda d: d.pop("pregrasp_distance"))
    assert "finger_length: Extra inputs are not permitted" in bad(lambda d: d.update(finger_length=0.05))
    assert "palm.colour: Extra inputs are not permitted" in bad(lambda d: d["palm"].update(colour="white"))


def test_inconsistent_geometry_is_refused():
    assert "must be below its max" in bad(lambda d: d["opening"].update(min=0.09))
    assert "pad.box 'tip' names no finger box" in bad(lambda d: d["pad"].update(box="tip"))
    assert "must be at the finger depth (0.06)" in bad(lambda d: d.update(finger_depth=0.06))
    assert "must lie on the closing plane" in bad(
        lambda d: d["fingers"][2].update(centre=[0.0, 0.01, 0.04075])
    )
    assert "must lie on the pad box" in bad(lambda d: d["pad"].update(contact_z=[0.02]))
    assert "grasp_frame.approach: Input should be '+z'" in bad(
        lambda d: d["grasp_frame"].update(approach="-z")
    )
    assert "force: the force range" in bad(lambda d: d["force"].update(range=[140.0, 70.0]))


def test_unreadable_files_say_so(tmp_path):
    with pytest.raises(GripperDescriptionError, match="cannot read"):
        read_gripper(tmp_path / "missing.json")
    (tmp_path / "broken.json").write_text("{not json")
    with pytest.raises(GripperDescriptionError, match="broken.json: not JSON"):
        read_gripper(tmp_path / "broken.json")
    (tmp_path / "list.json").write_text("[]")
    with pytest.raises(GripperDescriptionError, match="is a JSON object, got list"):
        read_gripper(tmp_path / "list.json")
