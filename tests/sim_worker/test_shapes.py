"""The generated shapes: the same files from the same index on every write, sized for the hand,
plausibly heavy, and a real pile of them settles on the table and is rebuilt from its recipe."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pybullet", reason="the sim extra is not installed")

from sim_worker.objects import MAX_GRASP_EXTENT, object_set  # noqa: E402
from sim_worker.recipes import SceneRecipe, object_ref, rebuild, resolve_ref  # noqa: E402
from sim_worker.scenes import generate_scene  # noqa: E402
from sim_worker.shapes import DENSITY_RANGE, EXTENT_RANGE, FAMILIES, shape_parts, shapes_set  # noqa: E402
from sim_worker.world import TABLE_Z, World  # noqa: E402

COUNT = 40  # ten of each family


def _mass(urdf: Path) -> float:
    return float(re.search(r'<mass value="([^"]+)"', urdf.read_text()).group(1))


def test_the_same_index_gives_the_same_files(tmp_path: Path) -> None:
    first = shapes_set(tmp_path / "a", COUNT).urdfs
    second = shapes_set(tmp_path / "b", COUNT).urdfs
    for a, b in zip(first, second, strict=True):
        assert a.read_bytes() == b.read_bytes()
        for mesh in re.findall(r'filename="([^"]+)"', a.read_text()):
            assert (a.parent / mesh).read_bytes() == (b.parent / mesh).read_bytes()


def test_every_family_is_made_and_every_part_is_a_closed_convex_mesh() -> None:
    families = set()
    for index in range(COUNT):
        family, parts = shape_parts(index)
        families.add(family)
        for part in parts:
            a, b, c = (part.vertices[part.faces[:, k]] for k in range(3))
            normals = np.cross(b - a, c - a)
            centre = part.vertices.mean(axis=0)
            # Outward, and every vertex behind every face's plane: convex.
            assert np.all(np.einsum("ij,ij->i", normals, a - centre) > 0)
            heights = part.vertices[None] - a[:, None]
            assert np.all(np.einsum("fvk,fk->fv", heights, normals) <= 1e-9)
    assert families == set(FAMILIES)


def test_shapes_fit_the_hand_and_weigh_what_their_size_says(tmp_path: Path) -> None:
    urdfs = shapes_set(tmp_path, COUNT).urdfs
    for index, urdf in enumerate(urdfs):
        family, parts = shape_parts(index)
        vertices = np.vstack([p.vertices for p in parts])
        extents = vertices.max(axis=0) - vertices.min(axis=0)
        assert extents.min() <= MAX_GRASP_EXTENT, (urdf.name, extents)
        assert extents.max() <= EXTENT_RANGE[1] * 1.2, (urdf.name, extents)
        assert extents.min() >= 0.012 - 1e-9, (urdf.name, extents)
        # No heavier than the densest plausible material filling the bounding box.
        assert 0 < _mass(urdf) <= DENSITY_RANGE[1] * float(np.prod(extents)), urdf.name


def test_a_pile_of_shapes_settles_and_is_rebuilt_from_its_recipe(tmp_path: Path) -> None:
    objects = shapes_set(tmp_path / "shapes", COUNT)
    roots = {"shapes": tmp_path / "shapes"}
    world = World(renderer="tiny")
    try:
        bodies = generate_scene(world, "pile", objects, 5, np.random.default_rng(3))
        assert bodies, "some shapes stay in the workspace"
        placed = [world.objects[b] for b in bodies]
        poses = []
        for body in bodies:
            position, orientation = world.p.getBasePositionAndOrientation(body)
            assert position[2] > TABLE_Z - 0.01, "a shape fell through the table"
            poses.append([*position, *orientation])
        refs = [object_ref(o.urdf, roots) for o in placed]
        assert all(ref.startswith("shapes:shape_") for ref in refs)
        recipe = SceneRecipe(
            "s0-0000000", refs, np.array([o.scale for o in placed]), np.array(poses), np.zeros((0, 7))
        )
        # A machine that never wrote the set writes it again when a recipe names a shape.
        rebuilt_roots = {"shapes": tmp_path / "elsewhere"}
        assert resolve_ref(refs[0], rebuilt_roots).read_bytes() == placed[0].urdf.read_bytes()
        rebuilt = rebuild(world, recipe, rebuilt_roots)
        for body, pose in zip(rebuilt, poses, strict=True):
            position, _ = world.p.getBasePositionAndOrientation(body)
            assert np.allclose(position, pose[:3], atol=1e-9)
    finally:
        world.close()


def test_the_set_is_named_shapes_on_the_command_line() -> None:
    assert object_set("shapes", "pile").name == "shapes"
