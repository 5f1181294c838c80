"""Split an object folder (VGN layout) into train and held-out objects, *by object*.

    python -m sim_worker.object_split $VGN_OBJECTS/pile/train ~/vgn-data/objects/pile --holdout 0.1

Membership depends only on each object's name (a hash), so the split is reproducible and
stable when objects are added. The new folders hold symbolic links to the URDF and its
meshes: nothing is copied.
"""

from __future__ import annotations

import argparse
import hashlib
from pathlib import Path


def is_held_out(name: str, fraction: float) -> bool:
    """Whether the object called ``name`` falls in the held-out ``fraction``, by a hash of the name alone."""
    bucket = int.from_bytes(hashlib.sha256(name.encode()).digest()[:4], "big") / 2**32
    return bucket < fraction


def split_objects(source: Path, destination: Path, fraction: float) -> tuple[int, int]:
    """Link each object of ``source`` into ``destination/train`` or ``destination/heldout``."""
    source = source.resolve()
    urdfs = sorted(source.glob("*.urdf"))
    if not urdfs:
        raise ValueError(f"{source} holds no .urdf files")
    counts = {"train": 0, "heldout": 0}
    for urdf in urdfs:
        part = "heldout" if is_held_out(urdf.stem, fraction) else "train"
        target = destination / part
        target.mkdir(parents=True, exist_ok=True)
        for file in [urdf, *sorted(source.glob(f"{urdf.stem}_*")), *sorted(source.glob(f"{urdf.stem}.*"))]:
            link = target / file.name
            if not link.exists():
                link.symlink_to(file)
        counts[part] += 1
    return counts["train"], counts["heldout"]


def main() -> None:
    """Split the folder given on the command line and print the counts."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("source", type=Path)
    parser.add_argument("destination", type=Path)
    parser.add_argument("--holdout", type=float, default=0.1, help="fraction of objects held out")
    args = parser.parse_args()
    train, heldout = split_objects(args.source, args.destination.expanduser(), args.holdout)
    print(f"{args.destination}: {train} train objects, {heldout} held out")


if __name__ == "__main__":
    main()
