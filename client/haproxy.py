"""Moved to ``service.launch.haproxy``, beside the server it starts; forwarded from here for one release."""

from __future__ import annotations

import importlib
import sys
from typing import TYPE_CHECKING

from client.moved import forwarding, warn_moved

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

__getattr__ = forwarding(__name__, "service.launch.haproxy", __all__)


if __name__ == "__main__":
    sys.exit(importlib.import_module("service.launch.haproxy").main())
