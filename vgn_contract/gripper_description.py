"""Parallel-jaw hands described in data files: one JSON file per hand, read and checked here.

Every number the service, the simulator and the data tools use about a hand (opening, finger
depth, the collision boxes of the palm and the fingers, the pads, the closing force, the
pre-grasp distance) comes from a description, so a hand is written down once. The built-in
hands ship in ``vgn_contract/grippers/`` (``franka``: the simulated hand every dataset and the
packaged network were made with); any other file is read by its path. The format is JSON, not
YAML or TOML: pyyaml is no dependency of the light client, and ``tomllib`` needs Python 3.11
while the project supports 3.10. Fields and frames: docs/your-gripper.md, docs/conventions.md.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

#: Where the built-in descriptions live, one ``<name>.json`` each.
BUILTIN_DIR = Path(__file__).resolve().parent / "grippers"
#: The hand a session plans for when it names none.
DEFAULT_GRIPPER = "franka"
NAME_PATTERN = r"^[a-z0-9][a-z0-9._-]{0,63}$"
#: How far a stated coincidence (the pad's tip at the finger depth, its inner face on the
#: closing plane) may be off, in metres: rounding in a hand-written file, not a design choice.
TOLERANCE = 1e-6
#: A closed hand whose pads stay at most this share of its opening apart holds nothing: VGN's
#: success test, shared by the training labels and the benchmark.
HELD_OPENING_FRACTION = 0.1

Triple = tuple[float, float, float]


class GripperDescriptionError(ValueError):
    """A description that cannot be read or breaks a rule; the message names the file and fields."""


class _Part(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class Opening(_Part):
    """The distance between the pads' inner faces (m): fully closed ``min``, fully open ``max``."""

    min: float = Field(ge=0.0)
    max: float = Field(gt=0.0)

    @model_validator(mode="after")
    def _ordered(self) -> Opening:
        if self.min >= self.max:
            raise ValueError(f"the opening's min ({self.min}) must be below its max ({self.max})")
        return self


class Box(_Part):
    """A collision box in the grasp frame: its ``centre`` (m), full ``size`` along x, y, z (m)
    and ``tilt`` (rad) about its own x axis, as a URDF ``<collision>`` box with ``rpy="tilt 0 0"``."""

    centre: Triple
    size: Triple
    tilt: float = Field(default=0.0, ge=-math.pi / 2, le=math.pi / 2)

    @model_validator(mode="after")
    def _positive(self) -> Box:
        if min(self.size) <= 0.0:
            raise ValueError(f"every side of a box must be positive, got size {list(self.size)}")
        return self

    @property
    def half(self) -> Triple:
        """Half the size along each axis (m)."""
        return (self.size[0] / 2, self.size[1] / 2, self.size[2] / 2)


class FingerBox(Box):
    """One box of the left (+y) finger at zero opening: its inner side faces the closing plane
    y = 0; at an opening ``w`` it sits ``w / 2`` further along +y, and the right finger mirrors it."""

    name: str = Field(min_length=1)


class Pad(_Part):
    """Which finger box meets the object, and where on it (grasp frame x and z, m) the grip check
    probes the closing contact."""

    box: str
    contact_x: tuple[float, ...] = Field(min_length=1)
    contact_z: tuple[float, ...] = Field(min_length=1)


class Force(_Part):
    """Closing force: ``closing`` N per finger, what the simulated hand closes with, and the range
    (N) the real hand can be set to, as its maker states it."""

    closing: float = Field(gt=0.0)
    range: tuple[float, float]

    @model_validator(mode="after")
    def _ordered(self) -> Force:
        low, high = self.range
        if not 0.0 < low <= high:
            raise ValueError(f"the force range must be 0 < min <= max, got {list(self.range)}")
        return self


class Mass(_Part):
    """The simulated links' masses (kg): the ``palm`` (the body the arm carries, the hand's housing
    included) and each ``finger``; a hand simulated from its boxes needs them."""

    palm: float = Field(gt=0.0)
    finger: float = Field(gt=0.0)


class GraspFrame(_Part):
    """The grasp-frame convention the numbers are given in; only the service's is accepted, so a
    file written for another convention is refused instead of misread."""

    approach: Literal["+z"]
    closing_axis: Literal["y"]
    origin: Literal["between the finger bases"]


class GripperDescription(_Part):
    """One parallel-jaw hand. ``version`` labels data made with it (``generation.json: gripper``);
    ``urdf`` names its simulator model (repository-relative or absolute; none: the simulator builds
    one from the boxes, which then needs ``mass``)."""

    name: str = Field(pattern=NAME_PATTERN)
    version: str = Field(min_length=1)
    description: str
    sources: tuple[str, ...] = ()
    urdf: str | None = None
    grasp_frame: GraspFrame
    opening: Opening
    finger_depth: float = Field(gt=0.0)
    pregrasp_distance: float = Field(gt=0.0)
    palm: Box
    fingers: tuple[FingerBox, ...] = Field(min_length=1)
    pad: Pad
    force: Force
    mass: Mass | None = None

    @model_validator(mode="after")
    def _consistent(self) -> GripperDescription:
        names = [box.name for box in self.fingers]
        if len(set(names)) != len(names):
            raise ValueError(f"finger box names must differ, got {names}")
        if self.pad.box not in names:
            raise ValueError(f"pad.box {self.pad.box!r} names no finger box (finger boxes: {names})")
        if self.opening.max >= self.palm.size[1]:
            raise ValueError(
                f"the fingers open wider ({self.opening.max} m) than the palm is wide ({self.palm.size[1]} m)"
            )
        pad = self.pad_box
        (px, py, pz), (hx, hy, hz) = pad.centre, pad.half
        if abs(pz + hz - self.finger_depth) > TOLERANCE:
            raise ValueError(
                f"the pad's tip (z = {pz + hz:.6g}) must be at the finger depth ({self.finger_depth})"
            )
        if pad.tilt:
            raise ValueError(f"the pad {pad.name!r} must not be tilted: its inner face closes flat")
        if abs(py - hy) > TOLERANCE:
            raise ValueError(f"the pad's inner face (y = {py - hy:.6g}) must lie on the closing plane y = 0")
        if any(abs(x - px) > hx for x in self.pad.contact_x) or any(
            abs(z - pz) > hz for z in self.pad.contact_z
        ):
            raise ValueError("pad.contact_x and pad.contact_z must lie on the pad box")
        return self

    @property
    def max_opening(self) -> float:
        """The fully open width (m): the opening the hand approaches with."""
        return self.opening.max

    @property
    def held_opening(self) -> float:
        """The opening (m) at or below which the closed hand counts as holding nothing."""
        return HELD_OPENING_FRACTION * self.opening.max

    @property
    def pad_box(self) -> FingerBox:
        """The finger box that meets the object."""
        return next(box for box in self.fingers if box.name == self.pad.box)

    @property
    def pad_middle(self) -> float:
        """The middle of the pad along the approach (m, grasp frame z)."""
        return self.pad_box.centre[2]

    @property
    def digest(self) -> str:
        """SHA-256 (hex) of what makes the hand: every field but the prose (``description``,
        ``sources``), so data and results name the exact hand they were made with."""
        fields = self.model_dump(mode="json", exclude={"description", "sources"})
        canonical = json.dumps(fields, sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(canonical.encode()).hexdigest()


def builtin_grippers() -> tuple[str, ...]:
    """The names of the hands shipped in ``vgn_contract/grippers/``, sorted."""
    return tuple(sorted(path.stem for path in BUILTIN_DIR.glob("*.json")))


def parse_gripper(data: object, source: str = "<data>") -> GripperDescription:
    """A description from parsed JSON; ``GripperDescriptionError`` naming ``source`` and every
    bad field (missing, unknown, out of range) when it breaks a rule."""
    if not isinstance(data, dict):
        raise GripperDescriptionError(
            f"{source}: a gripper description is a JSON object, got {type(data).__name__}"
        )
    try:
        return GripperDescription.model_validate(data)
    except ValidationError as error:
        problems = "; ".join(
            (".".join(str(part) for part in e["loc"]) or "description")
            + ": "
            + e["msg"].removeprefix("Value error, ")
            for e in error.errors()
        )
        raise GripperDescriptionError(f"{source}: {problems}") from None


def read_gripper(path: str | Path) -> GripperDescription:
    """The description in the JSON file at ``path`` (``GripperDescriptionError`` if it is bad)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as error:
        raise GripperDescriptionError(
            f"{path}: cannot read the gripper description ({error.strerror})"
        ) from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as error:
        raise GripperDescriptionError(f"{path}: not JSON ({error})") from None
    return parse_gripper(data, str(path))


@functools.cache
def builtin_gripper(name: str) -> GripperDescription:
    """A built-in hand by name; ``GripperDescriptionError`` naming the built-in hands otherwise."""
    if name not in builtin_grippers():
        raise GripperDescriptionError(
            f"no built-in gripper {name!r}; built in: {', '.join(builtin_grippers())}"
        )
    description = read_gripper(BUILTIN_DIR / f"{name}.json")
    if description.name != name:
        raise GripperDescriptionError(f"{BUILTIN_DIR / name}.json describes {description.name!r}")
    return description


def load_gripper(name_or_path: str | Path) -> GripperDescription:
    """A built-in hand by name, or the description at a path (anything ending in ``.json``)."""
    text = str(name_or_path)
    if isinstance(name_or_path, Path) or text.endswith(".json"):
        return read_gripper(name_or_path)
    return builtin_gripper(text)


def check_version(hand: GripperDescription) -> None:
    """``GripperDescriptionError`` when ``hand`` borrows the ``version`` of a built-in hand it is not:
    data made with it would carry that hand's label and be mixed with that hand's data."""
    for name in builtin_grippers():
        builtin = builtin_gripper(name)
        if builtin.version == hand.version and builtin.digest != hand.digest:
            raise GripperDescriptionError(
                f"the gripper {hand.name!r} is labelled {hand.version!r}, the version of the built-in hand "
                f"{name!r}, but it is another hand: give it a version of its own"
            )


def default_gripper() -> GripperDescription:
    """The hand planned for when none is named: :data:`DEFAULT_GRIPPER`."""
    return builtin_gripper(DEFAULT_GRIPPER)
