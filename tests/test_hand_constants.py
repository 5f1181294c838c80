"""The hand is written down once: in its gripper description (vgn_contract/grippers/*.json).

A hand constant typed into a module (``MAX_OPENING = 0.08``) silently disagrees with the
description the day someone plans for another hand, so this test reads the shipped packages'
source with ``ast`` and fails on any outside the description reader.
"""

from __future__ import annotations

import ast
import re
import textwrap
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ("vgn_contract", "client", "service", "sim_worker", "training", "vgn_data")
#: The module that reads descriptions: the one place their fields are named and checked.
READER = "vgn_contract/gripper_description.py"
#: Names that are a hand's constant whatever their value.
HAND_NAMES = frozenset({"MAX_OPENING", "FINGER_DEPTH", "PREGRASP_DISTANCE"})
#: A name about a hand's geometry; with one of the franka hand's own numbers it is a copy of the description.
ABOUT_A_HAND = re.compile(r"opening|finger|pregrasp|palm|pad|jaw|gripper|hand", re.IGNORECASE)
HAND_NUMBERS = frozenset({0.08, 0.05})


def _targets(node: ast.AST) -> Iterator[tuple[str, ast.AST | None]]:
    """(name, value) of what ``node`` binds: assignments, annotated fields and argument defaults."""
    if isinstance(node, ast.Assign):
        for target in node.targets:
            for name in ast.walk(target):
                if isinstance(name, ast.Name | ast.Attribute):
                    yield (name.id if isinstance(name, ast.Name) else name.attr), node.value
    elif isinstance(node, ast.AnnAssign):
        target = node.target
        yield (target.id if isinstance(target, ast.Name) else getattr(target, "attr", "")), node.value
    elif isinstance(node, ast.arguments):
        positional = [*node.posonlyargs, *node.args]
        for arg, default in zip(
            positional[len(positional) - len(node.defaults) :], node.defaults, strict=True
        ):
            yield arg.arg, default
        for arg, default in zip(node.kwonlyargs, node.kw_defaults, strict=True):
            yield arg.arg, default


def _is_hand_number(value: ast.AST | None) -> bool:
    return (
        isinstance(value, ast.Constant) and not isinstance(value.value, bool) and value.value in HAND_NUMBERS
    )


def hand_constants(source: str, path: str) -> list[str]:
    """``path:line: name`` for every hand constant ``source`` defines."""
    found = []
    for node in ast.walk(ast.parse(source)):
        for name, value in _targets(node):
            if name in HAND_NAMES or (ABOUT_A_HAND.search(name) and _is_hand_number(value)):
                found.append(f"{path}:{node.lineno if hasattr(node, 'lineno') else value.lineno}: {name}")
    return found


def test_no_shipped_module_but_the_reader_defines_a_hand_constant():
    found = []
    for package in SHIPPED:
        for path in sorted((ROOT / package).rglob("*.py")):
            relative = path.relative_to(ROOT).as_posix()
            if relative != READER:
                found += hand_constants(path.read_text(encoding="utf-8"), relative)
    assert not found, "hand constants outside the gripper description (read them from it):\n" + "\n".join(
        found
    )


def test_the_scan_finds_each_kind():
    source = textwrap.dedent(
        """
        MAX_OPENING = 0.085
        class Spec:
            finger_depth: float = 0.05
        def close(width, opening=0.08):
            self.pad_half = 0.05
        TABLE_Z = 0.05
        SCALE = 0.08
        """
    )
    assert hand_constants(source, "m.py") == [
        "m.py:2: MAX_OPENING",
        "m.py:4: finger_depth",
        "m.py:5: opening",
        "m.py:6: pad_half",
    ]
