"""The model card names no machine: it travels with its weights (one ships in the package), so the
paths it records are relative to where the command ran or under ``~``, and cards written before,
with absolute paths and a ``working_directory``, still read."""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from pathlib import Path

import pytest

from service.settings import PACKAGED_MODEL
from service.vgn.checkpoint import card_path, card_summary
from training.card import build_card, labelling_hand, portable_path, write_card


def test_a_path_inside_the_working_directory_is_written_relative_to_it(tmp_path: Path):
    home = tmp_path / "home"
    work = home / "checkout"
    assert portable_path(work / "data", cwd=work, home=home) == "data"
    assert portable_path(str(work / "data" / "shards"), cwd=work, home=home) == "data/shards"
    assert portable_path(work, cwd=work, home=home) == "."


def test_a_path_under_the_home_directory_is_written_from_tilde(tmp_path: Path):
    home, work = tmp_path / "home", tmp_path / "elsewhere"
    assert portable_path(home / "vgn-data" / "cache", cwd=work, home=home) == "~/vgn-data/cache"
    assert portable_path(home, cwd=work, home=home) == "~"


def test_other_paths_and_text_are_kept(tmp_path: Path):
    home, work = tmp_path / "home", tmp_path / "work"
    assert portable_path("/srv/datasets/pile", cwd=work, home=home) == "/srv/datasets/pile"
    assert portable_path("data", cwd=work, home=home) == "data", "already relative"
    assert portable_path("packed shards", cwd=work, home=home) == "packed shards", "a note, not a path"
    assert portable_path("/srv/data", cwd=Path("/"), home=home) == "/srv/data", "a root cwd does not count"


def test_a_symlinked_working_directory_still_counts(tmp_path: Path):
    real = tmp_path / "real"
    (real / "data").mkdir(parents=True)
    link = tmp_path / "link"
    link.symlink_to(real)
    # Dataset paths are resolved before they reach the card; the shell's cwd may be the link.
    assert portable_path((link / "data").resolve(), cwd=link, home=tmp_path / "home") == "data"


def test_a_new_card_records_portable_paths_and_no_working_directory(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
):
    home, work = tmp_path / "home", tmp_path / "home" / "checkout"
    work.mkdir(parents=True)
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.chdir(work)
    weights = work / "vgn.safetensors"
    weights.write_bytes(b"weights")
    datasets = [
        {"path": str(work / "data"), "scenes": 3, "cache": str(home / ".cache" / "grids")},
        {"path": str(work / "raw"), "scenes": 2, "cache": "packed shards"},
    ]
    card = build_card(
        weights=weights,
        datasets=datasets,
        training={},
        history=[],
        best=None,
        command="vgn-train",
        threshold=0.8,
    )
    assert "working_directory" not in card
    assert card["gripper"] is None, "not recorded unless given"
    assert card["datasets"][0] == {"path": "data", "scenes": 3, "cache": "~/.cache/grids"}
    assert card["datasets"][1] == {"path": "raw", "scenes": 2, "cache": "packed shards"}
    assert datasets[0]["path"] == str(work / "data"), "the caller's summaries are left as they were"
    write_card(card, card_path(weights))
    assert str(tmp_path) not in card_path(weights).read_text(), "the written card names no machine path"


def test_a_card_written_before_still_reads(tmp_path: Path):
    weights = tmp_path / "vgn.safetensors"
    weights.write_bytes(b"weights")
    old = {
        "format": 1,
        "datasets": [{"path": "/work/main/data", "scenes": 5, "grasps": 40, "cache": "/root/vgn-data/cache"}],
        "epochs": 1,
        "threshold": 0.8,
        "command": "vgn-train --data data",
        "working_directory": "/work/main",
    }
    card_path(weights).write_text(json.dumps(old))
    summary = card_summary(weights)
    assert summary is not None and summary["scenes"] == 5 and summary["grasps"] == 40


#: An absolute path at the start of a value or after a space, ``=``, a quote or a bracket.
ABSOLUTE_PATH = re.compile(r"(?:^|[\s='\"(])/[\w.-]")


def strings(value: object, where: str = "") -> Iterator[tuple[str, str]]:
    """Every text in a JSON value, with where it is."""
    if isinstance(value, dict):
        for key, item in value.items():
            yield from strings(item, f"{where}.{key}")
    elif isinstance(value, list):
        for index, item in enumerate(value):
            yield from strings(item, f"{where}[{index}]")
    elif isinstance(value, str):
        yield where, value


def test_the_shipped_cards_name_no_machine_path():
    cards = sorted(PACKAGED_MODEL.parent.glob("*.card.json"))
    assert card_path(PACKAGED_MODEL) in cards
    for path in cards:
        card = json.loads(path.read_text())
        assert "working_directory" not in card, path.name
        found = [f"{where}: {text!r}" for where, text in strings(card) if ABSOLUTE_PATH.search(text)]
        assert not found, f"{path.name} names machine paths: {found}"


def test_the_card_names_the_hand_of_every_dataset_or_none():
    assert labelling_hand(["robotiq-2f85-v1", "robotiq-2f85-v1"]) == "robotiq-2f85-v1"
    assert labelling_hand(["franka-v2", None]) is None, "a dataset made elsewhere: not recorded"
    with pytest.raises(ValueError, match=r"different hands \(franka-v2, robotiq-2f85-v1\)"):
        labelling_hand(["robotiq-2f85-v1", "franka-v2", None])
