"""Training data as it is kept in the repository: packed, append-only shards with a manifest.

Raw datasets (depth images, ``vgn_data.dataset``) are too large to keep and do not survive from
one machine to the next. What training needs of a scene is its fused network input and its
labels, so a shard holds, for a few hundred to a thousand scenes, ``scene_ids``, ``grids``
(uint8 ``round(255 · grid)``: 0 stays exactly 0, "unobserved"), ``grasp_scene`` and every
label as generated in ``grasps`` (float16, workspace frame), as an uncompressed ``.npz`` in an
xz stream. ``manifest.json`` lists the shards and, per source, the generator's settings and
hand. Shards are never rewritten, and data made by another hand or under other generator
settings is refused rather than mixed.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import io
import json
import lzma
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from training.grids import MAX_DEPTH, RESOLUTION, fuse_grid
from vgn_data.dataset import RawDataset
from vgn_data.files import remove_stale_temporaries, write_atomically

MANIFEST = "manifest.json"
SHARD_FORMAT = 1
# Precision kept: the quantised grid is within 1/510 (about 0.002) of the network input, and float16
# labels keep positions to 0.25 mm, a 30th of a voxel. The xz stream is about a quarter smaller than
# the .npz's own deflate on these grids.
QUANTISATION = "uint8 = round(255 * grid)"
#: Scenes per shard: about 10 MB at ~10 kB a scene (grid and labels compressed).
DEFAULT_SCENES_PER_SHARD = 1000


class ShardError(Exception):
    """A shard folder is damaged, or new data does not belong in it."""


def quantize(grid: np.ndarray) -> np.ndarray:
    """uint8 network input: round(255 · grid), grid values in [0, 1]."""
    return np.rint(np.clip(grid, 0.0, 1.0) * 255.0).astype(np.uint8)


def dequantize(grid: np.ndarray) -> np.ndarray:
    """The float32 grid of a ``quantize``d one, within 1/510 of the original."""
    return grid.astype(np.float32) / np.float32(255.0)


def sha256_of(path: Path) -> str:
    """Hex sha256 of a file, read in 1 MiB blocks."""
    digest = hashlib.sha256()
    with path.open("rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


@dataclass
class Shard:
    """One loaded shard; ``grids`` stay quantised until a scene is used."""

    source: str
    scene_ids: np.ndarray
    grids: np.ndarray
    grasp_scene: np.ndarray
    grasps: np.ndarray

    def rows_by_scene(self) -> list[np.ndarray]:
        """The label rows of each scene, in scene order."""
        order = np.argsort(self.grasp_scene, kind="stable")
        bounds = np.searchsorted(self.grasp_scene[order], np.arange(len(self.scene_ids) + 1))
        return [self.grasps[order[bounds[i] : bounds[i + 1]]] for i in range(len(self.scene_ids))]


class ShardFolder:
    """A folder of shards and its manifest: read, verify, and append new shards."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)
        self.manifest_path = self.root / MANIFEST

    def exists(self) -> bool:
        """Whether the folder holds a manifest, i.e. is a packed dataset."""
        return self.manifest_path.is_file()

    def manifest(self) -> dict[str, Any]:
        """The manifest as JSON; ``FileNotFoundError`` when the folder is not a packed dataset."""
        if not self.exists():
            raise FileNotFoundError(f"{self.manifest_path} does not exist: not a packed dataset folder")
        return json.loads(self.manifest_path.read_text())

    def load(self, verify: bool = True) -> list[Shard]:
        """Every shard, checked against the manifest's sha256 when ``verify``."""
        manifest = self.manifest()
        shards = []
        for entry in manifest["shards"]:
            path = checked_shard(self.root, entry, self.manifest_path, verify)
            with _open_shard(path) as data:
                shards.append(
                    Shard(
                        entry["source"],
                        data["scene_ids"],
                        data["grids"],
                        data["grasp_scene"],
                        data["grasps"].astype(np.float32),
                    )
                )
        return shards

    def packed_scene_ids(self, source: str) -> set[str]:
        """The scene ids already packed for ``source``: what a rerun of ``pack`` skips."""
        ids: set[str] = set()
        if not self.exists():
            return ids
        for entry in self.manifest()["shards"]:
            if entry["source"] == source:
                with _open_shard(self.root / entry["file"]) as data:
                    ids.update(str(s) for s in data["scene_ids"])
        return ids

    def pack(
        self,
        raw: RawDataset,
        source: str,
        scenes_per_shard: int = DEFAULT_SCENES_PER_SHARD,
        resolution: int = RESOLUTION,
        max_depth: float = MAX_DEPTH,
        limit: int | None = None,
        progress: Callable[[str], object] | None = None,
    ) -> list[dict[str, Any]]:
        """Fuse and pack the scenes of ``raw`` not packed yet as new shards of ``source``;
        returns the new manifest entries. ``limit`` caps the scenes packed by this call;
        ``progress`` is called with each scene id once it is fused."""
        if not source.replace("-", "").replace("_", "").isalnum():
            raise ShardError(f"source name {source!r} must be alphanumeric (with - or _)")
        manifest = self._manifest_for(raw, source, resolution, max_depth)
        remove_stale_temporaries(self.root)
        packed = self.packed_scene_ids(source)
        ids, rows = raw.grasps()
        by_scene: dict[str, list[np.ndarray]] = {}
        for scene_id, row in zip(ids, rows, strict=True):
            by_scene.setdefault(scene_id, []).append(row)
        todo = sorted(sid for sid in by_scene if sid not in packed)
        if limit is not None:
            todo = todo[:limit]
        entries = []
        for start in range(0, len(todo), scenes_per_shard):
            chunk = todo[start : start + scenes_per_shard]
            grids = []
            for scene_id in chunk:
                grid = fuse_grid(raw.read_scene(scene_id), raw.setup, resolution, max_depth)
                grids.append(quantize(grid))
                if progress:
                    progress(scene_id)
            label_rows = [np.asarray(by_scene[sid], dtype=np.float32).reshape(-1, 9) for sid in chunk]
            entry = self._write_shard(manifest, source, chunk, np.stack(grids), label_rows)
            manifest["shards"].append(entry)
            manifest["updated"] = _now()
            write_atomically(self.manifest_path, json.dumps(manifest, indent=2) + "\n")
            entries.append(entry)
        return entries

    def _manifest_for(
        self, raw: RawDataset, source: str, resolution: int, max_depth: float
    ) -> dict[str, Any]:
        """The manifest to extend, after checking that ``raw`` may join it."""
        generation = raw.generation()
        gripper = generation.get("gripper")
        if gripper is None:
            raise ShardError(
                f"{raw.root} does not record the hand that labelled it (generation.json: gripper)"
            )
        fixed = {
            "format": SHARD_FORMAT,
            "resolution": resolution,
            "max_depth": max_depth,
            "quantisation": QUANTISATION,
            "gripper": gripper,
            "setup": raw.setup.to_json(),
        }
        if self.exists():
            manifest = self.manifest()
            for key, value in fixed.items():
                if manifest.get(key) != value:
                    raise ShardError(
                        f"{self.root} holds data with {key}={manifest.get(key)!r}; {raw.root} has {value!r}: "
                        "data of different hands, grids or setups is never mixed (use another folder)"
                    )
            known = manifest["sources"].get(source)
            if known is not None and known != generation:
                raise ShardError(
                    f"source {source!r} in {self.root} was generated with other settings; "
                    "give these scenes another source name"
                )
        else:
            manifest = {**fixed, "sources": {}, "shards": [], "created": _now()}
        manifest["sources"][source] = generation
        return manifest

    def _write_shard(
        self,
        manifest: dict[str, Any],
        source: str,
        scene_ids: list[str],
        grids: np.ndarray,
        label_rows: list[np.ndarray],
    ) -> dict[str, Any]:
        taken = {entry["file"] for entry in manifest["shards"]}
        index = sum(1 for entry in manifest["shards"] if entry["source"] == source)
        name = f"shards/{source}-{index:04d}.npz.xz"
        while name in taken or (self.root / name).exists():
            index += 1
            name = f"shards/{source}-{index:04d}.npz.xz"
        grasps = np.concatenate(label_rows) if label_rows else np.zeros((0, 9), np.float32)
        grasp_scene = np.concatenate(
            [np.full(len(rows), i, dtype=np.int32) for i, rows in enumerate(label_rows)]
        )
        buffer = io.BytesIO()
        np.savez(
            buffer,
            scene_ids=np.asarray(scene_ids),
            grids=grids,
            grasp_scene=grasp_scene,
            grasps=grasps.astype(np.float16),
        )
        path = self.root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomically(path, lzma.compress(buffer.getvalue(), preset=9))
        return {
            "file": name,
            "sha256": sha256_of(path),
            "bytes": path.stat().st_size,
            "source": source,
            "scenes": len(scene_ids),
            "grasps": int(len(grasps)),
            "positives": int((grasps[:, 8] > 0.5).sum()),
            "first_scene": scene_ids[0],
            "last_scene": scene_ids[-1],
            "created": _now(),
        }


def checked_shard(root: Path, entry: dict[str, Any], manifest_path: Path, verify: bool = True) -> Path:
    """The path of a manifest entry's shard, after checking that it is there and (with ``verify``)
    that it is the file the manifest names by sha256."""
    path = root / entry["file"]
    if not path.is_file():
        raise ShardError(f"{path} is listed in {manifest_path} but missing")
    if verify and sha256_of(path) != entry["sha256"]:
        raise ShardError(f"{path} does not match its sha256 in the manifest: damaged or rewritten")
    return path


def _open_shard(path: Path) -> np.lib.npyio.NpzFile:
    """The shard's arrays (an ``NpzFile``, usable as a context manager)."""
    try:
        return np.load(io.BytesIO(lzma.decompress(path.read_bytes())))
    except (lzma.LZMAError, ValueError, OSError) as error:
        raise ShardError(f"{path} cannot be read as a shard: {error}") from error


def _now() -> str:
    return dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds")


def manifest_summary(manifest: dict[str, Any]) -> dict[str, Any]:
    """Totals over a manifest, for the model card and the README."""
    shards = manifest["shards"]
    return {
        "gripper": manifest["gripper"],
        "shards": [{"file": s["file"], "sha256": s["sha256"]} for s in shards],
        "scenes": sum(s["scenes"] for s in shards),
        "grasps": sum(s["grasps"] for s in shards),
        "positives": sum(s["positives"] for s in shards),
        "bytes": sum(s["bytes"] for s in shards),
    }
