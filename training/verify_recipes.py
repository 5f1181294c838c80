"""``vgn-data verify``: rebuild scenes from their recipes and check that they are the scenes that
were labelled.

Each recipe records the digest of the grid its labels were made on; a scene passes when its
rebuilt original observation has that digest. Where the grid shards a recipe came from are at
hand (``--grids``, or the repository's history), the rebuilt grid is also compared voxel by
voxel. Scenes drawn with EGL before ``World`` loaded one object file's copies at their own
scales (PyBullet's EGL renderer caches a mesh by path, not scale; data/README.md) differ from
their digest; verify says so where drawing the scene as the defect did gives the digest.
"""

from __future__ import annotations

import subprocess
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from training.recipe_grids import grid_digest, observation_grid
from training.recipe_shards import RecipeFolder, RecipeShard
from training.shards import ShardError, ShardFolder, quantize

if TYPE_CHECKING:
    from sim_worker.camera import Camera
    from sim_worker.recipes import SceneRecipe

#: Why a rebuilt scene fails its digest when no cause is known.
DIFFERS = "the rebuilt grid differs from the labelled one"


@dataclass
class VerifyReport:
    """What a verification found."""

    checked: int = 0
    matched: int = 0
    compared_with_grid: int = 0
    largest_difference: int = 0
    mismatches: list[tuple[str, str]] = field(default_factory=list)
    #: Mismatches explained by the EGL scale defect: the rebuild is right, the digest is not.
    drawn_at_one_scale: int = 0
    object_problems: list[str] = field(default_factory=list)

    @property
    def match_rate(self) -> float:
        """Share of checked scenes whose rebuilt grid has the recorded digest."""
        return self.matched / self.checked if self.checked else 0.0


def check_object_files(shards: list[RecipeShard], roots: dict[str, Path]) -> list[str]:
    """Problems with the object files the shards name: missing here, or not the file that was used."""
    from sim_worker.recipes import RecipeError, file_hashes, resolve_ref

    seen: dict[str, tuple[str, str]] = {}
    for shard in shards:
        for ref, urdf_sha, mesh_sha in shard.object_files():
            seen.setdefault(ref, (urdf_sha, mesh_sha))
    problems = []
    for ref, expected in sorted(seen.items()):
        try:
            found = file_hashes(resolve_ref(ref, roots))
        except RecipeError as error:
            problems.append(str(error))
            continue
        if found != expected:
            problems.append(f"object {ref}: its files differ from the ones the scenes were made with")
    return problems


def files_at_several_scales(recipe: SceneRecipe) -> dict[str, list[float]]:
    """Each object file the recipe places at more than one scale, with its scales in order."""
    scales: dict[str, list[float]] = {}
    for ref, scale in zip(recipe.objects, recipe.scales, strict=True):
        if float(scale) not in scales.setdefault(ref, []):
            scales[ref].append(float(scale))
    return {ref: found for ref, found in scales.items() if len(found) > 1}


def rebuilt_digest(camera: Camera, recipe: SceneRecipe, roots: dict[str, Path]) -> np.ndarray:
    """The digest of the recipe's original observation, rebuilt in the camera's world."""
    from sim_worker.recipes import rebuild, render_original

    rebuild(camera.world, recipe, roots)
    return grid_digest(quantize(observation_grid(render_original(camera, recipe), recipe.views)))


def drawn_at_one_scale(
    camera: Camera, recipe: SceneRecipe, roots: dict[str, Path], digest: np.ndarray
) -> str | None:
    """Why the recipe's labelled observation differs from its rebuild, when that is EGL's scale
    defect: the scene holds a file at several scales and drawn as the defect drew it (each mesh
    at the scale first loaded, in recipe order as generation loaded them) it has the digest."""
    rescaled = files_at_several_scales(recipe)
    if not rescaled or not camera.world.egl:
        return None
    camera.world.alias_scaled_meshes = False
    try:
        if not np.array_equal(rebuilt_digest(camera, recipe, roots), digest):
            return None
    finally:
        camera.world.alias_scaled_meshes = True
    held = "; ".join(
        f"{ref} at scales {', '.join(f'{s:.4f}' for s in scales)}" for ref, scales in rescaled.items()
    )
    return (f"this scene holds {held}; its stored observation was drawn with every copy at the first scale by "
            "PyBullet's EGL renderer defect (drawn so again it matches): the rebuild is right, the labels stand")  # fmt: skip


def grids_from_history(folder: Path, files: list[str], out: Path | None = None) -> ShardFolder | None:
    """The grid shards a migration replaced, taken from the git history of ``folder`` (the last
    commit that still had them) into ``out`` (default: a temporary folder) with a manifest of
    their own; None outside a repository or when the history lacks them."""
    import json
    import tempfile

    def git(*args: str, where: Path = Path(folder)) -> bytes:
        return subprocess.run(["git", "-C", str(where), *args], capture_output=True, check=True).stdout

    try:
        prefix = git("rev-parse", "--show-prefix").decode().strip()
        top = Path(git("rev-parse", "--show-toplevel").decode().strip())
        out = Path(out) if out is not None else Path(tempfile.mkdtemp(prefix="vgn-grid-shards-"))
        manifest = None
        for name in files:
            path = f"{prefix}{name}"
            removed = (
                git("log", "-1", "--format=%H", "--diff-filter=D", "--", path, where=top).decode().strip()
            )
            revision = f"{removed}^" if removed else "HEAD"
            (out / name).parent.mkdir(parents=True, exist_ok=True)
            (out / name).write_bytes(git("show", f"{revision}:{path}", where=top))
            if manifest is None:
                manifest = json.loads(git("show", f"{revision}:{prefix}manifest.json", where=top))
    except (subprocess.CalledProcessError, FileNotFoundError, ValueError):
        return None
    manifest["shards"] = [s for s in manifest["shards"] if s["file"] in files]
    (out / "manifest.json").write_text(json.dumps(manifest, indent=2) + "\n")
    return ShardFolder(out)


def stored_grids(folder: ShardFolder | None, wanted: set[str]) -> dict[str, np.ndarray]:
    """The quantised grids of the ``wanted`` scenes that ``folder`` holds."""
    grids: dict[str, np.ndarray] = {}
    if folder is None:
        return grids
    for shard in folder.load():
        for scene_id, grid in zip(shard.scene_ids, shard.grids, strict=True):
            if str(scene_id) in wanted:
                grids[str(scene_id)] = grid
    return grids


def verify(
    data: Path,
    scenes: int,
    seed: int = 0,
    vgn_objects: str | None = None,
    grids: Path | None = None,
) -> VerifyReport:
    """Rebuild ``scenes`` random scenes of the folder (all when larger) and compare them."""
    from sim_worker.camera import Camera
    from sim_worker.recipes import RecipeError, object_roots, rebuild, render_original
    from sim_worker.world import World

    folder = RecipeFolder(data)
    manifest = folder.manifest()
    shards = folder.load()
    roots = object_roots(vgn_objects)
    report = VerifyReport(object_problems=check_object_files(shards, roots))
    rows = [(s, r) for s in shards for r in range(len(s.scene_ids))]
    rng = np.random.default_rng(seed)
    picked = [rows[i] for i in sorted(rng.choice(len(rows), size=min(scenes, len(rows)), replace=False))]
    legacy_files = [f for m in manifest.get("migration", {}).values() for f in m.get("grid_shards", [])]
    legacy = ShardFolder(grids) if grids is not None else None
    if legacy is None and legacy_files:
        legacy = grids_from_history(data, legacy_files)
    try:
        originals = stored_grids(legacy, {s.scene_ids[r] for s, r in picked})
    except ShardError:
        originals = {}
    cameras: dict[str, Camera] = {}  # one world per renderer the scenes were drawn with
    try:
        for shard, row in picked:
            recipe = shard.recipe(row)
            report.checked += 1
            if recipe.renderer not in cameras:
                cameras[recipe.renderer] = Camera(World(renderer=recipe.renderer))  # type: ignore[arg-type]
            camera = cameras[recipe.renderer]
            world = camera.world
            try:
                rebuild(world, recipe, roots)
            except RecipeError as error:  # a missing or changed object file
                report.mismatches.append((recipe.scene_id, str(error)))
                continue
            grid = quantize(observation_grid(render_original(camera, recipe), recipe.views))
            matched = bool(np.array_equal(grid_digest(grid), shard.data["grid_digest"][row]))
            report.matched += matched
            if recipe.scene_id in originals:
                report.compared_with_grid += 1
                difference = int(
                    np.abs(grid.astype(np.int16) - originals[recipe.scene_id].astype(np.int16)).max()
                )
                report.largest_difference = max(report.largest_difference, difference)
            if not matched:
                why = drawn_at_one_scale(camera, recipe, roots, shard.data["grid_digest"][row])
                report.drawn_at_one_scale += why is not None
                report.mismatches.append((recipe.scene_id, why or DIFFERS))
    finally:
        for camera in cameras.values():
            camera.world.close()
    return report
