"""The hands the service plans for: which it knows, which a network serves, and the one in use.

The service knows the built-in descriptions (``vgn_contract/grippers/``) and the files its operator
adds (``VGN_GRIPPERS``); a session names one (default ``franka``) and is refused when the hand
is unknown or no loaded network was trained for it, since a network's grasps are what its
hand could do. While a session's grasps are checked, :func:`planning_for` makes its hand the
one the clearance and grip checks measure (a context variable: each request thread sees its
own, and code that names no hand gets ``franka``, the hand of every existing result).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from pathlib import Path

from service.errors import GripperNotServed, InvalidInput
from vgn_contract.gripper_description import (
    DEFAULT_GRIPPER,
    GripperDescription,
    builtin_gripper,
    builtin_grippers,
    default_gripper,
    read_gripper,
)

_ACTIVE: ContextVar[GripperDescription | None] = ContextVar("vgn_gripper", default=None)


def active_hand() -> GripperDescription:
    """The hand the checks measure now: the planning session's, else the default hand."""
    return _ACTIVE.get() or default_gripper()


@contextmanager
def planning_for(hand: GripperDescription) -> Iterator[GripperDescription]:
    """Make ``hand`` the active hand inside the ``with`` block (this thread or task only)."""
    token = _ACTIVE.set(hand)
    try:
        yield hand
    finally:
        _ACTIVE.reset(token)


@dataclass(frozen=True)
class Hands:
    """The hands one service knows, by name, and the names a network serves: the main network's,
    and those with a network of their own (``VGN_HAND_MODELS``)."""

    known: dict[str, GripperDescription]
    served: frozenset[str]

    @classmethod
    def build(
        cls,
        extra_files: Iterable[Path] = (),
        network_hands: Iterable[str] = (DEFAULT_GRIPPER,),
        own_networks: Iterable[str] = (),
    ) -> Hands:
        """The built-in hands plus ``extra_files`` (a name taken twice is an error); the
        service's network serves ``network_hands`` (whether or not it is loaded yet), and each of
        ``own_networks`` has one of its own."""
        known = {name: builtin_gripper(name) for name in builtin_grippers()}
        for path in extra_files:
            description = read_gripper(path)
            if description.name in known:
                raise ValueError(f"{path}: the gripper name {description.name!r} is taken; rename it")
            known[description.name] = description
        hands = cls(known, frozenset())
        main = hands.checked("VGN_NETWORK_GRIPPERS", network_hands)
        return cls(known, main | hands.checked("VGN_HAND_MODELS", own_networks))

    def checked(self, setting: str, names: Iterable[str]) -> frozenset[str]:
        """``names``, which ``setting`` gives, all known hands (``ValueError`` naming the others)."""
        named = frozenset(names)
        unknown = sorted(named - set(self.known))
        if unknown:
            raise ValueError(f"{setting} names unknown hands {unknown}; known: {sorted(self.known)}")
        return named

    def resolve(self, name: str | None) -> GripperDescription:
        """The hand a new session plans for: ``InvalidInput`` for an unknown name,
        ``GripperNotServed`` for a hand no loaded network serves."""
        name = name or DEFAULT_GRIPPER
        if name not in self.known:
            raise InvalidInput(
                f"unknown gripper {name!r}; this service knows: {', '.join(sorted(self.known))}"
            )
        if name not in self.served:
            served = ", ".join(sorted(self.served)) or "none"
            raise GripperNotServed(
                f"no network of this service is trained for the gripper {name!r}; hands with a network: {served}"
            )
        return self.known[name]
