"""``vgn-client ... --log-level``: every subcommand takes it, and it decides what the ``vgn.*``
loggers write to stderr. Runs the real command line in a child process against a port nothing
listens on, so no service is needed."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from client.cli import build_parser

REPO = Path(__file__).resolve().parents[2]
UNREACHABLE = "http://127.0.0.1:9"  # the discard port: refused at once on a machine without the service


def vgn_client(*args: str) -> subprocess.CompletedProcess[str]:
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])),
    }
    env.pop("VGN_URL", None)
    return subprocess.run(
        [sys.executable, "-m", "client.cli", *args],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=REPO,
        env=env,
    )


def test_debug_shows_the_client_loggers():
    result = vgn_client("status", "--url", UNREACHABLE, "--log-level", "debug")
    assert result.returncode == 1, result.stderr  # unreachable, but the command ran
    assert f"DEBUG vgn.client: connecting to {UNREACHABLE} over HTTP" in result.stderr
    assert "cannot reach the service" in result.stderr


def test_default_keeps_debug_messages_off():
    result = vgn_client("status", "--url", UNREACHABLE)
    assert result.returncode == 1, result.stderr
    assert "vgn.client" not in result.stderr
    assert "DEBUG" not in result.stderr
    assert "cannot reach the service" in result.stderr


def test_an_unknown_level_is_a_usage_error():
    result = vgn_client("status", "--url", UNREACHABLE, "--log-level", "loud")
    assert result.returncode == 2
    assert "argument --log-level: invalid choice: 'loud'" in result.stderr
    assert "vgn.client" not in result.stderr  # refused before anything connected


def _subcommands() -> list[str]:
    parser = build_parser()
    (commands,) = [a for a in parser._actions if a.dest == "command"]
    return sorted(commands.choices)


@pytest.mark.parametrize("command", _subcommands())
def test_every_subcommand_takes_the_option(command):
    parser = build_parser()
    required = {
        "grasps": ["S"],
        "view": ["S"],
        "clean-data": ["SRC", "DST"],
        "generate-data": ["--out", "D"],
    }.get(command, [])
    args = parser.parse_args([command, *required, "--log-level", "info"])
    assert args.log_level == "info"
    assert parser.parse_args([command, *required]).log_level == "warning"
