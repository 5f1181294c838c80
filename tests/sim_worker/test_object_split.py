"""The object split that keeps benchmark objects out of training: by object, reproducible,
stable when objects are added, and linking rather than copying."""

from __future__ import annotations

from pathlib import Path

import pytest

from sim_worker.object_split import is_held_out, split_objects


def object_folder(root: Path, names: list[str]) -> Path:
    """A VGN-layout folder: ``name.urdf`` with a mesh and a collision mesh per object."""
    root.mkdir(parents=True, exist_ok=True)
    for name in names:
        (root / f"{name}.urdf").write_text(f"<robot name='{name}'/>")
        (root / f"{name}.obj").write_text("v 0 0 0\n")
        (root / f"{name}_collision.obj").write_text("v 0 0 0\n")
    return root


def members(destination: Path, part: str) -> set[str]:
    return {p.stem for p in (destination / part).glob("*.urdf")}


NAMES = [f"object_{n:03d}" for n in range(60)]


def test_the_split_is_by_object_and_the_same_every_time(tmp_path: Path):
    source = object_folder(tmp_path / "objects", NAMES)
    first, second = tmp_path / "a", tmp_path / "b"
    assert split_objects(source, first, 0.2) == split_objects(source, second, 0.2)
    held_out = members(first, "heldout")
    assert held_out == members(second, "heldout") and members(first, "train") == members(second, "train")
    assert held_out.isdisjoint(members(first, "train"))
    assert held_out | members(first, "train") == set(NAMES)
    assert 3 <= len(held_out) <= 24, "about a fifth held out"
    for name in held_out:  # every file of an object goes with it, as a link to the original
        files = sorted(p.name for p in (first / "heldout").glob(f"{name}*"))
        assert files == [f"{name}.obj", f"{name}.urdf", f"{name}_collision.obj"]
        assert all((first / "heldout" / f).is_symlink() for f in files)
        assert (first / "heldout" / f"{name}.urdf").resolve() == (source / f"{name}.urdf").resolve()


def test_adding_objects_never_moves_the_old_ones(tmp_path: Path):
    before = tmp_path / "before"
    split_objects(object_folder(tmp_path / "few", NAMES[:30]), before, 0.2)
    after = tmp_path / "after"
    split_objects(object_folder(tmp_path / "more", NAMES), after, 0.2)
    assert members(before, "heldout") == {n for n in members(after, "heldout") if n in NAMES[:30]}


@pytest.mark.parametrize("fraction", [0.0, 1.0])
def test_the_fraction_bounds(fraction: float):
    assert {is_held_out(name, fraction) for name in NAMES} == {fraction == 1.0}


def test_a_folder_without_objects_is_refused(tmp_path: Path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="no .urdf"):
        split_objects(tmp_path / "empty", tmp_path / "out", 0.1)
