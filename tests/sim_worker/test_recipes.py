"""Scene recipes: recorded from a generated scene, rebuilt without physics, rendered bit for bit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sim_worker.datagen import DataGenConfig, SceneBuilder
from sim_worker.recipes import (
    ObjectTable,
    RecipeError,
    file_hashes,
    object_ref,
    object_roots,
    rebuild,
    recipe_arrays,
    recipe_from_arrays,
    render_original,
    resolve_ref,
    rng_from_state,
    rng_state,
)


def test_a_recorded_generator_state_draws_the_same_numbers():
    rng = np.random.default_rng([3, 4])
    rng.normal(size=5)
    rng.random(dtype=np.float32)  # leaves a buffered 32-bit half behind
    state = rng_state(rng)
    expected = [rng.gamma(1000.0, 1e-3), *rng.standard_normal(4), rng.integers(1 << 30)]
    again = rng_from_state(state)
    assert [again.gamma(1000.0, 1e-3), *again.standard_normal(4), again.integers(1 << 30)] == expected


@pytest.mark.parametrize("objects, noise", [("blocks", 1.0), ("pybullet", 0.0)])
def test_a_rebuilt_scene_renders_its_original_observation_bit_for_bit(objects, noise):
    config = DataGenConfig(scene="pile", objects=(objects,), seed=11, noise_fraction=noise, renderer="tiny")
    builder = SceneBuilder(config)
    try:
        built = builder.build(0)
        assert built is not None and built.noisy == (noise == 1.0)
        table = ObjectTable(object_roots())
        recipe = builder.recipe(built, table)
        original = builder.render(built)
        # Round trip through the stored form, then rebuild with no physics step in a reset world.
        stored, files = recipe_from_arrays(recipe.scene_id, recipe_arrays(recipe, table))
        assert {f.ref for f in files} == set(recipe.objects) and stored.renderer == "tiny"
        bodies = rebuild(builder.world, stored, table.roots)
        assert len(bodies) == len(recipe.objects) >= 1
        np.testing.assert_array_equal(render_original(builder.camera, stored), original)
        # The rebuilt poses are the recorded ones.
        for body, pose in zip(bodies, stored.poses, strict=True):
            position, orientation = builder.world.object_pose(body)
            np.testing.assert_allclose(np.r_[position, orientation], pose, atol=1e-9)
    finally:
        builder.close()


def test_a_moved_object_changes_the_observation():
    config = DataGenConfig(scene="packed", objects=("blocks",), seed=2, renderer="tiny")
    builder = SceneBuilder(config)
    try:
        built = builder.build(1)
        table = ObjectTable(object_roots())
        recipe = builder.recipe(built, table)
        original = builder.render(built)
        recipe.poses[0, 0] += 0.01
        rebuild(builder.world, recipe, table.roots)
        assert not np.array_equal(render_original(builder.camera, recipe), original)
    finally:
        builder.close()


def test_references_name_objects_by_root_not_by_machine_path(tmp_path: Path):
    roots = {**object_roots(), "vgn": tmp_path / "sets"}
    folder = roots["vgn"] / "pile" / "train"
    folder.mkdir(parents=True)
    (folder / "thing.urdf").write_text(
        '<robot><link><visual><geometry><mesh filename="thing.obj"/></geometry></visual></link></robot>'
    )
    (folder / "thing.obj").write_text("v 0 0 0\n")
    split = tmp_path / "split"
    split.mkdir()
    (split / "thing.urdf").symlink_to(folder / "thing.urdf")  # a split folder of links names the original
    assert object_ref(split / "thing.urdf", roots) == "vgn:pile/train/thing.urdf"
    assert resolve_ref("vgn:pile/train/thing.urdf", roots) == folder / "thing.urdf"
    elsewhere = tmp_path / "mine.urdf"
    elsewhere.write_text("<robot/>")
    assert object_ref(elsewhere, roots) == f"file:{elsewhere.resolve()}"
    urdf_sha, mesh_sha = file_hashes(folder / "thing.urdf")
    (folder / "thing.obj").write_text("v 0 0 1\n")
    changed_urdf, changed_mesh = file_hashes(folder / "thing.urdf")
    assert changed_urdf == urdf_sha and changed_mesh != mesh_sha  # a changed mesh shows in its own hash


def test_an_unknown_root_or_missing_file_is_a_clear_error(tmp_path: Path):
    roots = {"builtin": tmp_path}
    with pytest.raises(RecipeError, match="set VGN_OBJECTS"):
        resolve_ref("vgn:pile/train/x.urdf", roots)
    with pytest.raises(RecipeError, match="does not exist"):
        resolve_ref(f"file:{tmp_path / 'gone.urdf'}", roots)
