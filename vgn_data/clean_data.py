"""``vgn-client clean-data``: VGN's cleaning of a raw dataset, into a new folder.

The command belongs to the dataset layout, not to the robot-side client: ``client.cli`` only
routes the subcommand here by name (as it does the simulator commands), so ``client`` imports
nothing of this package, which itself builds on ``client``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from vgn_data.dataset import clean_and_balance


def run(args: argparse.Namespace) -> int:
    """Clean ``args.source`` into ``args.destination``. Exit status: 0 done, 2 a refused folder."""
    try:
        kept = clean_and_balance(Path(args.source), Path(args.destination), seed=args.seed)
    except (ValueError, FileNotFoundError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    print(f"wrote {args.destination}: {kept} grasps")
    return 0
