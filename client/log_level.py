"""``--log-level`` for the command-line tools: library code logs to named loggers (``vgn.*``,
``sim_worker.*``, ``service.*``) and says nothing unless a tool turns them on."""

from __future__ import annotations

import argparse
import logging

LEVELS = ("debug", "info", "warning", "error")


def add_log_level_option(parser: argparse.ArgumentParser, default: str = "warning") -> None:
    """Add ``--log-level`` to ``parser``; ``configure_logging`` applies the choice after parsing."""
    parser.add_argument(
        "--log-level",
        choices=LEVELS,
        default=default,
        help="what the libraries report on stderr (default %(default)s; info names the renderer, "
        "the weights format and similar choices)",
    )


def configure_logging(level: str) -> None:
    """Route every logger to stderr at ``level`` (the tools' own progress output is separate)."""
    logging.basicConfig(level=level.upper(), format="%(levelname)s %(name)s: %(message)s", force=True)
