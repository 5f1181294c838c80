"""Session snapshots: a session's fused volumes and settings as one compact file, so that a
session can leave a service (an operator draining a replica) and carry on in another.

The format is ``vgn_contract.snapshot``'s. Reading one checks everything before a session is
built from it: the members and their array headers (shape and dtype, read before any data,
so a small upload cannot declare a huge array), the settings by the API's own schemas, and the
voxels (finite, tsdf in [-1, 1], weights not negative).
"""

from __future__ import annotations

import io
import json
import re
import zipfile
from dataclasses import dataclass
from typing import IO

import numpy as np
from pydantic import ValidationError

from service.errors import InvalidInput
from vgn_contract import snapshot as fmt
from vgn_contract.gripper_description import DEFAULT_GRIPPER, NAME_PATTERN
from vgn_contract.schemas import SESSION_ID_PATTERN, Intrinsics, Workspace

#: Largest fine (cloud) volume a snapshot may carry, voxels a side (``VGN_CLOUD_RESOLUTION``'s bound).
MAX_FINE_RESOLUTION = 400


@dataclass(frozen=True)
class Snapshot:
    """A session's state: what it fuses into, and its volumes as ``SceneVolume.state()`` gives them."""

    session_id: str
    workspace: Workspace
    intrinsics: Intrinsics | None
    frame_count: int
    integration_ms: float
    coarse: np.ndarray
    fine: np.ndarray | None
    decay: float | None = None  # a forgetting session's factor (absent in older snapshots)
    gripper: str = DEFAULT_GRIPPER  # the hand the session plans for (absent in older snapshots)


def encode(snapshot: Snapshot) -> bytes:
    """The ``.npz`` bytes of a snapshot (compressed: most voxels of a scene are unobserved)."""
    meta = {
        "format": fmt.FORMAT,
        "version": fmt.VERSION,
        "session_id": snapshot.session_id,
        "workspace": snapshot.workspace.model_dump(mode="json"),
        "intrinsics": None if snapshot.intrinsics is None else snapshot.intrinsics.model_dump(mode="json"),
        "frame_count": snapshot.frame_count,
        "integration_ms": snapshot.integration_ms,
        "decay": snapshot.decay,
        "gripper": snapshot.gripper,
    }
    arrays = {fmt.META: np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8), fmt.COARSE: snapshot.coarse}
    if snapshot.fine is not None:
        arrays[fmt.FINE] = snapshot.fine
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    return buffer.getvalue()


def decode(data: bytes) -> Snapshot:
    """A checked snapshot; ``InvalidInput`` (HTTP 400) says what is wrong with ``data``."""
    try:
        meta = fmt.meta_of(data)
    except ValueError as error:
        raise InvalidInput(str(error)) from None
    session_id = meta.get("session_id")
    if not isinstance(session_id, str) or not _valid_id(session_id):
        raise InvalidInput(f"the snapshot's session id {session_id!r} is not a valid session id")
    try:
        workspace = Workspace.model_validate(meta.get("workspace"))
        intrinsics = None if meta.get("intrinsics") is None else Intrinsics.model_validate(meta["intrinsics"])
    except ValidationError as error:
        raise InvalidInput(f"the snapshot's settings are invalid: {error.errors()[0]['msg']}") from None
    frame_count, integration_ms = meta.get("frame_count"), meta.get("integration_ms")
    if not isinstance(frame_count, int) or frame_count < 0:
        raise InvalidInput(f"the snapshot's frame_count must be a count, got {frame_count!r}")
    if not isinstance(integration_ms, int | float) or not np.isfinite(integration_ms) or integration_ms < 0:
        raise InvalidInput(f"the snapshot's integration_ms must be a duration, got {integration_ms!r}")
    decay = meta.get("decay")
    if decay is not None and (
        isinstance(decay, bool) or not isinstance(decay, int | float) or not 0 < decay < 1
    ):
        raise InvalidInput(f"the snapshot's decay must be a number in (0, 1) or null, got {decay!r}")
    gripper = meta.get("gripper", DEFAULT_GRIPPER)
    if not isinstance(gripper, str) or re.fullmatch(NAME_PATTERN, gripper) is None:
        raise InvalidInput(f"the snapshot's gripper must be a gripper name, got {gripper!r}")
    with zipfile.ZipFile(io.BytesIO(data)) as archive:
        members = set(archive.namelist())
        unknown = members - {f"{name}.npy" for name in (fmt.META, fmt.COARSE, fmt.FINE)}
        if unknown:
            raise InvalidInput(f"the snapshot holds unknown members {sorted(unknown)}")
        coarse = _volume(archive, fmt.COARSE, {workspace.resolution})
        fine = None
        if f"{fmt.FINE}.npy" in members:
            fine = _volume(archive, fmt.FINE, set(range(16, MAX_FINE_RESOLUTION + 1)))
    return Snapshot(session_id, workspace, intrinsics, frame_count, float(integration_ms), coarse, fine,
                    None if decay is None else float(decay), gripper)  # fmt: skip


def _valid_id(session_id: str) -> bool:
    return re.fullmatch(SESSION_ID_PATTERN, session_id) is not None


def _volume(archive: zipfile.ZipFile, name: str, resolutions: set[int]) -> np.ndarray:
    """A (R³, 2) float32 volume state with R in ``resolutions``, its header checked before its data is read."""
    try:
        with archive.open(f"{name}.npy") as member:
            shape, dtype = _header(member)
            resolution = round(shape[0] ** (1 / 3)) if len(shape) == 2 and shape[0] > 0 else 0
            if dtype != np.dtype("<f4") or shape != (resolution**3, 2) or resolution not in resolutions:
                wanted = (
                    f"{min(resolutions)}-{max(resolutions)}" if len(resolutions) > 1 else min(resolutions)
                )
                raise InvalidInput(
                    f"the snapshot's '{name}' must be (R³, 2) little-endian float32 with R = {wanted}, "
                    f"got {shape} {dtype}"
                )
        with archive.open(f"{name}.npy") as member:
            state = np.lib.format.read_array(member, allow_pickle=False)
    except KeyError:
        raise InvalidInput(f"the snapshot has no '{name}' volume") from None
    except (ValueError, OSError, zipfile.BadZipFile, EOFError) as error:
        raise InvalidInput(f"the snapshot's '{name}' cannot be read: {error}") from None
    tsdf, weight = state[:, 0], state[:, 1]
    if not (np.isfinite(state).all() and np.abs(tsdf).max(initial=0) <= 1.0 and weight.min(initial=0) >= 0):
        raise InvalidInput(
            f"the snapshot's '{name}' holds voxels out of range (finite, |tsdf| <= 1, weight >= 0)"
        )
    return state


def _header(member: IO[bytes]) -> tuple[tuple[int, ...], np.dtype]:
    """Shape and dtype from a ``.npy`` header, refusing Fortran order and pickled objects."""
    version = np.lib.format.read_magic(member)
    if version == (1, 0):
        shape, fortran, dtype = np.lib.format.read_array_header_1_0(member)
    elif version == (2, 0):
        shape, fortran, dtype = np.lib.format.read_array_header_2_0(member)
    else:
        raise ValueError(f"unsupported .npy version {version}")
    if fortran or dtype.hasobject:
        raise ValueError("arrays must be C-ordered numbers")
    return shape, dtype
