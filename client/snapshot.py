"""Moved to ``vgn_contract.snapshot`` (the wire contract); re-exported here for one release."""

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
