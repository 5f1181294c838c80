"""What a user reads in ``--help``: plain text (the help texts that come from docstrings carry no
reStructuredText quotes), every option of ``vgn-client serve`` explained with its default, and the
extras a command is said to need are the ones ``install.sh`` installs."""

from __future__ import annotations

import argparse
import re
from collections.abc import Iterator
from pathlib import Path

from client.cli import build_parser as client_parser
from training.cli import build_parser as train_parser
from training.data_cli import build_parser as data_parser
from training.pack import build_parser as pack_parser

ROOT = Path(__file__).resolve().parents[1]
COMMANDS = {"vgn-client": client_parser, "vgn-train": train_parser, "vgn-data": data_parser,
            "vgn-pack-data": pack_parser}  # fmt: skip


def subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    found = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(found[0].choices) if found else {}


def helps(name: str, parser: argparse.ArgumentParser) -> Iterator[tuple[str, str]]:
    """``--help`` of a command and of each of its subcommands."""
    yield name, parser.format_help()
    for sub, subparser in subcommands(parser).items():
        yield from helps(f"{name} {sub}", subparser)


def test_no_help_shows_restructuredtext_quotes():
    for command, build in COMMANDS.items():
        for name, text in helps(command, build()):
            assert "``" not in text, f"{name} --help: {[line for line in text.splitlines() if '``' in line]}"


def test_every_serve_option_is_explained_with_its_default():
    serve = subcommands(client_parser())["serve"]
    for action in serve._actions:
        if action.option_strings and action.dest != "help":
            assert action.help, action.option_strings[0]
            if action.default is not None:
                assert "%(default)s" in action.help, action.option_strings[0]
    text = serve.format_help()
    assert "default 127.0.0.1" in text and "default 8000" in text


def test_clear_scene_is_said_to_need_the_extras_install_sh_installs():
    installed = re.search(
        r"^\s*lock=requirements/main\.txt extras=([\w,]+)$", (ROOT / "install.sh").read_text(), re.M
    )
    assert installed, "install.sh's default extras were not found"
    (line,) = [line for line in client_parser().format_help().splitlines() if "clear-scene --sim" in line]
    needs = line.split("needs", 1)[1]
    assert "[all]" not in needs and all(
        re.search(rf"\b{extra}\b", needs) for extra in installed.group(1).split(",")
    ), line
