"""Scenes into recipe shards: new raw datasets (generated with recipes) and migrated grid shards."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from sim_worker.recipes import object_ref, object_roots
from training.grids import MAX_DEPTH, RESOLUTION, fuse_grid
from training.migrate import legacy_scenes, read_result
from training.recipe_grids import grid_digest
from training.recipe_shards import DEFAULT_SCENES_PER_SHARD, RecipeFolder, RecipeRecord
from training.shards import ShardError, ShardFolder, quantize
from vgn_data.dataset import RawDataset

#: Generation settings recorded since some sources were packed: a folder that records them still
#: packs into such a source when every other setting matches (the hand's name and description digest).
RECORDED_LATER = ("gripper_name", "gripper_digest")


def portable_generation(generation: dict[str, Any], object_refs: Iterable[str]) -> dict[str, Any]:
    """A source's generator settings with its object folders named by the object references its
    scenes use (``vgn:pile/train``), not by one machine's paths."""
    folders = set()
    for ref in object_refs:
        root, _, path = ref.partition(":")
        folders.add(f"{root}:{path.rsplit('/', 1)[0] if '/' in path else ''}")
    return {**generation, "objects": sorted(folders)}


def portable_objects(arrays: dict[str, np.ndarray], roots: dict[str, Path]) -> dict[str, np.ndarray]:
    """A recipe's arrays with every ``file:`` object that lies under a known root (VGN's object
    sets at ``$VGN_OBJECTS``, ``pybullet_data``, the built-in blocks) named by that root, as
    scenes generated without ``$VGN_OBJECTS`` set record them; the sha256s are kept, so a
    rebuild still proves the files are the same."""
    refs = [str(ref) for ref in arrays["objects"]]
    portable = [object_ref(Path(ref.removeprefix("file:")), roots) if ref.startswith("file:") else ref
                for ref in refs]  # fmt: skip
    return arrays if portable == refs else {**arrays, "objects": np.array(portable)}


def _chunks(records: list[RecipeRecord], size: int) -> Iterable[list[RecipeRecord]]:
    for start in range(0, len(records), size):
        yield records[start : start + size]


def pack_raw(
    raw: RawDataset, source: str, out: Path, scenes_per_shard: int = DEFAULT_SCENES_PER_SHARD,
    limit: int | None = None,
) -> list[dict[str, Any]]:  # fmt: skip
    """Pack the scenes of ``raw`` that carry a recipe and are not in ``out`` yet as new shards of
    ``source``; the digest is taken of the grid fused from the raw depth the labels were made on.
    Objects recorded by absolute path under a known root are named by the root
    (:func:`portable_objects`)."""
    generation = raw.generation()
    if "gripper" not in generation:
        raise ShardError(f"{raw.root} does not record the hand that labelled it (generation.json: gripper)")
    folder = RecipeFolder(out)
    manifest = folder.start(generation["gripper"], raw.setup.to_json())
    done = folder.scene_ids(source)
    ids, rows = raw.grasps()
    by_scene: dict[str, list[np.ndarray]] = {}
    for scene_id, row in zip(ids, rows, strict=True):
        by_scene.setdefault(scene_id, []).append(row)
    records, roots = [], object_roots()
    for scene_id in sorted(set(by_scene) - done):
        arrays = raw.read_recipe(scene_id)
        if arrays is None:
            continue  # made before generation wrote recipes: it cannot be rebuilt
        arrays = portable_objects(arrays, roots)
        grid = quantize(fuse_grid(raw.read_scene(scene_id), raw.setup, RESOLUTION, MAX_DEPTH))
        records.append(RecipeRecord(scene_id, arrays, grid_digest(grid), np.asarray(by_scene[scene_id])))
        if limit is not None and len(records) >= limit:
            break
    if not records:
        return []
    settings = portable_generation(generation, (str(r) for rec in records for r in rec.arrays["objects"]))
    known = manifest["sources"].get(source)
    # A source packed before a setting was recorded grows with scenes whose folder records it.
    later = {key for key in RECORDED_LATER if known is not None and key not in known}
    comparable = {key: value for key, value in settings.items() if key not in later}
    if known is not None and {**known, "objects": None} != {**comparable, "objects": None}:
        raise ShardError(
            f"source {source!r} in {out} was generated with other settings; use another source name"
        )
    if known is not None:
        settings["objects"] = sorted(set(known["objects"]) | set(settings["objects"]))
    manifest["sources"][source] = settings
    return [folder.append(manifest, source, chunk) for chunk in _chunks(records, scenes_per_shard)]


def finish_migration(
    grids: ShardFolder, work: Path, out: Path, scenes_per_shard: int = DEFAULT_SCENES_PER_SHARD
) -> dict[str, Any]:
    """Write the converted scenes of every source (those whose rebuild matched their grid) as
    recipe shards in ``out``, and record in the manifest what was converted and what was not,
    and why. Returns that record per source. The grid shards are not touched."""
    old = grids.manifest()
    legacy = {
        source: list(legacy_scenes(grids, source)) for source in old["sources"]
    }  # read before out changes
    folder = RecipeFolder(out)
    manifest = folder.start(old["gripper"], old["setup"], replace_grids=True)
    summary: dict[str, Any] = {}
    for source, generation in old["sources"].items():
        records, missing, reasons = [], 0, {}
        for scene_id, grid, labels in legacy[source]:
            path = work / source / f"{scene_id}.npz"
            if not path.is_file():
                missing += 1
                continue
            result, arrays = read_result(path)
            if not result["match"]:
                reasons[result["reason"]] = reasons.get(result["reason"], 0) + 1
                continue
            records.append(RecipeRecord(scene_id, arrays, grid_digest(grid), labels))
        if missing:
            raise ShardError(
                f"{missing} scenes of {source!r} have not been converted yet: run vgn-data migrate first"
            )
        manifest["sources"][source] = portable_generation(
            generation, (str(r) for rec in records for r in rec.arrays["objects"])
        )
        total = len(records) + sum(reasons.values())
        summary[source] = {"scenes": total, "converted": len(records), "not_converted": reasons,
                           "grid_shards": [s["file"] for s in old["shards"] if s["source"] == source]}  # fmt: skip
        manifest["migration"] = summary
        for chunk in _chunks(records, scenes_per_shard):
            folder.append(manifest, source, chunk)
    return summary
