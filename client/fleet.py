"""Moved to ``service.launch.fleet``, beside the server it starts; forwarded from here for one release."""

from __future__ import annotations

from typing import TYPE_CHECKING

from client.moved import forwarding, warn_moved

if TYPE_CHECKING:
    from service.launch.fleet import EXEC_ENDING_WITH_PARENT, Fleet, FleetConfig, FleetError

warn_moved("client.fleet", "service.launch.fleet")

__all__ = [
    "EXEC_ENDING_WITH_PARENT",
    "Fleet",
    "FleetConfig",
    "FleetError",
]

__getattr__ = forwarding(__name__, "service.launch.fleet", __all__)
