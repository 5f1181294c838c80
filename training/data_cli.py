"""vgn-data: the repository's training data as scene recipes.

    vgn-data show data                                    what the folder holds
    vgn-data verify data --scenes 200                     rebuild random scenes, compare with their grids
    vgn-data render data --per-scene 8 --out ~/vgn-cache  fresh observations for training, cached
    vgn-data migrate data --work ~/vgn-data/migration --objects pile=DIR,DIR --objects packed=DIR
    vgn-data pack RAW --source pile --out data            new raw scenes (with recipes) as shards
    vgn-data legacy-grids data --out DIR                  the grid shards a migration replaced, from git history

VGN's object sets are found through --vgn-objects or $VGN_OBJECTS (the folder holding pile/,
packed/ and blocks/); see data/README.md.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from client.log_level import add_log_level_option, configure_logging
from sim_worker.recipes import RecipeError
from training.observations import ObservationSettings
from training.options import add_options, config_values
from training.shards import ShardError


def _objects_option(values: list[str]) -> dict[str, tuple[str, ...]]:
    folders: dict[str, tuple[str, ...]] = {}
    for value in values:
        source, _, dirs = value.partition("=")
        if not source or not dirs:
            raise ValueError(f"--objects {value!r}: expected SOURCE=DIR[,DIR...]")
        folders[source] = tuple(d for d in dirs.split(",") if d)
    return folders


def build_parser() -> argparse.ArgumentParser:
    """The ``vgn-data`` command line; the module docstring is its help text."""
    parser = argparse.ArgumentParser(
        prog="vgn-data", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    add_log_level_option(parser)
    commands = parser.add_subparsers(dest="command", required=True)

    migrate = commands.add_parser("migrate", help="convert grid shards to recipes (replay, rebuild, compare)")
    migrate.add_argument("data", type=Path, help="folder of grid shards (manifest format 1)")
    migrate.add_argument("--work", type=Path, required=True, help="folder for per-scene results (resumable)")
    migrate.add_argument("--objects", action="append", default=[], metavar="SOURCE=DIR[,DIR]",
                         help="this machine's object folders of a source, in the order generation used them")  # fmt: skip
    migrate.add_argument("--source", action="append", help="only these sources (default: all)")
    migrate.add_argument("--workers", type=int, default=1)
    migrate.add_argument("--limit", type=int, help="convert at most this many scenes per source")
    migrate.add_argument("--vgn-objects", help="folder of VGN's object sets (default $VGN_OBJECTS)")
    migrate.add_argument("--renderer", choices=["egl", "tiny"], default="egl",
                         help="the renderer the grids were made with (default %(default)s)")  # fmt: skip
    migrate.add_argument("--finish", action="store_true",
                         help="once every scene is converted: write the recipe shards and remove the grid shards")  # fmt: skip

    verify = commands.add_parser("verify", help="rebuild random scenes from their recipes and compare")
    verify.add_argument("data", type=Path)
    verify.add_argument(
        "--scenes", type=int, default=200, help="how many random scenes (default %(default)s)"
    )
    verify.add_argument("--seed", type=int, default=0, help="which scenes are drawn")
    verify.add_argument("--vgn-objects", help="folder of VGN's object sets (default $VGN_OBJECTS)")
    verify.add_argument(
        "--grids", type=Path, help="grid shards to compare with (default: the repository's history)"
    )

    pack = commands.add_parser("pack", help="add a raw dataset's new scenes (with recipes) as shards")
    pack.add_argument("raw", type=Path, help="raw dataset folder made by generate-data")
    pack.add_argument("--source", required=True, help="name of this stream of scenes, e.g. pile")
    pack.add_argument("--out", type=Path, default=Path("data"))
    pack.add_argument("--limit", type=int, help="pack at most this many new scenes")

    render = commands.add_parser("render", help="render K observations per scene into a cache for vgn-train")
    render.add_argument("data", type=Path)
    render.add_argument("--out", type=Path, help="cache folder (default: ~/.cache/vgn-service/observations)")
    observations = render.add_argument_group("observations", "how each scene's observations are drawn")
    add_options({"observations": observations}, ObservationSettings, own_names=True)
    render.add_argument("--workers", type=int, default=1)
    render.add_argument("--vgn-objects", help="folder of VGN's object sets (default $VGN_OBJECTS)")

    legacy = commands.add_parser(
        "legacy-grids",
        help="write the grid shards a migration removed (from the repository's history) to a folder",
    )
    legacy.add_argument("data", type=Path)
    legacy.add_argument(
        "--out", type=Path, required=True, help="folder for the grid shards (vgn-train --data OUT)"
    )

    show = commands.add_parser("show", help="what a data folder holds")
    show.add_argument("data", type=Path)
    return parser


def _verify(args: argparse.Namespace) -> int:
    from training.verify_recipes import verify

    if args.scenes < 1:
        raise ValueError("--scenes must be >= 1")
    started = time.perf_counter()
    report = verify(args.data, args.scenes, args.seed, args.vgn_objects, args.grids)
    for problem in report.object_problems:
        print(f"object: {problem}")
    for scene_id, reason in report.mismatches:
        print(f"mismatch: {scene_id}: {reason}")
    compared = (f"; largest difference from the stored grid {report.largest_difference} / 255 "
                f"({report.compared_with_grid} scenes compared voxel by voxel)") if report.compared_with_grid else ""  # fmt: skip
    print(f"verified {report.checked} scenes in {time.perf_counter() - started:.0f} s: "
          f"{report.matched} match ({100 * report.match_rate:.1f} %){compared}")  # fmt: skip
    return 0 if report.matched == report.checked and not report.object_problems else 1


def _pack(args: argparse.Namespace) -> int:
    from training.recipe_pack import pack_raw
    from vgn_data.dataset import RawDataset

    for entry in pack_raw(RawDataset(args.raw), args.source, args.out, limit=args.limit):
        print(f"{entry['file']}: {entry['scenes']} scenes, {entry['grasps']} grasps "
              f"({entry['positives']} positive), {entry['bytes'] / 1e6:.2f} MB")  # fmt: skip
    return _show(argparse.Namespace(data=args.out))


def render_settings(args: argparse.Namespace) -> ObservationSettings:
    """The observations ``vgn-data render`` makes: its options are ``ObservationSettings``' fields."""
    return ObservationSettings(**config_values(args, ObservationSettings))


def _render(args: argparse.Namespace) -> int:
    from sim_worker.objects import default_cache_dir
    from training.observations import render_cache
    from training.recipe_shards import RecipeFolder

    settings = render_settings(args)
    if args.workers < 1:
        raise ValueError("--workers must be >= 1")
    out = args.out or default_cache_dir() / "observations"
    total = sum(e["scenes"] for e in RecipeFolder(args.data).manifest()["shards"])
    started, done = time.perf_counter(), [0]

    def progress(count: int) -> None:
        done[0] += count
        if done[0] % 256 < count or done[0] == total:
            rate = done[0] / (time.perf_counter() - started)
            print(f"{done[0]}/{total} scenes, {rate:.2f} scenes/s", file=sys.stderr, flush=True)

    paths = render_cache(args.data, out, settings, args.workers, args.vgn_objects, progress)
    seconds = time.perf_counter() - started
    rendered = (
        f"; rendered {done[0]} scenes in {seconds:.0f} s ({done[0] / seconds:.2f} scenes/s)"
        if done[0]
        else ""
    )
    print(f"{len(paths)} cache files in {out} (settings {settings.key()}){rendered}")
    return 0


def _legacy_grids(args: argparse.Namespace) -> int:
    from training.recipe_shards import RecipeFolder
    from training.verify_recipes import grids_from_history

    migration = RecipeFolder(args.data).manifest().get("migration", {})
    files = [name for record in migration.values() for name in record.get("grid_shards", [])]
    if not files:
        raise ValueError(f"{args.data} records no migrated grid shards")
    if grids_from_history(args.data, files, args.out) is None:
        raise ValueError(f"the grid shards are not in the git history of {args.data}")
    print(f"{len(files)} grid shards in {args.out}: vgn-train --data {args.out} trains on their stored grids")
    return 0


def _show(args: argparse.Namespace) -> int:
    from training.recipe_shards import RecipeFolder

    manifest = RecipeFolder(args.data).manifest()
    shards = manifest["shards"]
    by_source: dict[str, list[int]] = {}
    for entry in shards:
        totals = by_source.setdefault(entry["source"], [0, 0, 0])
        totals[0] += entry["scenes"]
        totals[1] += entry["grasps"]
        totals[2] += entry["bytes"]
    print(
        f"{args.data}: format {manifest.get('format')}, hand {manifest.get('gripper')}, {len(shards)} shards"
    )
    for source, (scenes, grasps, size) in sorted(by_source.items()):
        print(f"  {source}: {scenes} scenes, {grasps} labels, {size / 1e6:.1f} MB")
    print(f"  total: {sum(t[0] for t in by_source.values())} scenes, "
          f"{sum(t[2] for t in by_source.values()) / 1e6:.1f} MB")  # fmt: skip
    return 0


def _migrate(args: argparse.Namespace) -> int:
    from training.migrate import MigrationJob, run_migration
    from training.shards import ShardFolder

    folder = ShardFolder(args.data)
    manifest = folder.manifest()
    if manifest.get("format") != 1:
        print(f"vgn-data: {args.data} is not a folder of grid shards (format 1)", file=sys.stderr)
        return 2
    objects = _objects_option(args.objects)
    vgn_objects = args.vgn_objects
    for source in args.source or sorted(manifest["sources"]):
        if source not in objects:
            print(f"vgn-data: give --objects {source}=DIR[,DIR] (recorded: "
                  f"{manifest['sources'][source]['objects']})", file=sys.stderr)  # fmt: skip
            return 2
        job = MigrationJob(source, manifest["sources"][source], objects[source], args.work, vgn_objects,
                           args.renderer)  # fmt: skip
        started, counts = time.perf_counter(), [0, 0]

        def progress(
            result: dict, counts: list[int] = counts, started: float = started, source: str = source
        ) -> None:
            counts[0] += 1
            counts[1] += bool(result["match"])
            if counts[0] % 100 == 0:
                print(f"{source}: {counts[0]} scenes, {counts[1]} match, "
                      f"{time.perf_counter() - started:.0f} s", file=sys.stderr, flush=True)  # fmt: skip

        run_migration(folder, job, args.workers, args.limit, progress)
        print(f"{source}: converted {counts[0]} scenes this run, {counts[1]} match")
    if args.finish:
        return _finish_migration(args, folder)
    return 0


def _finish_migration(args: argparse.Namespace, folder: object) -> int:
    from training.recipe_pack import finish_migration

    summary = finish_migration(folder, args.work, args.data)
    for source, record in summary.items():
        print(f"{source}: {record['converted']} of {record['scenes']} scenes converted; not converted: "
              f"{record['not_converted'] or 'none'}")  # fmt: skip
        for name in record["grid_shards"]:
            (args.data / name).unlink(missing_ok=True)
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run one ``vgn-data`` command; 2 for bad input."""
    args = build_parser().parse_args(argv)
    configure_logging(args.log_level)
    try:
        return {
            "migrate": _migrate,
            "verify": _verify,
            "pack": _pack,
            "render": _render,
            "legacy-grids": _legacy_grids,
            "show": _show,
        }[args.command](args)
    except (ValueError, FileNotFoundError, ShardError, RecipeError) as error:
        print(f"vgn-data: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
