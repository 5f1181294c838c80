"""Object sets (sim_worker/objects.py) and scene generators (sim_worker/scenes.py)."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pybullet")

from sim_worker.objects import (  # noqa: E402
    BLOCKS,
    BLOCKS_SCALE,
    MAX_EXTENT,
    MAX_GRASP_EXTENT,
    MIN_EXTENT,
    ObjectSet,
    blocks_set,
    object_set,
    pybullet_data_set,
    urdf_folder_set,
    write_blocks,
)
from sim_worker.scenes import generate_scene, poisson_object_count  # noqa: E402
from sim_worker.world import TABLE_Z, WORKSPACE_SIZE, World  # noqa: E402

COUNT = 5


@pytest.fixture(scope="module")
def cache_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One cache for the module, so the pybullet_data set is vetted once (~3 s)."""
    return tmp_path_factory.mktemp("vgn-cache")


@pytest.fixture(autouse=True)
def _isolated_cache(cache_dir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("VGN_CACHE_DIR", str(cache_dir))


@pytest.fixture(scope="module")
def blocks(cache_dir: Path) -> ObjectSet:
    return blocks_set(cache_dir / "blocks")


@pytest.fixture(scope="module")
def pybullet_objects(cache_dir: Path) -> ObjectSet:
    return pybullet_data_set(cache_dir)


@pytest.fixture
def world():
    with World(renderer="tiny") as world:
        yield world


def _sets(blocks: ObjectSet, pybullet_objects: ObjectSet) -> dict[str, ObjectSet]:
    return {"blocks": blocks, "pybullet": pybullet_objects}


def _snapshot(world: World, bodies: list[int]) -> list[tuple[str, np.ndarray]]:
    """(URDF name, [x, y, z, qx, qy, qz, qw]) of each body, in order."""
    return [(world.objects[b].urdf.name, np.concatenate(world.object_pose(b))) for b in bodies]


def _build(kind: str, objects: ObjectSet, seed: int) -> list[tuple[str, np.ndarray]]:
    with World(renderer="tiny") as world:
        return _snapshot(world, generate_scene(world, kind, objects, COUNT, np.random.default_rng(seed)))


# Object sets -----------------------------------------------------------------------------------
def test_blocks_regenerate_into_an_empty_cache_and_load(tmp_path: Path, world: World) -> None:
    directory = tmp_path / "blocks"
    objects = blocks_set(directory)
    assert objects.scale_factor == BLOCKS_SCALE
    assert len(objects) >= 5
    assert all(urdf.is_file() and urdf.parent == directory for urdf in objects.urdfs)
    for urdf in objects.urdfs:
        body = world.add_object(urdf, (0.15, 0.15, 0.2))
        lower, upper = world.aabb(body)
        extents = (upper - lower) * BLOCKS_SCALE  # the largest scene scale (U(0.8, 1.0) × 1.67)
        assert extents.min() < MAX_GRASP_EXTENT, urdf.name  # graspable across some dimension
        assert extents.max() < 0.12, urdf.name
        assert world.p.getDynamicsInfo(body, -1)[0] > 0.0
        world.remove_object(body)

    # Reused when present, regenerated when missing or altered.
    mtimes = {path: path.stat().st_mtime_ns for path in directory.iterdir()}
    assert blocks_set(directory).urdfs == objects.urdfs
    assert {path: path.stat().st_mtime_ns for path in directory.iterdir()} == mtimes
    objects.urdfs[0].unlink()
    mesh = next(directory.glob("*.obj"))
    mesh.write_text("garbage")
    blocks_set(directory)
    assert objects.urdfs[0].is_file() and mesh.read_text().startswith("# generated")
    assert not list(directory.glob("*.tmp"))


def test_pybullet_set_is_nonempty_and_every_urdf_loads(pybullet_objects: ObjectSet, world: World) -> None:
    assert len(pybullet_objects) > 50
    assert pybullet_objects.scale_factor == 1.0
    for index, urdf in enumerate(pybullet_objects.urdfs):
        scale = pybullet_objects.base_scale(index)
        assert 0.0 < scale <= 1.0
        body = world.add_object(urdf, (0.15, 0.15, 0.5), scale=scale)
        lower, upper = world.aabb(body)
        extents = upper - lower
        assert min(extents[0], extents[1]) <= MAX_GRASP_EXTENT + 1e-3, urdf
        assert extents.min() >= MIN_EXTENT - 1e-3 and extents.max() <= MAX_EXTENT + 1e-3, urdf
        world.remove_object(body)


def test_pybullet_set_is_cached(pybullet_objects: ObjectSet, cache_dir: Path) -> None:
    assert (cache_dir / "pybullet_data_set.json").is_file()
    again = pybullet_data_set(cache_dir)
    assert again.urdfs == pybullet_objects.urdfs and again.object_scales == pybullet_objects.object_scales


def test_urdf_folder_set_errors_clearly(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="no .urdf files"):
        urdf_folder_set(tmp_path)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        urdf_folder_set(tmp_path / "missing")


def test_urdf_folder_set_and_object_set_names(blocks: ObjectSet, tmp_path: Path) -> None:
    folder = urdf_folder_set(blocks.urdfs[0].parent)
    assert folder.urdfs == sorted(blocks.urdfs) and folder.scale_factor == 1.0

    assert object_set(None, "blocks").name == "blocks"
    assert object_set(None, "pile").name == "pybullet"
    assert object_set("", "packed").name == "pybullet"
    assert object_set("blocks", "pile").scale_factor == BLOCKS_SCALE
    # A folder named "blocks" gets VGN's block scale; any other folder 1.0.
    assert object_set(str(blocks.urdfs[0].parent), "pile").scale_factor == BLOCKS_SCALE
    other = tmp_path / "mine"
    other.mkdir()
    (other / "cube.urdf").write_text(blocks.urdfs[0].read_text())
    assert object_set(str(other), "pile").urdfs == [other / "cube.urdf"]
    with pytest.raises(ValueError, match="neither"):
        object_set(str(tmp_path / "nope"), "pile")
    with pytest.raises(ValueError, match="unknown scene"):
        object_set("blocks", "tower")


def test_a_folder_in_vgns_blocks_layout(world: World, tmp_path: Path) -> None:
    """A folder named ``blocks`` holding one URDF per block (meshes beside them), as VGN's
    is laid out: it gets VGN's block scale and builds a full blocks scene."""
    folder = tmp_path / "blocks"
    write_blocks(folder)
    objects = object_set(str(folder), "blocks")
    assert len(objects) == len(BLOCKS) and objects.scale_factor == BLOCKS_SCALE
    bodies = generate_scene(world, "blocks", objects, COUNT, np.random.default_rng(0))
    assert len(bodies) >= COUNT - 1


# Scenes ----------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("kind", "set_name", "minimum"),
    [
        ("blocks", "blocks", COUNT),
        ("pile", "pybullet", COUNT - 1),
        ("packed", "blocks", COUNT - 1),
        ("packed", "pybullet", COUNT - 1),
    ],
)
def test_scene_has_the_objects_inside_the_workspace(
    kind: str, set_name: str, minimum: int, blocks: ObjectSet, pybullet_objects: ObjectSet, world: World
) -> None:
    objects = _sets(blocks, pybullet_objects)[set_name]
    for seed in (0, 1):
        for body in list(world.objects):
            world.remove_object(body)
        bodies = generate_scene(world, kind, objects, COUNT, np.random.default_rng(seed))
        assert minimum <= len(bodies) <= COUNT
        assert sorted(bodies) == sorted(world.objects)
        for body in bodies:
            position, _ = world.object_pose(body)
            assert np.all(position >= 0.0) and np.all(position <= WORKSPACE_SIZE), position
            assert position[2] > TABLE_Z, position
        # Only the objects and the table remain: the pile's box is gone.
        assert world.p.getNumBodies() == len(bodies) + 1


@pytest.mark.parametrize(("kind", "set_name"), [("pile", "blocks"), ("packed", "pybullet")])
def test_same_seed_same_scene_different_seed_different(
    kind: str, set_name: str, blocks: ObjectSet, pybullet_objects: ObjectSet
) -> None:
    objects = _sets(blocks, pybullet_objects)[set_name]
    first, second, other = _build(kind, objects, 7), _build(kind, objects, 7), _build(kind, objects, 8)
    assert [name for name, _ in first] == [name for name, _ in second]
    for (_, a), (_, b) in zip(first, second, strict=True):
        np.testing.assert_allclose(a, b, atol=1e-6)
    different_objects = [name for name, _ in first] != [name for name, _ in other]
    assert different_objects or any(
        not np.allclose(a, b, atol=1e-3) for (_, a), (_, b) in zip(first, other, strict=False)
    )


def test_packed_objects_stand_upright_and_do_not_overlap(blocks: ObjectSet, world: World) -> None:
    for seed in range(3):
        for body in list(world.objects):
            world.remove_object(body)
        bodies = generate_scene(world, "packed", blocks, COUNT, np.random.default_rng(seed))
        for body in bodies:
            _, orientation = world.object_pose(body)
            z_axis = np.reshape(world.p.getMatrixFromQuaternion(orientation.tolist()), (3, 3))[:, 2]
            assert np.degrees(np.arccos(np.clip(z_axis[2], -1.0, 1.0))) < 10.0
        for a, b in itertools.combinations(bodies, 2):
            points = world.p.getClosestPoints(bodyA=a, bodyB=b, distance=0.0)
            assert all(point[8] > -2e-3 for point in points)  # touching at most, no overlap


def test_unknown_scene_kind(blocks: ObjectSet, world: World) -> None:
    with pytest.raises(ValueError, match="unknown scene kind"):
        generate_scene(world, "tower", blocks, COUNT, np.random.default_rng(0))


def test_poisson_object_count() -> None:
    rng = np.random.default_rng(0)
    counts = np.array([poisson_object_count(rng) for _ in range(4000)])
    assert counts.min() >= 1
    assert abs(counts.mean() - 5.0) < 0.15


def test_env_cache_dir_is_used(cache_dir: Path) -> None:
    assert blocks_set().urdfs[0].parent == cache_dir / "blocks"
