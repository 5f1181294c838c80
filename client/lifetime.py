"""Moved to ``service.launch.lifetime``, beside the server it starts; forwarded from here for one release."""

from __future__ import annotations

from typing import TYPE_CHECKING

from client.moved import forwarding, warn_moved

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

__getattr__ = forwarding(__name__, "service.launch.lifetime", __all__)
