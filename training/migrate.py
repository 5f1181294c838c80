"""Grid shards to recipe shards: recover each scene's recipe from its seed, and prove it.

Scene ``i`` of a generator seed is rebuilt by running the generator again (the same objects,
drops and settling); its recipe (the settled poses, the original views and the noise state) is
recorded, the scene is rebuilt from that recipe alone (poses set, no physics step) and its
original observation rendered and fused. Only a scene whose fused grid equals the stored grid
voxel for voxel is converted: a replay can settle differently from the original run (a pile's
drops are chaotic, and a solver's rounding differs between processors), and a recipe whose
poses differ from the labelled ones would carry wrong labels.

Work is kept per scene in a folder outside the repository (``<work>/<source>/<scene>.npz``), so
an interrupted run resumes where it stopped.
"""

from __future__ import annotations

import json
import multiprocessing
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from training.recipe_grids import grid_digest, observation_grid
from training.shards import ShardFolder, quantize
from vgn_data.files import atomic_writer

#: The renderer the repository's grid shards were made with: recipes are checked against it.
MIGRATION_RENDERER = "egl"


@dataclass(frozen=True)
class MigrationJob:
    """The scenes of one grid-shard source to convert: its generator settings with the object
    folders of this machine, and where results go."""

    source: str
    generation: dict
    objects: tuple[str, ...]
    work: Path
    vgn_objects: str | None = None
    renderer: str = MIGRATION_RENDERER

    def result_path(self, scene_id: str) -> Path:
        """Where one scene's result is kept."""
        return self.work / self.source / f"{scene_id}.npz"


def legacy_scenes(folder: ShardFolder, source: str) -> Iterator[tuple[str, np.ndarray, np.ndarray]]:
    """(scene id, quantised grid, label rows) of every scene of ``source`` in a folder of grid shards."""
    for shard in folder.load():
        if shard.source != source:
            continue
        for scene_id, grid, rows in zip(shard.scene_ids, shard.grids, shard.rows_by_scene(), strict=True):
            yield str(scene_id), grid, rows


_builder = None
_table = None


def _start_worker(job: MigrationJob) -> None:
    global _builder, _table
    from service.launch.lifetime import end_with_parent
    from sim_worker.datagen import DataGenConfig, SceneBuilder
    from sim_worker.recipes import ObjectTable, object_roots

    end_with_parent()
    g = job.generation
    config = DataGenConfig(scene=g["scene"], objects=job.objects, seed=g["seed"],
                           points_per_scene=g["points_per_scene"], yaws=g["yaws"], max_views=g["max_views"],
                           noise=g["noise"], noise_fraction=g["noise_fraction"],
                           side_view_fraction=g["side_view_fraction"], renderer=job.renderer)  # fmt: skip
    _builder = SceneBuilder(config)
    _table = ObjectTable(object_roots(job.vgn_objects))


def convert_scene(job: MigrationJob, scene_id: str, stored: np.ndarray) -> dict:
    """Replay one scene, record its recipe, rebuild from it and compare with ``stored`` (the
    quantised grid); the result (recipe arrays and the comparison) is written to the work folder."""
    from sim_worker.recipes import rebuild, recipe_arrays, render_original

    index = int(scene_id.rsplit("-", 1)[1])
    built = _builder.build(index)
    result: dict = {"scene_id": scene_id}
    if built is None:
        result.update(match=False, reason="the replay came out empty")
    else:
        recipe = _builder.recipe(built, _table)
        rebuild(_builder.world, recipe, _table.roots)
        depths = render_original(_builder.camera, recipe)
        grid = quantize(observation_grid(depths, recipe.views))
        difference = np.abs(grid.astype(np.int16) - stored.astype(np.int16))
        result.update(
            match=bool(difference.max() == 0),
            max_difference=int(difference.max()),
            voxels_differing=int(np.count_nonzero(difference)),
            reason="" if difference.max() == 0 else "the replay settled differently",
        )
        arrays = recipe_arrays(recipe, _table)
        arrays["grid_digest"] = grid_digest(stored)
    path = job.result_path(scene_id)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_writer(path) as stream:
        np.savez(stream, result=np.asarray(json.dumps(result)), **(arrays if built is not None else {}))
    return result


def _convert_chunk(job: MigrationJob, chunk: list[tuple[str, np.ndarray]]) -> list[dict]:
    return [convert_scene(job, scene_id, grid) for scene_id, grid in chunk]


def run_migration(
    folder: ShardFolder,
    job: MigrationJob,
    workers: int = 1,
    limit: int | None = None,
    progress: Callable[[dict], object] | None = None,
) -> list[dict]:
    """Convert the scenes of ``job.source`` not converted yet (at most ``limit``) in ``workers``
    processes; returns the new results."""
    todo = [
        (sid, grid) for sid, grid, _ in legacy_scenes(folder, job.source) if not job.result_path(sid).exists()
    ]
    todo = todo[:limit] if limit is not None else todo
    chunks = [todo[start : start + 8] for start in range(0, len(todo), 8)]
    results = []
    context = multiprocessing.get_context("spawn")  # PyBullet and fork do not mix
    with ProcessPoolExecutor(workers, mp_context=context, initializer=_start_worker, initargs=(job,)) as pool:
        for chunk_results in pool.map(_convert_chunk, [job] * len(chunks), chunks):
            for result in chunk_results:
                results.append(result)
                if progress:
                    progress(result)
    return results


def read_result(path: Path) -> tuple[dict, dict[str, np.ndarray]]:
    """A scene's result and its recipe arrays (empty when the replay came out empty)."""
    with np.load(path) as data:
        result = json.loads(str(data["result"]))
        arrays = {name: data[name] for name in data.files if name != "result"}
    return result, arrays
