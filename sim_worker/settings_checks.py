"""Checks that run-settings dataclasses apply on construction, so a typo in a scene, planner
or renderer name fails at once with its allowed values instead of deep inside a run (or, worse,
after hours of a run recorded under a setting nothing understood)."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any, get_args


def check_choice(name: str, value: Any, allowed: Any) -> None:
    """``value`` must be one of ``allowed`` (an iterable or a ``Literal`` type)."""
    options = tuple(get_args(allowed)) or tuple(allowed if isinstance(allowed, Iterable) else ())
    if value not in options:
        raise ValueError(f"{name} must be one of {', '.join(map(repr, options))}; got {value!r}")


def check_at_least(name: str, value: int, minimum: int) -> None:
    """``value`` must be an integer (not a bool) of at least ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}; got {value!r}")


def check_fraction(name: str, value: float | None, optional: bool = False) -> None:
    """A share or a probability threshold: a number in [0, 1] (or None where ``optional``)."""
    if value is None and optional:
        return
    if isinstance(value, bool) or not isinstance(value, int | float) or not 0.0 <= value <= 1.0:
        raise ValueError(f"{name} must be a number in [0, 1]; got {value!r}")
