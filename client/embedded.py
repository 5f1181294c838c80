"""Moved to ``service.launch.embedded``, beside the server it starts; forwarded from here for one release."""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from client.moved import warn_moved

if TYPE_CHECKING:
    from service.launch.embedded import EmbeddedService, bind_error, free_port

warn_moved("client.embedded", "service.launch.embedded")

__all__ = [
    "EmbeddedService",
    "bind_error",
    "free_port",
]


def __getattr__(name: str) -> Any:
    """Each name on first use, so that importing ``client`` loads none of the server's package."""
    if name not in __all__:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module("service.launch.embedded"), name)
