"""Moved to ``service.launch.embedded``, beside the server it starts; forwarded from here for one release."""

from __future__ import annotations

from typing import TYPE_CHECKING

from client.moved import forwarding, warn_moved

if TYPE_CHECKING:
    from service.launch.embedded import EmbeddedService, bind_error, free_port

warn_moved("client.embedded", "service.launch.embedded")

__all__ = [
    "EmbeddedService",
    "bind_error",
    "free_port",
]

__getattr__ = forwarding(__name__, "service.launch.embedded", __all__)
