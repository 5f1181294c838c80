"""Observations of recipe scenes for training: K rendered grids per scene, cached outside the
repository.

A recipe holds a scene, not a view of it, so training can see each scene through fresh views and
fresh sensor noise. Rendering and fusing a view takes tens of milliseconds, far more than a
training step can wait for on a small machine, so ``vgn-data render`` renders K observations per
scene once (in worker processes), and training draws one of the K at every draw of the scene.
Slot 0 can hold the scene's original observation (the grid its labels were made on).

A cache file per shard, ``<cache>/<shard sha256[:16]>-<settings key>.npy``: (S, K, N, N, N)
uint8, ``round(255 * grid)``, memory-mapped when read. Every observation is fixed by (scene id,
slot, settings), so a cache rebuilt anywhere holds the same grids.
"""

from __future__ import annotations

import hashlib
import json
import multiprocessing
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from training.grids import RESOLUTION
from training.options import NOT_AN_OPTION, option
from training.recipe_grids import observation_grid
from training.recipe_shards import RecipeFolder
from training.shards import quantize
from vgn_data.files import atomic_writer

#: Bump when rendering or fusing changes, so old caches stop matching.
#: 2: objects drawn at their own scale under EGL (caches of format 1 drew some at another's).
OBSERVATION_FORMAT = 2
#: Depth-sensor models a fresh observation may carry (docs/sensors.md).
SENSORS = ("dex", "structured-light")
#: Single side views look from this far off vertical (degrees), as data generation's.
SIDE_VIEW_TILT_DEG = (45.0, 65.0)
#: How fresh observations place their cameras: data generation's random views, or VGN's six
#: evaluation views on a circle (the benchmark's; a teacher's privileged view of a scene).
VIEWS = ("random", "six")


@dataclass(frozen=True)
class ObservationSettings:
    """How a scene's training observations are drawn.

    ``per_scene`` observations per scene; with ``original`` the first is the scene's original
    observation. The others take 1..``max_views`` views from above as data generation does
    (distance U(0.48, 0.72) m, tilt U(0°, 45°)), or with probability ``side_view_fraction`` one
    side view (tilt U(45°, 65°)); with probability ``noise_fraction`` the depth carries the
    errors of ``sensor``: ``"dex"`` (Dex-Net noise, ``sim_worker.camera.DepthNoise``) or
    ``"structured-light"`` (``sim_worker.sensors.StructuredLightNoise``; docs/sensors.md).
    ``views="six"`` takes VGN's six evaluation views instead of random ones (no side views).
    Each field's metadata is also its option (``training.options``), in ``vgn-train`` and, named
    after the field, in ``vgn-data render``; ``max_views`` and ``seed`` have none.
    """

    per_scene: int = field(
        default=1,
        metadata=option(
            "observations",
            "observations rendered per scene; with K > 1 every draw of a scene in training shows one of "
            "them at random (default %(default)s: the original observation only)",
            flag="--observations",
            metavar="K",
        ),
    )
    original: bool = field(
        default=True,
        metadata=option(
            "observations", "every observation fresh (default: the first is the scene's original one)"
        ),
    )
    max_views: int = field(default=6, metadata=NOT_AN_OPTION)
    side_view_fraction: float = field(
        default=0.2,
        metadata=option(
            "observations",
            "share of fresh observations that are one side view (default %(default)s)",
            flag="--observation-side-views",
            metavar="F",
        ),
    )
    noise_fraction: float = field(
        default=0.5,
        metadata=option(
            "observations",
            "share of fresh observations whose depth carries the sensor's errors (default %(default)s)",
            flag="--observation-noise",
            metavar="F",
        ),
    )
    sensor: str = field(
        default="dex",
        metadata=option(
            "observations",
            "the depth errors of noisy fresh observations: Dex-Net noise or a structured-light camera's "
            "(docs/sensors.md; default %(default)s)",
            flag="--observation-sensor",
            choices=SENSORS,
        ),
    )
    seed: int = field(default=0, metadata=NOT_AN_OPTION)
    views: str = field(
        default="random",
        metadata=option(
            "observations",
            "where fresh observations' cameras stand: data generation's random views or VGN's six "
            "evaluation views, the benchmark's; six takes no side views (default %(default)s)",
            flag="--observation-views",
            choices=VIEWS,
        ),
    )

    def __post_init__(self) -> None:
        if self.per_scene < 1 or self.max_views < 1:
            raise ValueError("per_scene and max_views must be >= 1")
        if self.sensor not in SENSORS:
            raise ValueError(f"sensor must be one of {SENSORS}, got {self.sensor!r}")
        if self.views not in VIEWS:
            raise ValueError(f"views must be one of {VIEWS}, got {self.views!r}")
        for name in ("side_view_fraction", "noise_fraction"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} must be in [0, 1], got {getattr(self, name)}")

    def key(self) -> str:
        """Short hash of everything an observation depends on besides the scene."""
        fields = asdict(self)
        if fields["views"] == "random":
            del fields["views"]  # so caches rendered before the choice existed keep their key
        else:  # six fixed views: the random views' knobs change nothing, so they name no other cache
            del fields["max_views"], fields["side_view_fraction"]
        text = json.dumps({**fields, "format": OBSERVATION_FORMAT, "resolution": RESOLUTION}, sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:12]

    def rng(self, scene_id: str, slot: int) -> np.random.Generator:
        """The generator of one observation: fixed by the scene, the slot and the seed."""
        scene = int.from_bytes(hashlib.sha256(scene_id.encode()).digest()[:8], "big")
        return np.random.default_rng([self.seed, scene, slot])


def draw_cameras(settings: ObservationSettings, rng: np.random.Generator) -> tuple[list[np.ndarray], bool]:
    """Camera poses (camera → world) of one fresh observation, and whether it is noisy."""
    from sim_worker.camera import random_views, six_views

    noisy = bool(rng.random() < settings.noise_fraction)
    if settings.views == "six":
        return six_views(), noisy
    if rng.random() < settings.side_view_fraction:
        return random_views(rng, 1, tilt_deg=SIDE_VIEW_TILT_DEG), noisy
    return random_views(rng, int(rng.integers(1, settings.max_views + 1))), noisy


class ObservationRenderer:
    """Simulator worlds that render the observations of recipes (one set per worker process),
    each recipe with the renderer its original observation was drawn with."""

    def __init__(self, settings: ObservationSettings, vgn_objects: str | None = None) -> None:
        from sim_worker.recipes import object_roots

        self.settings = settings
        self.roots = object_roots(vgn_objects)
        self.cameras: dict[str, Any] = {}

    def _camera(self, renderer: str) -> Any:
        from sim_worker.camera import Camera
        from sim_worker.world import World

        if renderer not in self.cameras:
            self.cameras[renderer] = Camera(World(renderer=renderer))  # type: ignore[arg-type]
        return self.cameras[renderer]

    def noise(self) -> Any:
        """The depth model of a noisy fresh observation."""
        from sim_worker.camera import SIM_INTRINSICS, DepthNoise
        from sim_worker.sensors import StructuredLightNoise

        return (
            StructuredLightNoise(SIM_INTRINSICS)
            if self.settings.sensor == "structured-light"
            else DepthNoise()
        )

    def observations(self, recipe: Any) -> np.ndarray:
        """(K, N, N, N) uint8 observations of one recipe (a ``SceneRecipe``)."""
        from sim_worker.recipes import pose_vector, rebuild, render_original, render_views

        camera = self._camera(recipe.renderer)
        rebuild(camera.world, recipe, self.roots)
        grids = []
        for slot in range(self.settings.per_scene):
            if slot == 0 and self.settings.original:
                depths, views = render_original(camera, recipe), recipe.views
            else:
                rng = self.settings.rng(recipe.scene_id, slot)
                poses, noisy = draw_cameras(self.settings, rng)
                depths = render_views(camera, poses, self.noise() if noisy else None, rng)
                views = np.stack([pose_vector(c) for c in poses])
            grids.append(quantize(observation_grid(depths, views)))
        return np.stack(grids)

    def close(self) -> None:
        """Close the simulators."""
        for camera in self.cameras.values():
            camera.world.close()


def cache_path(cache: Path, shard_sha256: str, settings: ObservationSettings) -> Path:
    """The cache file of one shard under ``settings``."""
    return Path(cache) / f"{shard_sha256[:16]}-{settings.key()}.npy"


_renderer: ObservationRenderer | None = None


def _start_worker(settings: ObservationSettings, vgn_objects: str | None) -> None:
    global _renderer
    from service.launch.lifetime import end_with_parent

    end_with_parent()
    _renderer = ObservationRenderer(settings, vgn_objects)


def _render_recipes(recipes: list[object]) -> list[np.ndarray]:
    return [_renderer.observations(recipe) for recipe in recipes]


def render_cache(
    data: Path,
    cache: Path,
    settings: ObservationSettings,
    workers: int = 1,
    vgn_objects: str | None = None,
    progress: Callable[[int], object] | None = None,
    shards: list[Any] | None = None,
) -> list[Path]:
    """Render the observations of every shard of ``data`` whose cache file is missing; returns
    every shard's cache file. A file is written whole (atomically) once its shard is done.
    ``shards``: the folder's shards (or some of them), when the caller has loaded them already."""
    folder = RecipeFolder(data)
    entries = {entry["file"]: entry for entry in folder.manifest()["shards"]}
    shards = folder.load() if shards is None else shards
    paths = []
    context = multiprocessing.get_context("spawn")  # PyBullet and fork do not mix
    with ProcessPoolExecutor(workers, mp_context=context, initializer=_start_worker,
                             initargs=(settings, vgn_objects)) as pool:  # fmt: skip
        for shard in shards:
            path = cache_path(cache, entries[shard.file]["sha256"], settings)
            paths.append(path)
            if path.is_file():
                continue
            recipes = [shard.recipe(row) for row in range(len(shard.scene_ids))]
            chunks = [recipes[start : start + 16] for start in range(0, len(recipes), 16)]
            grids = []
            for chunk in pool.map(_render_recipes, chunks):
                grids += chunk
                if progress:
                    progress(len(chunk))
            path.parent.mkdir(parents=True, exist_ok=True)
            with atomic_writer(path) as stream:
                np.save(stream, np.stack(grids))
    return paths


def open_cache(path: Path, scenes: int, settings: ObservationSettings) -> np.ndarray:
    """A shard's cached observations, memory-mapped; ``ValueError`` when the file does not fit."""
    grids = np.load(path, mmap_mode="r")
    n = RESOLUTION
    if grids.shape != (scenes, settings.per_scene, n, n, n) or grids.dtype != np.uint8:
        raise ValueError(
            f"{path} holds {grids.shape} {grids.dtype}, not ({scenes}, {settings.per_scene}, {n}, {n}, {n}) uint8"
        )
    return grids
