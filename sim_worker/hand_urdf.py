"""The simulated hand's URDF: the file its gripper description names, or one built from its boxes.

A description without a URDF (``urdf: null``) is simulated as it is written: a palm link holding
the palm box, two fingers of the finger boxes on prismatic joints along the closing axis (the
right one mirrors the left), joint limits from the opening and the joint effort from the closing
force. Each link's centre of mass sits at its origin, so the base frame is the grasp frame
(docs/conventions.md). The file goes to the cache folder under a name keyed by the description's
digest, written atomically, so every worker of a run loads the same one.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path

from sim_worker.objects import default_cache_dir, write_atomic
from vgn_contract.gripper_description import Box, GripperDescription, GripperDescriptionError

#: The folder that holds the packages: a description's relative ``urdf`` path starts there.
REPOSITORY = Path(__file__).resolve().parents[1]
#: URDF requires a joint speed limit, which PyBullet's position control does not apply (the motor's
#: force and gains set how fast a finger moves); every built hand states the shipped hand's.
JOINT_VELOCITY_LIMIT = 0.2
PALM_COLOUR = "0.85 0.85 0.88 1"
FINGER_COLOUR = "0.2 0.2 0.2 1"


def hand_urdf(hand: GripperDescription, cache_dir: Path | None = None) -> Path:
    """The URDF that simulates ``hand``: the file it names, else one built from its boxes in
    ``cache_dir`` (default: the ``grippers`` folder of :func:`default_cache_dir`), written when
    missing or stale. ``GripperDescriptionError`` when a hand to build states no ``mass``."""
    if hand.urdf is not None:
        named = Path(hand.urdf)
        return named if named.is_absolute() else REPOSITORY / named
    text = urdf_text(hand)
    directory = Path(cache_dir) if cache_dir is not None else default_cache_dir() / "grippers"
    path = directory / f"{hand.name}-{hand.digest[:16]}.urdf"
    write_atomic(path, text)  # keeps a file that already holds this text
    return path


def urdf_text(hand: GripperDescription) -> str:
    """The URDF of ``hand`` built from its boxes (see the module docstring)."""
    if hand.mass is None:
        raise GripperDescriptionError(
            f"the gripper {hand.name!r} names no URDF, so the simulator builds one from its boxes, which "
            'needs the links\' masses: add "mass": {"palm": KG, "finger": KG} to its description'
        )
    left = hand.fingers
    right = [mirrored(box) for box in left]
    low, high = hand.opening.min / 2, hand.opening.max / 2
    return "\n".join(
        [
            '<?xml version="1.0"?>',
            f"<!-- Built by vgn-service from the gripper description {hand.name!r} ({hand.version}, "
            f"digest {hand.digest[:16]}): base frame = grasp frame; joint position = half the opening. -->",
            f'<robot name="vgn_gripper_{hand.name}">',
            *_link("palm", hand.mass.palm, [hand.palm], PALM_COLOUR),
            *_link("left_finger", hand.mass.finger, left, FINGER_COLOUR),
            *_link("right_finger", hand.mass.finger, right, FINGER_COLOUR),
            *_joint("left_finger_joint", "left_finger", "0 1 0", low, high, hand.force.closing),
            *_joint("right_finger_joint", "right_finger", "0 -1 0", low, high, hand.force.closing),
            "</robot>",
            "",
        ]
    )


def mirrored(box: Box) -> Box:
    """``box`` of the left finger as the right finger carries it: reflected in the plane y = 0."""
    x, y, z = box.centre
    return box.model_copy(update={"centre": (x, -y, z), "tilt": -box.tilt})


def box_inertia(mass: float, boxes: Iterable[Box]) -> tuple[float, float, float]:
    """(ixx, iyy, izz) of a solid box of ``mass`` as large as the extent of ``boxes``: the link's
    size, all a carried hand's motion and its prismatic fingers need of it."""
    corners = [corner for box in boxes for corner in _corners(box)]
    size = [max(c[axis] for c in corners) - min(c[axis] for c in corners) for axis in range(3)]
    sx, sy, sz = (side**2 for side in size)
    return mass * (sy + sz) / 12, mass * (sx + sz) / 12, mass * (sx + sy) / 12


def _corners(box: Box) -> list[tuple[float, float, float]]:
    """The eight corners of ``box`` in its link's frame (tilted about x)."""
    cos, sin = math.cos(box.tilt), math.sin(box.tilt)
    (cx, cy, cz), (hx, hy, hz) = box.centre, box.half
    corners = []
    for dx in (-hx, hx):
        for dy in (-hy, hy):
            for dz in (-hz, hz):
                corners.append((cx + dx, cy + cos * dy - sin * dz, cz + sin * dy + cos * dz))
    return corners


def _number(value: float) -> str:
    return f"{value:.10g}"


def _triple(values: Iterable[float]) -> str:
    return " ".join(_number(v) for v in values)


def _link(name: str, mass: float, boxes: list[Box], colour: str) -> list[str]:
    ixx, iyy, izz = box_inertia(mass, boxes)
    lines = [
        f'  <link name="{name}">',
        "    <inertial>",
        '      <origin xyz="0 0 0"/>',
        f'      <mass value="{_number(mass)}"/>',
        f'      <inertia ixx="{_number(ixx)}" ixy="0" ixz="0" iyy="{_number(iyy)}" iyz="0" izz="{_number(izz)}"/>',
        "    </inertial>",
    ]
    for kind in ("visual", "collision"):
        for box in boxes:
            rpy = f' rpy="{_number(box.tilt)} 0 0"' if box.tilt else ""
            body = [
                f'      <origin xyz="{_triple(box.centre)}"{rpy}/>',
                f'      <geometry><box size="{_triple(box.size)}"/></geometry>',
            ]
            if kind == "visual":
                body.append(f'      <material name="{name}"><color rgba="{colour}"/></material>')
            lines += [f"    <{kind}>", *body, f"    </{kind}>"]
    return [*lines, "  </link>"]


def _joint(name: str, child: str, axis: str, lower: float, upper: float, effort: float) -> list[str]:
    return [
        f'  <joint name="{name}" type="prismatic">',
        '    <parent link="palm"/>',
        f'    <child link="{child}"/>',
        '    <origin xyz="0 0 0"/>',
        f'    <axis xyz="{axis}"/>',
        f'    <limit lower="{_number(lower)}" upper="{_number(upper)}" effort="{_number(effort)}" '
        f'velocity="{_number(JOINT_VELOCITY_LIMIT)}"/>',
        "  </joint>",
    ]
