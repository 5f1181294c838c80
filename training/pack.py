"""vgn-pack-data: pack raw datasets into the repository's append-only training shards.

    vgn-pack-data ~/vgn-data/raw-v2/pile --source pile --out data
    vgn-pack-data --show data

Each run fuses the scenes of the raw folder that no shard of that source holds yet, writes
them as new shards (never touching old ones) and extends manifest.json. Raw depth stays
where it is; a scene can be made again from its seed (the manifest records the generator's
settings).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from client.log_level import add_log_level_option, configure_logging
from training.shards import DEFAULT_SCENES_PER_SHARD, ShardError, ShardFolder, manifest_summary
from vgn_data.dataset import RawDataset


def build_parser() -> argparse.ArgumentParser:
    """The ``vgn-pack-data`` command line; the module docstring is its help text."""
    parser = argparse.ArgumentParser(
        prog="vgn-pack-data", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "raw", nargs="?", type=Path, help="raw dataset folder (setup.json, grasps.csv, scenes/)"
    )
    parser.add_argument("--source", help="name of this stream of scenes in the manifest, e.g. pile")
    parser.add_argument("--out", type=Path, default=Path("data"), help="shard folder (default %(default)s)")
    parser.add_argument(
        "--scenes-per-shard",
        type=int,
        default=DEFAULT_SCENES_PER_SHARD,
        help="scenes per shard file (default %(default)s, about 10 MB)",
    )
    parser.add_argument("--limit", type=int, help="pack at most this many new scenes")
    parser.add_argument("--show", type=Path, metavar="DIR", help="print a shard folder's totals and exit")
    add_log_level_option(parser)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Pack a raw dataset's new scenes into shards, or with
    ``--show`` print a shard folder's totals; 2 for bad input."""
    args = build_parser().parse_args(argv)
    configure_logging(args.log_level)
    if args.show is not None:
        try:
            print(json.dumps(manifest_summary(ShardFolder(args.show).manifest()), indent=2))
        except FileNotFoundError as error:
            print(f"vgn-pack-data: {error}", file=sys.stderr)
            return 2
        return 0
    if args.raw is None or not args.source:
        print("vgn-pack-data: give a raw dataset folder and --source (or --show DIR)", file=sys.stderr)
        return 2
    if args.scenes_per_shard < 1 or (args.limit is not None and args.limit < 0):
        print("vgn-pack-data: --scenes-per-shard must be >= 1 and --limit >= 0", file=sys.stderr)
        return 2
    folder = ShardFolder(args.out)
    try:
        raw = RawDataset(args.raw)
        entries = folder.pack(raw, args.source, args.scenes_per_shard, limit=args.limit)
    except (ShardError, FileNotFoundError, ValueError) as error:
        print(f"vgn-pack-data: {error}", file=sys.stderr)
        return 2
    if not entries:
        print(f"no new scenes in {args.raw} for source {args.source!r}")
    for entry in entries:
        print(
            f"{entry['file']}: {entry['scenes']} scenes, {entry['grasps']} grasps "
            f"({entry['positives']} positive), {entry['bytes'] / 1e6:.2f} MB"
        )
    totals = manifest_summary(folder.manifest()) if folder.exists() else None
    if totals:
        print(
            f"{args.out}: {len(totals['shards'])} shards, {totals['scenes']} scenes, {totals['grasps']} grasps, "
            f"{totals['bytes'] / 1e6:.1f} MB"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
