"""The session snapshot format, shared by the service (which writes and reads it) and the client.

A snapshot is a ``.npz`` (a zip of ``.npy`` arrays, no pickles) holding

* ``meta``: UTF-8 JSON as uint8 bytes: ``format``, ``version``, ``session_id``, ``workspace``,
  ``intrinsics``, ``frame_count``, ``integration_ms``;
* ``coarse``: (N³, 2) float32 (tsdf, weight) of the grid the network reads (N = the workspace's
  resolution);
* ``fine``: (M³, 2) float32 of the volume behind the point cloud, when a frame reached it.

The client needs only the session id (to route an import to the replica that will own it).
"""

from __future__ import annotations

import io
import json
import zipfile
from typing import Any

import numpy as np

FORMAT = "vgn-session-snapshot"
VERSION = 1
MEDIA_TYPE = "application/x-npz"
META, COARSE, FINE = "meta", "coarse", "fine"


def meta_of(data: bytes) -> dict[str, Any]:
    """The ``meta`` record of a snapshot; ``ValueError`` when ``data`` is not a snapshot of
    this format and version. Reads only that member, however large the volumes are."""
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as archive, archive.open(f"{META}.npy") as member:
            array = np.lib.format.read_array(member, allow_pickle=False)
    except (zipfile.BadZipFile, KeyError, ValueError, OSError) as error:
        raise ValueError(f"not a session snapshot (a .npz with a '{META}' array): {error}") from None
    if array.dtype != np.uint8 or array.ndim != 1 or array.size > 64 * 1024:
        raise ValueError(f"a snapshot's '{META}' must be at most 64 KiB of uint8 JSON")
    try:
        meta = json.loads(array.tobytes().decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as error:
        raise ValueError(f"a snapshot's '{META}' is not JSON: {error}") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT or meta.get("version") != VERSION:
        raise ValueError(f"not a {FORMAT} version {VERSION}")
    return meta


def session_id_of(data: bytes) -> str:
    """The id of the session a snapshot was taken of."""
    session_id = meta_of(data).get("session_id")
    if not isinstance(session_id, str):
        raise ValueError("the snapshot names no session id")
    return session_id
