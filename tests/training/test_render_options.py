"""``vgn-data render``'s observation options are ``ObservationSettings``' fields, named after them,
as ``vgn-train``'s are under their own names: one declaration, so both commands offer the same
options with the same defaults, and a documented render command makes the observations it says."""

from __future__ import annotations

import argparse
import shlex

from tests.training.test_train_options import DOCUMENTS
from training.cli import build_parser as train_parser
from training.cli import config_from_args
from training.data_cli import build_parser, render_settings
from training.observations import ObservationSettings
from training.options import declared_options

#: The flags ``vgn-data render`` had before they were derived, which scripts may use.
FLAGS = {"--per-scene", "--no-original", "--side-view-fraction", "--noise-fraction", "--sensor", "--views"}


def render_parser() -> argparse.ArgumentParser:
    commands = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return commands.choices["render"]


def render(line: str) -> ObservationSettings:
    return render_settings(render_parser().parse_args(shlex.split(line)))


def test_every_observation_setting_is_a_render_flag_named_after_it_with_its_default():
    actions = {flag: action for action in render_parser()._actions for flag in action.option_strings}
    declared = list(declared_options(ObservationSettings))
    assert {
        a.option_strings[0] for a in render_parser()._actions if a.dest in {d.dest for d in declared}
    } == FLAGS
    for option in declared:
        name = option.dest.replace("_", "-")
        flag = f"--no-{name}" if option.default is True else f"--{name}"
        assert actions[flag].dest == option.dest and actions[flag].default == option.default, flag
    assert render("data") == ObservationSettings()


def test_render_and_train_make_the_same_observations_of_the_same_words():
    rendered = render("data --per-scene 4 --views six --noise-fraction 0.67 --side-view-fraction 0.1 "
                      "--sensor structured-light --no-original")  # fmt: skip
    trained = config_from_args(train_parser().parse_args(shlex.split(
        "--data data --out w.safetensors --observations 4 --observation-views six --observation-noise 0.67 "
        "--observation-side-views 0.1 --observation-sensor structured-light --no-original"
    ))).observations  # fmt: skip
    assert rendered == trained == ObservationSettings(
        per_scene=4, original=False, side_view_fraction=0.1, noise_fraction=0.67,
        sensor="structured-light", views="six",
    )  # fmt: skip


def test_the_documented_render_command_lines_parse():
    lines = []
    for path in DOCUMENTS:
        for text in path.read_text().splitlines():
            for command in text.split("#")[0].split("&&"):
                if command.strip().startswith("vgn-data render "):
                    lines.append(command.strip().removeprefix("vgn-data render "))
    assert len(lines) >= 8, "the documentation's render command lines were not found"
    for line in lines:
        assert isinstance(render(line), ObservationSettings), line
    assert render("DATA --views six --no-original --noise-fraction 0 --out CACHE") == ObservationSettings(
        original=False, noise_fraction=0.0, views="six"
    )
