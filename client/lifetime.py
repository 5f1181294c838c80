"""Moved to ``service.launch.lifetime``, beside the server it starts; forwarded from here for one release."""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from client.moved import warn_moved

if TYPE_CHECKING:
    from service.launch.lifetime import (
        PARENT_VARIABLE,
        end_with_parent,
        end_with_parent_if_asked,
        ending_with_this_process,
    )

warn_moved("client.lifetime", "service.launch.lifetime")

__all__ = [
    "PARENT_VARIABLE",
    "end_with_parent",
    "end_with_parent_if_asked",
    "ending_with_this_process",
]


def __getattr__(name: str) -> Any:
    """Each name on first use, so that importing ``client`` loads none of the server's package."""
    if name not in __all__:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module("service.launch.lifetime"), name)
