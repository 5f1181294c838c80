"""Moved to ``service.launch.haproxy``, beside the server it starts; forwarded from here for one release."""

from __future__ import annotations

import importlib
import sys
from typing import TYPE_CHECKING, Any

from client.moved import warn_moved

if TYPE_CHECKING:
    from service.launch.haproxy import ProxyConfig, Replica, main, numbered, render

warn_moved("client.haproxy", "service.launch.haproxy")

__all__ = [
    "ProxyConfig",
    "Replica",
    "main",
    "numbered",
    "render",
]


def __getattr__(name: str) -> Any:
    """Each name on first use, so that importing ``client`` loads none of the server's package."""
    if name not in __all__:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module("service.launch.haproxy"), name)


if __name__ == "__main__":
    sys.exit(importlib.import_module("service.launch.haproxy").main())
