"""vgn-train's options are TrainConfig's fields: every field has its flag with the field's default, and
the command lines the documentation shows still parse to the runs they describe."""

from __future__ import annotations

import argparse
import json
import shlex
from dataclasses import MISSING, dataclass, field, fields, is_dataclass
from pathlib import Path
from typing import get_type_hints

import pytest

from training.cli import EPILOG, build_parser, config_from_args
from training.observations import ObservationSettings
from training.options import OPTION, add_options, option
from training.train import TrainConfig

ROOT = Path(__file__).resolve().parents[2]
DOCUMENTS = [ROOT / "README.md", ROOT / "data" / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
SHIPPED_COMMAND = (
    "--data data --cache CACHE --init service/models/vgn.safetensors --teacher service/models/vgn.safetensors "
    "--distill-weight 8 --epochs 3 --batch-scenes 4 --threads 2 --threshold 0.8 --observations 1 "
    "--out all/vgn.safetensors"
)


def run_settings(cls: type = TrainConfig, prefix: str = "") -> dict[str, tuple[object, str | None]]:
    """Every setting of a run that is meant to be an option, by its dest: its default, and the word
    that stands for None on the command line, if any."""
    settings = {}
    for item in fields(cls):
        kind = get_type_hints(cls)[item.name]
        if is_dataclass(kind):
            settings |= run_settings(kind, f"{prefix}{item.name}.")
        elif item.metadata.get(OPTION, True) is not None:
            none = getattr(item.metadata.get(OPTION), "none", None)
            settings[prefix + item.name] = (item.default, none)
    return settings


def actions() -> dict[str, argparse.Action]:
    """The parser's options by dest (the first that sets it)."""
    found: dict[str, argparse.Action] = {}
    for action in build_parser()._actions:
        if action.option_strings:
            found.setdefault(action.dest, action)
    return found


def test_every_run_setting_has_a_flag_with_the_settings_default():
    parser_actions = actions()
    assert set(run_settings()) <= set(parser_actions), "settings without a flag"
    for dest, (default, none) in run_settings().items():
        action = parser_actions[dest]
        if default is MISSING:
            assert action.required, dest
        else:
            given = None if none is not None and action.default == none else action.default
            assert given == default, f"{action.option_strings[0]}: {action.default!r} != {default!r}"


def test_only_a_few_flags_are_not_run_settings():
    hand_written = set(actions()) - set(run_settings()) - {"help"}
    assert hand_written == {"eval_objects", "eval_scene", "eval_rounds", "threads", "log_level"}


def documented_command_lines() -> list[list[str]]:
    """vgn-train command lines from the documentation, the shipped model's card and --help's examples."""
    lines = []
    for text in [path.read_text().replace("\\\n", " ") for path in DOCUMENTS] + [EPILOG]:
        for line in text.splitlines():
            if line.strip().startswith("vgn-train --"):
                lines.append(shlex.split(line.split("#")[0])[1:])
    for card in sorted((ROOT / "service" / "models").glob("*.card.json")):
        command = json.loads(card.read_text()).get("command", "")
        if command.startswith("vgn-train --"):
            lines.append(shlex.split(command)[1:])
    return lines


def parse(argv: list[str]) -> TrainConfig:
    for flag in ("--init", "--teacher"):  # TrainConfig wants the weights to exist
        if flag in argv:
            weights = Path(argv[argv.index(flag) + 1])
            weights.parent.mkdir(parents=True, exist_ok=True)
            weights.touch()
    return config_from_args(build_parser().parse_args(argv))


def test_the_documented_command_lines_parse(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    monkeypatch.chdir(tmp_path)
    commands = documented_command_lines()
    assert len(commands) >= 15, "the documentation's command lines were not found"
    for argv in commands:
        assert isinstance(parse(argv), TrainConfig), shlex.join(argv)


def test_documented_command_lines_describe_the_same_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    monkeypatch.chdir(tmp_path)
    teacher = Path("service/models/vgn.safetensors")
    shipped = parse(shlex.split(SHIPPED_COMMAND))
    assert shipped == TrainConfig(
        data=[Path("data")],
        out=Path("all/vgn.safetensors"),
        cache=Path("CACHE"),
        init=teacher,
        teacher=teacher,
        distill_weight=8.0,
        epochs=3,
        batch_scenes=4,
        threshold=0.8,
    )
    fresh = parse(
        shlex.split(
            "--data DATA --cache CACHE --init service/models/vgn.safetensors --teacher "
            "service/models/vgn.safetensors --teacher-views six --distill-weight 8 --epochs 3 --threshold 0.8 "
            "--observations 4 --observation-views six --observation-noise 0.67 --out fresh/vgn.safetensors"
        )
    )
    assert fresh.teacher_views == "six" and fresh.observations == ObservationSettings(
        per_scene=4, views="six", noise_fraction=0.67
    )
    picked = parse(
        shlex.split("--data data --source pile --source pile-answers --train-scenes 6000 --out m.safetensors")
    )
    assert picked.sources == ("pile", "pile-answers") and picked.max_train_scenes == 6000


@pytest.mark.parametrize(
    ("extra", "name", "expected"),
    [
        (["--augment", "none"], "augment", None),
        (["--no-augment"], "augment", None),
        (["--augment", "shift"], "augment", "shift"),
        (["--threshold", "auto"], "threshold", None),
        (["--threshold", "0.3"], "threshold", 0.3),
        (["--no-balance"], "balance", False),
        (["--no-progress"], "progress", False),
        (["--resume"], "resume", True),
    ],
)
def test_the_words_and_switches_that_set_a_field(extra: list[str], name: str, expected: object):
    args = build_parser().parse_args(["--data", "d", "--out", "w.safetensors", *extra])
    assert getattr(config_from_args(args), name) == expected


def test_a_threshold_is_a_number_or_auto(capsys: pytest.CaptureFixture[str]):
    with pytest.raises(SystemExit):
        build_parser().parse_args(["--data", "d", "--out", "w.safetensors", "--threshold", "high"])
    assert "expected a number in [0, 1] or 'auto', got 'high'" in capsys.readouterr().err


def test_a_setting_without_an_option_declaration_is_refused():
    @dataclass
    class Undeclared:
        epochs: int = field(default=1, metadata=option("run", "epochs"))
        forgotten: int = 0

    groups = {"run": argparse.ArgumentParser().add_argument_group("run")}
    with pytest.raises(TypeError, match="forgotten"):
        add_options(groups, Undeclared)
