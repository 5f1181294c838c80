"""Moved to ``vgn_contract.snapshot`` (the wire contract); re-exported here for one release."""

from client.moved import warn_moved
from vgn_contract.snapshot import (
    COARSE,
    FINE,
    FORMAT,
    MEDIA_TYPE,
    META,
    VERSION,
    meta_of,
    session_id_of,
)

warn_moved("client.snapshot", "vgn_contract.snapshot")

__all__ = [
    "COARSE",
    "FINE",
    "FORMAT",
    "MEDIA_TYPE",
    "META",
    "VERSION",
    "meta_of",
    "session_id_of",
]
