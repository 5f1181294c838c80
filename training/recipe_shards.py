"""Training data as scene recipes: compact, append-only shards with a manifest (format 2).

A shard, ``shards/<source>-r<NNNN>.npz.xz``, is an uncompressed ``.npz`` inside an xz stream
holding, per scene, its ids, how it was originally observed (side view, renderer, depth-noise
state, the grid's digest), its placed objects (file, scale, settled pose), its original
cameras and its grasp labels; data/README.md lists every array with its shape and type.

Shards are never rewritten: new scenes go into new shards, and the manifest (written
atomically) lists each with its sha256. Data of another hand, grid or world is refused.
"""

from __future__ import annotations

import io
import json
import lzma
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from training.grids import MAX_DEPTH, RESOLUTION
from training.recipe_grids import DIGEST
from training.shards import ShardError, checked_shard, sha256_of
from training.shards import _now as now
from vgn_data.files import remove_stale_temporaries, write_atomically

RECIPE_FORMAT = 2
MANIFEST = "manifest.json"
#: The simulated world every recipe lives in (docs/conventions.md).
WORLD = {
    "table_top_z": 0.05,
    "workspace_size": 0.30,
    "workspace_pose": "identity (corner at the world origin)",
}
DEFAULT_SCENES_PER_SHARD = 2000


@dataclass
class RecipeRecord:
    """One scene as a shard stores it: recipe arrays (``sim_worker.recipes.recipe_arrays``),
    the digest of its original grid, and its label rows."""

    scene_id: str
    arrays: dict[str, np.ndarray]
    grid_digest: np.ndarray
    labels: np.ndarray


@dataclass
class RecipeShard:
    """A loaded recipe shard, with per-scene accessors."""

    source: str
    file: str
    data: dict[str, np.ndarray]

    @property
    def scene_ids(self) -> list[str]:
        """The shard's scene ids, in row order."""
        return [str(s) for s in self.data["scene_ids"]]

    def recipe(self, row: int) -> Any:
        """The ``SceneRecipe`` of scene ``row`` (imports the simulator's recipe module)."""
        from sim_worker.recipes import SceneRecipe

        d = self.data
        objects = d["object_scene"] == row
        views = d["view_scene"] == row
        return SceneRecipe(
            scene_id=str(d["scene_ids"][row]),
            objects=[str(d["object_refs"][i]) for i in d["object_file"][objects]],
            scales=d["object_scale"][objects],
            poses=d["object_pose"][objects],
            views=d["view_pose"][views],
            noise_state=d["noise_state"][row] if d["noisy"][row] else None,
            side_view=bool(d["side_view"][row]),
            renderer=str(d["renderer"][row]),
        )

    def labels_by_scene(self) -> list[np.ndarray]:
        """(n, 9) float32 label rows of each scene, in row order."""
        scene = self.data["grasp_scene"]
        order = np.argsort(scene, kind="stable")
        bounds = np.searchsorted(scene[order], np.arange(len(self.data["scene_ids"]) + 1))
        grasps = self.data["grasps"].astype(np.float32)
        return [grasps[order[bounds[i] : bounds[i + 1]]] for i in range(len(bounds) - 1)]

    def object_files(self) -> list[tuple[str, str, str]]:
        """(reference, urdf sha256, mesh sha256) of every object file the shard uses."""
        d = self.data
        return [(str(r), str(u), str(m))
                for r, u, m in zip(d["object_refs"], d["object_urdf_sha256"], d["object_mesh_sha256"], strict=True)]  # fmt: skip


def shard_arrays(records: list[RecipeRecord]) -> dict[str, np.ndarray]:
    """The arrays of one shard holding ``records``."""
    refs: dict[str, int] = {}
    urdf_sha, mesh_sha = [], []
    object_scene, object_file, scales, poses, view_scene, views = [], [], [], [], [], []
    noise, noisy, side, digests, grasp_scene, grasps, renderers = [], [], [], [], [], [], []
    for row, record in enumerate(records):
        a = record.arrays
        for ref, u, m in zip(a["objects"], a["urdf_sha256"], a["mesh_sha256"], strict=True):
            ref = str(ref)
            if ref not in refs:
                refs[ref] = len(refs)
                urdf_sha.append(str(u))
                mesh_sha.append(str(m))
            elif (urdf_sha[refs[ref]], mesh_sha[refs[ref]]) != (str(u), str(m)):
                raise ShardError(f"{record.scene_id}: object {ref} has other hashes than in earlier scenes")
            object_file.append(refs[ref])
            object_scene.append(row)
        scales.append(np.asarray(a["scales"], np.float64))
        poses.append(np.asarray(a["poses"], np.float64).reshape(-1, 7))
        view_pose = np.asarray(a["views"], np.float64).reshape(-1, 7)
        views.append(view_pose)
        view_scene += [row] * len(view_pose)
        state = np.asarray(a["noise_state"], np.uint64)
        noisy.append(state.size > 0)
        noise.append(state if state.size else np.zeros(6, np.uint64))
        side.append(bool(a["side_view"]))
        renderers.append(str(a["renderer"]) if "renderer" in a else "egl")
        digests.append(record.grid_digest)
        grasps.append(np.asarray(record.labels, np.float32).reshape(-1, 9))
        grasp_scene += [row] * len(grasps[-1])
    return {
        "scene_ids": np.asarray([r.scene_id for r in records]),
        "side_view": np.asarray(side, bool),
        "renderer": np.asarray(renderers),
        "noisy": np.asarray(noisy, bool),
        "noise_state": np.stack(noise).astype(np.uint64),
        "grid_digest": np.stack(digests).astype(np.uint8),
        "object_refs": np.asarray(list(refs)),
        "object_urdf_sha256": np.asarray(urdf_sha),
        "object_mesh_sha256": np.asarray(mesh_sha),
        "object_scene": np.asarray(object_scene, np.int32),
        "object_file": np.asarray(object_file, np.int32),
        "object_scale": np.concatenate(scales),
        "object_pose": np.concatenate(poses),
        "view_scene": np.asarray(view_scene, np.int32),
        "view_pose": np.concatenate(views),
        "grasp_scene": np.asarray(grasp_scene, np.int32),
        "grasps": np.concatenate(grasps).astype(np.float16),
    }


def _read(path: Path) -> dict[str, np.ndarray]:
    try:
        with np.load(io.BytesIO(lzma.decompress(path.read_bytes()))) as data:
            return {name: data[name] for name in data.files}
    except (lzma.LZMAError, ValueError, OSError) as error:
        raise ShardError(f"{path} cannot be read as a recipe shard: {error}") from error


class RecipeFolder:
    """A folder of recipe shards and its manifest: read, verify, append."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)
        self.manifest_path = self.root / MANIFEST

    def exists(self) -> bool:
        """Whether the folder holds a recipe manifest."""
        return self.manifest_path.is_file() and self.manifest().get("format") == RECIPE_FORMAT

    def manifest(self) -> dict[str, Any]:
        """The manifest; ``FileNotFoundError`` when there is none."""
        if not self.manifest_path.is_file():
            raise FileNotFoundError(f"{self.manifest_path} does not exist: not a data folder")
        return json.loads(self.manifest_path.read_text())

    def load(self, verify: bool = True) -> list[RecipeShard]:
        """Every shard, checked against its sha256 when ``verify``."""
        manifest = self.manifest()
        if manifest.get("format") != RECIPE_FORMAT:
            raise ShardError(
                f"{self.manifest_path} is format {manifest.get('format')}, not recipes ({RECIPE_FORMAT})"
            )
        shards = []
        for entry in manifest["shards"]:
            path = checked_shard(self.root, entry, self.manifest_path, verify)
            shards.append(RecipeShard(entry["source"], entry["file"], _read(path)))
        return shards

    def scene_ids(self, source: str | None = None) -> set[str]:
        """Scene ids already in the folder (of ``source``, or all)."""
        if not self.exists():
            return set()
        return {
            sid
            for shard in self.load(verify=False)
            if source in (None, shard.source)
            for sid in shard.scene_ids
        }

    def start(self, gripper: str, setup: dict[str, Any], replace_grids: bool = False) -> dict[str, Any]:
        """The manifest to extend: the folder's, after checking the hand and setup match, or a new
        one (also in place of a grid-shard manifest with ``replace_grids``, for the migration)."""
        fixed = {"format": RECIPE_FORMAT, "resolution": RESOLUTION, "max_depth": MAX_DEPTH,
                 "grid_digest": DIGEST, "gripper": gripper, "setup": setup, "world": WORLD}  # fmt: skip
        if not self.manifest_path.is_file() or (replace_grids and self.manifest().get("format") == 1):
            return {**fixed, "sources": {}, "shards": [], "created": now()}
        manifest = self.manifest()
        for key, value in fixed.items():
            if manifest.get(key) != value:
                raise ShardError(f"{self.root} holds data with {key}={manifest.get(key)!r}, not {value!r}: "
                                 "data of different hands, grids or worlds is never mixed")  # fmt: skip
        return manifest

    def append(self, manifest: dict[str, Any], source: str, records: list[RecipeRecord]) -> dict[str, Any]:
        """Write ``records`` as a new shard of ``source`` and the manifest listing it; returns its entry."""
        if not source.replace("-", "").replace("_", "").isalnum():
            raise ShardError(f"source name {source!r} must be alphanumeric (with - or _)")
        remove_stale_temporaries(self.root)
        taken = {entry["file"] for entry in manifest["shards"]}
        index = sum(1 for entry in manifest["shards"] if entry["source"] == source)
        while (name := f"shards/{source}-r{index:04d}.npz.xz") in taken or (self.root / name).exists():
            index += 1
        arrays = shard_arrays(records)
        buffer = io.BytesIO()
        np.savez(buffer, **arrays)
        path = self.root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomically(path, lzma.compress(buffer.getvalue(), preset=9 | lzma.PRESET_EXTREME))
        labels = arrays["grasps"]
        entry = {
            "file": name, "sha256": sha256_of(path), "bytes": path.stat().st_size, "source": source,
            "scenes": len(records), "grasps": int(len(labels)), "positives": int((labels[:, 8] > 0.5).sum()),
            "first_scene": records[0].scene_id, "last_scene": records[-1].scene_id, "created": now(),
        }  # fmt: skip
        manifest["shards"].append(entry)
        manifest["updated"] = now()
        write_atomically(self.manifest_path, json.dumps(manifest, indent=2) + "\n")
        return entry
