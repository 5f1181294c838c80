"""Moved to ``service.launch.fleet``, beside the server it starts; forwarded from here for one release."""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from client.moved import warn_moved

if TYPE_CHECKING:
    from service.launch.fleet import EXEC_ENDING_WITH_PARENT, Fleet, FleetConfig, FleetError

warn_moved("client.fleet", "service.launch.fleet")

__all__ = [
    "EXEC_ENDING_WITH_PARENT",
    "Fleet",
    "FleetConfig",
    "FleetError",
]


def __getattr__(name: str) -> Any:
    """Each name on first use, so that importing ``client`` loads none of the server's package."""
    if name not in __all__:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module("service.launch.fleet"), name)
