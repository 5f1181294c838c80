"""``vgn-data verify`` names PyBullet's EGL scale defect as the cause of a mismatch it explains:
a scene holding one file at two scales whose stored digest was taken of a render that drew both
copies at the first scale."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pybullet")

from sim_worker.camera import Camera  # noqa: E402
from sim_worker.recipes import SceneRecipe, object_roots, pose_vector  # noqa: E402
from sim_worker.world import TABLE_Z, World  # noqa: E402
from tests.sim_worker.test_world_scales import write_cube  # noqa: E402
from training.verify_recipes import drawn_at_one_scale, files_at_several_scales, rebuilt_digest  # noqa: E402
from vgn_contract.geometry import look_at  # noqa: E402

SCALES = (0.8, 1.6)


def _two_cubes(urdf: Path) -> SceneRecipe:
    """Two copies of one cube at two scales standing on the table, seen from above."""
    ref = f"file:{urdf}"
    poses = [
        [x, 0.15, TABLE_Z + 0.02 * s, 0.0, 0.0, 0.0, 1.0] for x, s in zip((0.08, 0.22), SCALES, strict=True)
    ]
    view = pose_vector(look_at((0.15, 0.15, 0.6), (0.15, 0.15, 0.0), up=(0.0, 1.0, 0.0)))
    return SceneRecipe("s0-0000000", [ref, ref], np.asarray(SCALES), np.asarray(poses), view[None])


def test_files_at_several_scales_lists_only_those() -> None:
    recipe = SceneRecipe("s0-0000000", ["a", "b", "a", "b"], np.array([1.0, 2.0, 1.5, 2.0]), np.zeros((4, 7)),
                         np.zeros((1, 7)))  # fmt: skip
    assert files_at_several_scales(recipe) == {"a": [1.0, 1.5]}


def test_a_digest_drawn_with_the_defect_is_explained_and_the_right_one_is_not(tmp_path: Path) -> None:
    recipe = _two_cubes(write_cube(tmp_path))
    try:
        world = World(renderer="egl")
    except RuntimeError as error:
        pytest.skip(f"PyBullet's EGL renderer cannot load here ({error}); the defect is EGL's alone")
    with world:
        camera, roots = Camera(world), object_roots()
        world.alias_scaled_meshes = False
        as_drawn_before = rebuilt_digest(camera, recipe, roots)
        world.alias_scaled_meshes = True
        right = rebuilt_digest(camera, recipe, roots)
        assert not np.array_equal(as_drawn_before, right)
        why = drawn_at_one_scale(camera, recipe, roots, as_drawn_before)
        assert why is not None and f"{recipe.objects[0]} at scales 0.8000, 1.6000" in why
        assert "EGL renderer defect" in why and "the rebuild is right" in why
        assert world.alias_scaled_meshes  # the world draws right again
        assert drawn_at_one_scale(camera, recipe, roots, right) is None  # not the defect: no explanation
