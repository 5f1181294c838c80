"""Training data as scene recipes: generated through a real service, packed, verified, migrated
from grid shards, rendered into observations and trained on."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from training.dataset import RenderedObservations, SceneDataset, load_scenes
from training.observations import ObservationSettings, render_cache
from training.recipe_shards import RecipeFolder, shard_arrays
from training.shards import ShardFolder, sha256_of
from vgn_data.dataset import RawDataset


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, timeout=600)


def generate(url: str, out: Path, scenes: int, seed: int = 3) -> None:
    done = run("-m", "client.cli", "generate-data", "--sim", "--url", url, "--scene", "pile", "--objects", "blocks",
               "--scenes", str(scenes), "--points", "6", "--seed", str(seed), "--noise-fraction", "0.5",
               "--renderer", "tiny", "--out", str(out))  # fmt: skip
    assert done.returncode == 0, done.stderr


def vgn_data(*args: str) -> subprocess.CompletedProcess:
    return run("-m", "training.data_cli", *args)


@pytest.fixture(scope="module")
def raw(server, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("raw") / "pile"
    generate(server.url, out, scenes=3)
    return out


def test_generation_writes_a_recipe_per_scene_and_packing_verifies(raw: Path, tmp_path: Path):
    dataset = RawDataset(raw)
    assert sorted(p.stem for p in dataset.recipes_dir.glob("*.npz")) == dataset.scene_ids()
    data = tmp_path / "data"
    packed = vgn_data("pack", str(raw), "--source", "pile", "--out", str(data))
    assert packed.returncode == 0, packed.stderr
    manifest = RecipeFolder(data).manifest()
    assert (
        manifest["format"] == 2
        and manifest["gripper"]
        and manifest["sources"]["pile"]["objects"] == ["builtin:"]
    )
    (entry,) = manifest["shards"]
    assert entry["scenes"] == len(dataset.scene_ids()) and entry["sha256"] == sha256_of(data / entry["file"])
    verified = vgn_data("verify", str(data), "--scenes", "10")
    assert verified.returncode == 0, verified.stdout + verified.stderr
    assert f"verified {entry['scenes']} scenes" in verified.stdout and "(100.0 %)" in verified.stdout
    # Nothing new: no shard is written, none rewritten.
    assert vgn_data("pack", str(raw), "--source", "pile", "--out", str(data)).returncode == 0
    assert RecipeFolder(data).manifest()["shards"] == [entry]


def test_objects_recorded_by_path_are_packed_by_their_root(raw: Path, tmp_path: Path):
    """Scenes generated without VGN_OBJECTS set name their objects by absolute path; packing names
    each by the root it lies under, so the shards rebuild on any machine."""
    from sim_worker.recipes import object_roots, resolve_ref

    by_path = tmp_path / "raw"
    shutil.copytree(raw, by_path)
    roots = object_roots()
    for recipe in RawDataset(by_path).recipes_dir.glob("*.npz"):
        with np.load(recipe) as stored:
            arrays = {name: stored[name] for name in stored.files}
        arrays["objects"] = np.array(
            [f"file:{resolve_ref(str(ref), roots).resolve()}" for ref in arrays["objects"]]
        )
        np.savez(recipe, **arrays)
    data = tmp_path / "data"
    assert vgn_data("pack", str(by_path), "--source", "pile", "--out", str(data)).returncode == 0
    assert RecipeFolder(data).manifest()["sources"]["pile"]["objects"] == ["builtin:"]
    verified = vgn_data("verify", str(data), "--scenes", "10")
    assert verified.returncode == 0 and "(100.0 %)" in verified.stdout, verified.stdout + verified.stderr


def test_new_scenes_go_into_a_new_shard_and_old_ones_stay(server, raw: Path, tmp_path: Path):
    grown = tmp_path / "raw"
    shutil.copytree(raw, grown)
    data = tmp_path / "data"
    assert vgn_data("pack", str(grown), "--source", "pile", "--out", str(data)).returncode == 0
    (first,) = RecipeFolder(data).manifest()["shards"]
    generate(server.url, grown, scenes=4)
    assert vgn_data("pack", str(grown), "--source", "pile", "--out", str(data)).returncode == 0
    shards = RecipeFolder(data).manifest()["shards"]
    assert shards[0] == first and len(shards) == 2 and shards[1]["first_scene"] == "s3-0000003"
    assert sha256_of(data / first["file"]) == first["sha256"]


def test_a_source_packed_before_the_hand_was_named_grows_with_folders_that_name_it(raw: Path, tmp_path: Path):
    """Sources packed when generation recorded only the hand's version keep growing once it also
    records the hand's name and digest; a folder whose other settings differ is still refused."""
    older = tmp_path / "older"
    shutil.copytree(raw, older)
    generation = json.loads((older / "generation.json").read_text())
    assert {"gripper_name", "gripper_digest"} <= set(generation)
    for key in ("gripper_name", "gripper_digest"):
        del generation[key]
    (older / "generation.json").write_text(json.dumps(generation))
    for recipe in sorted(RawDataset(older).recipes_dir.glob("*.npz"))[1:]:  # the first scene only
        recipe.unlink()
    data = tmp_path / "data"
    assert vgn_data("pack", str(older), "--source", "pile", "--out", str(data)).returncode == 0
    assert "gripper_name" not in RecipeFolder(data).manifest()["sources"]["pile"]
    other = tmp_path / "other"
    shutil.copytree(raw, other)
    settings = json.loads((raw / "generation.json").read_text())
    (other / "generation.json").write_text(json.dumps(settings | {"yaws": settings["yaws"] + 1}))
    refused = vgn_data("pack", str(other), "--source", "pile", "--out", str(data))
    assert refused.returncode != 0 and "other settings" in refused.stderr
    grown = vgn_data("pack", str(raw), "--source", "pile", "--out", str(data))
    assert grown.returncode == 0, grown.stderr
    manifest = RecipeFolder(data).manifest()
    assert len(manifest["shards"]) == 2 and manifest["sources"]["pile"]["gripper_name"] == "franka"


def test_a_recipe_that_no_longer_matches_its_labels_fails_verification(raw: Path, tmp_path: Path):
    data = tmp_path / "data"
    assert vgn_data("pack", str(raw), "--source", "pile", "--out", str(data)).returncode == 0
    folder = RecipeFolder(data)
    (shard,) = folder.load()
    arrays = dict(shard.data)
    arrays["object_pose"] = arrays["object_pose"].copy()
    arrays["object_pose"][0, 1] += 0.02  # one object moved 2 cm: its labels are wrong now
    manifest = folder.manifest()
    manifest["shards"] = []
    records = rebuild_records(arrays)
    folder.append(manifest, "pile", records)
    (data / shard.file).unlink()
    result = vgn_data("verify", str(data), "--scenes", "10")
    assert result.returncode == 1
    assert f"mismatch: {shard.scene_ids[0]}: the rebuilt grid differs" in result.stdout


def rebuild_records(arrays: dict[str, np.ndarray]) -> list:
    """The records of a shard's arrays (the inverse of ``shard_arrays``), to write a changed copy."""
    from training.recipe_shards import RecipeRecord, RecipeShard

    shard = RecipeShard("pile", "x", arrays)
    records = []
    for row, labels in enumerate(shard.labels_by_scene()):
        recipe = shard.recipe(row)
        files = dict(
            zip(
                arrays["object_refs"],
                zip(arrays["object_urdf_sha256"], arrays["object_mesh_sha256"], strict=True),
                strict=True,
            )
        )
        records.append(RecipeRecord(recipe.scene_id, {
            "objects": np.asarray(recipe.objects), "urdf_sha256": np.asarray([files[r][0] for r in recipe.objects]),
            "mesh_sha256": np.asarray([files[r][1] for r in recipe.objects]), "scales": recipe.scales,
            "poses": recipe.poses, "views": recipe.views,
            "noise_state": recipe.noise_state if recipe.noise_state is not None else np.zeros(0, np.uint64),
            "side_view": np.asarray(recipe.side_view), "renderer": np.asarray(recipe.renderer)},
            arrays["grid_digest"][row], labels))  # fmt: skip
    assert shard_arrays(records)["grasps"].shape == arrays["grasps"].shape
    return records


def git(repo: Path, *args: str) -> None:
    subprocess.run(["git", "-C", str(repo), "-c", "user.name=t", "-c", "user.email=t@t", *args], check=True,
                   capture_output=True)  # fmt: skip


def test_grid_shards_migrate_to_recipes_with_proof(raw: Path, tmp_path: Path):
    repo = tmp_path / "repo"
    grids = repo / "data"
    packed = run("-m", "training.pack", str(raw), "--source", "pile", "--out", str(grids))
    assert packed.returncode == 0, packed.stderr
    git(repo, "init", "-q")
    git(repo, "add", "-A")
    git(repo, "commit", "-q", "-m", "grid shards")
    stored = {
        str(s): g
        for shard in ShardFolder(grids).load()
        for s, g in zip(shard.scene_ids, shard.grids, strict=True)
    }
    migrated = vgn_data("migrate", str(grids), "--work", str(tmp_path / "work"), "--objects", "pile=blocks",
                        "--renderer", "tiny", "--finish")  # fmt: skip
    assert migrated.returncode == 0, migrated.stderr
    assert f"pile: {len(stored)} of {len(stored)} scenes converted" in migrated.stdout
    manifest = RecipeFolder(grids).manifest()
    assert manifest["format"] == 2 and manifest["migration"]["pile"]["converted"] == len(stored)
    assert not list((grids / "shards").glob("pile-0*.npz.xz"))  # the grid shards are gone
    git(repo, "add", "-A")
    git(repo, "commit", "-q", "-m", "recipes")
    # The removed grids are found in the history, and the rebuilt scenes equal them voxel for voxel.
    verified = vgn_data("verify", str(grids))
    assert verified.returncode == 0, verified.stdout
    assert (
        f"largest difference from the stored grid 0 / 255 ({len(stored)} scenes compared" in verified.stdout
    )
    extracted = vgn_data("legacy-grids", str(grids), "--out", str(tmp_path / "legacy"))
    assert extracted.returncode == 0, extracted.stderr
    (shard,) = ShardFolder(tmp_path / "legacy").load()
    assert {str(s) for s in shard.scene_ids} == set(stored)


def test_training_draws_fresh_observations_from_the_cache(raw: Path, tmp_path: Path):
    data = tmp_path / "data"
    assert vgn_data("pack", str(raw), "--source", "pile", "--out", str(data)).returncode == 0
    settings = ObservationSettings(per_scene=3, noise_fraction=0.5)
    cache = tmp_path / "cache"
    (path,) = render_cache(data, cache, settings)
    grids = np.load(path)
    (shard,) = RecipeFolder(data).load()
    assert grids.shape == (len(shard.scene_ids), 3, 40, 40, 40)
    from training.recipe_grids import grid_digest

    for row in range(len(shard.scene_ids)):  # slot 0 is the scene's original observation
        np.testing.assert_array_equal(grid_digest(grids[row, 0]), shard.data["grid_digest"][row])
        assert not np.array_equal(grids[row, 1], grids[row, 2])
    assert render_cache(data, cache, settings) == [path]  # cached: nothing rendered again
    scenes, (summary,) = load_scenes([data], 40, 2.0, cache, settings)
    assert summary.scenes == len(scenes) >= 1 and isinstance(scenes[0].source, RenderedObservations)
    fresh = SceneDataset(scenes, augment=None, seed=0, copies=8, fresh_observations=True)
    seen = {fresh[i].grid.numpy().tobytes() for i in range(0, 8 * len(scenes), len(scenes))}
    assert len(seen) >= 2
    fixed = SceneDataset(scenes, augment=None, seed=0, copies=8)
    assert len({fixed[i].grid.numpy().tobytes() for i in range(0, 8 * len(scenes), len(scenes))}) == 1
    trained = run("-m", "training.cli", "--data", str(data), "--cache", str(cache), "--observations", "3",
                  "--observation-noise", "0.5", "--epochs", "1", "--val-fraction", "0", "--out",
                  str(tmp_path / "w.safetensors"), "--no-progress")  # fmt: skip
    assert trained.returncode == 0, trained.stderr
    card = json.loads((tmp_path / "w.card.json").read_text())
    assert card["training"]["observations"]["per_scene"] == 3


def test_six_view_observations_are_the_evaluation_views_and_old_cache_keys_stand(raw: Path, tmp_path: Path):
    from sim_worker.camera import six_views
    from training.observations import draw_cameras

    assert ObservationSettings().key() == "20d6796c46f9", "caches rendered before views could be chosen"
    six = ObservationSettings(per_scene=1, original=False, views="six", noise_fraction=0.0)
    assert six.key() != ObservationSettings(per_scene=1, original=False, noise_fraction=0.0).key()
    same = ObservationSettings(
        per_scene=1, original=False, views="six", noise_fraction=0.0, side_view_fraction=0.0
    )
    assert same.key() == six.key(), "knobs of random views name no other six-view cache"
    poses, noisy = draw_cameras(six, six.rng("any", 0))
    assert not noisy and all(np.allclose(a, b) for a, b in zip(poses, six_views(), strict=True))
    with pytest.raises(ValueError, match="views"):
        ObservationSettings(views="four")
    data, cache = tmp_path / "data", tmp_path / "cache"
    assert vgn_data("pack", str(raw), "--source", "pile", "--out", str(data)).returncode == 0
    rendered = vgn_data("render", str(data), "--views", "six", "--no-original", "--noise-fraction", "0",
                        "--out", str(cache))  # fmt: skip
    assert rendered.returncode == 0, rendered.stderr
    (path,) = cache.glob(f"*-{six.key()}.npy")  # the command rendered the six views
    grids = np.load(path)
    original = np.load(render_cache(data, cache, ObservationSettings())[0])
    assert grids.shape == original.shape and not np.array_equal(grids, original)


@pytest.mark.slow
def test_teacher_and_student_see_the_six_views_and_the_card_says_so(raw: Path, tmp_path: Path):
    from service.settings import PACKAGED_MODEL

    data = tmp_path / "data"
    assert vgn_data("pack", str(raw), "--source", "pile", "--out", str(data)).returncode == 0
    common = ["-m", "training.cli", "--data", str(data), "--cache", str(tmp_path / "cache"), "--epochs", "1",
              "--val-fraction", "0", "--no-progress", "--teacher", str(PACKAGED_MODEL), "--teacher-views", "six"]  # fmt: skip
    trained = run(*common, "--observations", "2", "--observation-noise", "1", "--observation-sensor",
                  "structured-light", "--observation-views", "six", "--out", str(tmp_path / "w.safetensors"))  # fmt: skip
    assert trained.returncode == 0, trained.stderr
    card = json.loads((tmp_path / "w.card.json").read_text())["training"]
    assert (
        card["distillation"]["teacher_views"] == "each scene rendered clean from VGN's six evaluation views"
    )
    assert card["observations"]["sensor"] == "structured-light" and card["observations"]["per_scene"] == 2
    assert card["observations"]["views"] == "six"
    student = ObservationSettings(per_scene=2, noise_fraction=1.0, sensor="structured-light", views="six")
    assert len(list((tmp_path / "cache").glob(f"*-{student.key()}.npy"))) == 1, (
        "the student's views were cached"
    )
    six = ObservationSettings(
        per_scene=1, original=False, views="six", noise_fraction=0.0, side_view_fraction=0.0
    )
    assert len(list((tmp_path / "cache").glob(f"*-{six.key()}.npy"))) == 1, "the teacher's views were cached"
    alone = run(
        "-m",
        "training.cli",
        "--data",
        str(data),
        "--teacher-views",
        "six",
        "--out",
        str(tmp_path / "x.safetensors"),
    )
    assert alone.returncode != 0 and "--teacher-views needs --teacher" in alone.stderr
    legacy = tmp_path / "raw-copy"
    shutil.copytree(raw, legacy)
    not_recipes = run("-m", "training.cli", "--data", str(legacy), "--teacher", str(PACKAGED_MODEL), "--teacher-views",
                      "six", "--epochs", "1", "--no-progress", "--out", str(tmp_path / "y.safetensors"))  # fmt: skip
    assert not_recipes.returncode != 0 and "needs recipe folders" in not_recipes.stderr


def test_training_takes_the_sources_it_is_given(server, raw: Path, tmp_path: Path):
    """``--source`` trains on some streams of a recipe folder: only their scenes are rendered and
    drawn, the card says which, and a name the folder lacks is refused with the names it has."""
    data = tmp_path / "data"
    other = tmp_path / "raw-other"
    generate(server.url, other, scenes=2, seed=8)
    for folder, source in ((raw, "pile"), (other, "pile-other")):
        assert vgn_data("pack", str(folder), "--source", source, "--out", str(data)).returncode == 0
    cache = tmp_path / "cache"
    scenes, (summary,) = load_scenes([data], 40, 2.0, cache, sources=("pile-other",))
    assert {s.scene_id for s in scenes} == set(RawDataset(other).scene_ids()) and summary.scenes == len(
        scenes
    )
    assert len(list(cache.rglob("*.npy"))) == 1, "only the chosen source's shard is rendered"
    everything, _ = load_scenes([data], 40, 2.0, cache)
    assert len(everything) > len(scenes)
    with pytest.raises(ValueError, match="has the source\\(s\\) packed; it has: pile, pile-other"):
        load_scenes([data], 40, 2.0, cache, sources=("packed",))
    out = tmp_path / "w.safetensors"
    trained = run("-m", "training.cli", "--data", str(data), "--cache", str(cache), "--source", "pile-other",
                  "--epochs", "1", "--val-fraction", "0", "--out", str(out), "--no-progress")  # fmt: skip
    assert trained.returncode == 0, trained.stderr
    card = json.loads(out.with_suffix(".card.json").read_text())
    assert card["training"]["sources"] == ["pile-other"] and card["datasets"][0]["scenes"] == len(scenes)
    refused = run("-m", "training.cli", "--data", str(data), "--cache", str(cache), "--source", "packed",
                  "--epochs", "1", "--out", str(tmp_path / "x.safetensors"), "--no-progress")  # fmt: skip
    assert refused.returncode != 0 and "it has: pile, pile-other" in refused.stderr
