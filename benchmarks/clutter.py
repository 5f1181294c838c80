r"""Clutter removal for VGN and the antipodal baseline on the same seeds, next to the paper.

    python -m benchmarks.clutter --model vgn.safetensors --rounds 100 \
        --pile-objects objects/pile/heldout --packed-objects objects/packed/heldout

Scenarios (the paper's Table 1): blocks, pile and packed with 5 objects, pile with 10. Blocks
use the procedural set, which no model trains on; give held-out object folders for pile and
packed. Every (planner, selection, scenario) gets its own results folder under ``--out``, so
an interrupted benchmark resumes and more ``--rounds`` extend it. The table (success rate and
percent cleared with 95 % Wilson intervals, planning time) is printed and written to
``--out``/table.md and table.json, and drawn as a bar chart in table.png.

The grasps asked for are the service's default answer: turn-averaged (VGN) and clearance-checked
unless its operator turned these off; ``--no-turn-average --no-clearance --no-grip`` gives the
plain answer the paper measures. What was used names the folders and labels the rows: a
scenario's folder ends in -turns, -clearance and -grip for the checks, and in -side or -random
(``--views``), -dex or -structured-light (``--sensor``), -pose (``--pose-error``), -disturbP,
-closed and -wrist for the other ways of looking. ``--gripper`` runs another hand (its folders end
in -NAME, and the service must serve that hand with a network: docs/your-gripper.md).
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import json
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from benchmarks.chart import write_chart
from benchmarks.paper import PAPER_GPD, PAPER_TABLE_1, SCENARIOS
from benchmarks.report import HEADLINE_SEED, no_grasp_cell, this_machine
from client.cli import add_check_switches, add_gripper_option, add_looking_options, add_ray_option
from client.http import VGNClient
from service.launch.embedded import EmbeddedService
from sim_worker.clear_scene import grasp_defaults, resolve_planner, run_episode
from sim_worker.clutter import ClutterConfig, looking
from sim_worker.metrics import FAILURE_CLASSES, summarize
from sim_worker.objects import DEFAULT_OBJECT_SET
from sim_worker.results import ResultsFolder
from vgn_contract.gripper_description import DEFAULT_GRIPPER
from vgn_contract.schemas import ANTIPODAL_DEFAULT_THRESHOLD, SWITCHES, GraspDefaults
from vgn_data.files import write_atomically

if TYPE_CHECKING:
    from sim_worker.ray_runner import ClutterPool, RoundProgress

DEFAULT_SCENARIOS = SCENARIOS


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line; the module docstring is its help text."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--model", help="VGN weights for an embedded service (default: the packaged model)")
    parser.add_argument("--url", help="use a running service instead of an embedded one")
    parser.add_argument("--rounds", type=int, default=100, help="rounds per scenario (default %(default)s)")
    parser.add_argument("--seed", type=int, default=HEADLINE_SEED)
    parser.add_argument(
        "--threshold", type=float, help="VGN's quality threshold (default: the model's operating threshold)"
    )
    parser.add_argument(
        "--antipodal-threshold",
        type=float,
        default=ANTIPODAL_DEFAULT_THRESHOLD,
        help="the baseline's geometric-score threshold (default %(default)s; its scores are not probabilities)",
    )
    parser.add_argument("--planners", nargs="+", choices=["vgn", "antipodal"], default=["vgn", "antipodal"])
    parser.add_argument("--selections", nargs="+", choices=["best", "random"], default=["best", "random"])
    parser.add_argument("--scenarios", nargs="+", default=DEFAULT_SCENARIOS, help="SCENE-COUNT, e.g. pile-10")
    parser.add_argument("--pile-objects", help="held-out objects for pile scenes (default: the pybullet set)")
    parser.add_argument(
        "--packed-objects", help="held-out objects for packed scenes (default: the pybullet set)"
    )
    add_looking_options(parser)
    add_gripper_option(parser)
    add_check_switches(parser, "; checked rows are labelled PLANNER+CHECK (vgn+turns for turn averaging)")
    parser.add_argument("--renderer", choices=["auto", "egl", "tiny"], default="auto")
    parser.add_argument(
        "--torch-threads",
        type=int,
        default=1,
        help="torch threads of the embedded service (default %(default)s: the simulator shares the CPU, "
        "and on a small CPU more threads than free cores slow the forward down several times)",
    )
    add_ray_option(parser)
    parser.add_argument("--workers", type=int, help="with --ray: simulator workers (default: one per CPU)")
    parser.add_argument("--out", type=Path, default=Path("results/benchmark"))
    parser.add_argument(
        "--report",
        action="store_true",
        help="run nothing: tabulate the rounds already in --out (a partial scenario shows its round count)",
    )
    return parser.parse_args(argv)


def with_service_defaults(args: argparse.Namespace, defaults: GraspDefaults | None) -> argparse.Namespace:
    """``args`` with ``--clearance``, ``--grip`` and ``--turn-average`` left out replaced by the service's
    defaults: what its ``/model`` reports or, with no service to ask (``--report``), what one started
    here would use (the ``VGN_*`` environment, else the settings' defaults). Folder names and row labels
    then say what the runs used; ``left_to_service`` names the switches left out, which the runs'
    requests leave to the service."""
    if defaults is None:
        from service.settings import Settings

        switches = Settings().model_dump(include=set(SWITCHES))
    else:
        switches = defaults.model_dump(include=set(SWITCHES))
    left = frozenset(switch for switch in SWITCHES if getattr(args, switch) is None)
    resolved = {switch: switches[switch] if switch in left else getattr(args, switch) for switch in SWITCHES}
    return argparse.Namespace(**{**vars(args), **resolved, "left_to_service": left})


def scenario_config(args: argparse.Namespace, planner: str, selection: str, scenario: str) -> ClutterConfig:
    """The clutter-removal settings of one run: ``scenario`` is
    SCENE-COUNT, and each planner gets its own threshold option."""
    scene, count = scenario.rsplit("-", 1)
    objects = {"pile": args.pile_objects, "packed": args.packed_objects}.get(scene)
    return ClutterConfig(
        scene=scene, objects=objects, object_count=int(count), rounds=args.rounds, seed=args.seed,
        threshold=args.threshold if planner == "vgn" else args.antipodal_threshold, selection=selection,
        planner=planner, renderer=args.renderer, noise=args.noise, views=args.views, clearance=args.clearance,
        grip=args.grip, sensor=args.sensor, pose_error=args.pose_error,
        turn_average=args.turn_average if planner == "vgn" else False,
        disturb=args.disturb, closed_loop=args.closed_loop, scan=args.scan, hand=args.gripper,
        left_to_service=getattr(args, "left_to_service", frozenset()),
    )  # fmt: skip


def combinations(args: argparse.Namespace) -> Iterator[tuple[str, str, str, Path]]:
    """(planner, selection, scenario, results folder) for every run the arguments ask for."""
    for planner in args.planners:
        for selection in args.selections:
            for scenario in args.scenarios:
                suffix = ("-noise" if args.noise else "") + (f"-{args.views}" if args.views != "six" else "")
                suffix += (f"-{args.sensor}" if args.sensor else "") + ("-pose" if args.pose_error else "")
                suffix += "-turns" if args.turn_average and planner == "vgn" else ""
                suffix += "-clearance" if args.clearance else ""
                suffix += "-grip" if args.grip else ""
                suffix += (f"-disturb{args.disturb:g}" if args.disturb else "") + (
                    "-closed" if args.closed_loop else ""
                )
                suffix += "-wrist" if args.scan == "wrist" else ""
                suffix += f"-{args.gripper.name}" if args.gripper.name != DEFAULT_GRIPPER else ""
                yield planner, selection, scenario, args.out / f"{planner}-{selection}-{scenario}{suffix}"


def table_row(planner: str, selection: str, scenario: str, config: dict, summary: dict) -> dict:
    """One line of the results table: the run's identity (VGN with turn averaging is ``vgn+turns``,
    a planner with the clearance check ``PLANNER+clearance``, with the grip check ``PLANNER+grip``),
    its threshold and model (and the one-view network, where the service had one), and its summary."""
    planner += "+turns" if config.get("turn_average") else ""
    planner += "+clearance" if config.get("clearance") else ""
    planner += "+grip" if config.get("grip") else ""
    one_view = {"one_view_model": config["one_view_model"]} if config.get("one_view_model") else {}
    return {"planner": planner, "selection": selection, "scenario": scenario,
            "threshold": config["threshold"], "model": config["model"], **one_view, **summary}  # fmt: skip


def run_all(
    args: argparse.Namespace,
    vgn: VGNClient | None,
    ray_pool: ClutterPool | None = None,
    progress: RoundProgress | None = None,
) -> list[dict]:
    """Every combination through ``vgn`` in this process, or over the Ray workers of ``ray_pool``
    (``progress``: one progress bar over the rounds of all combinations)."""
    rows = []
    for planner, selection, scenario, folder in combinations(args):
        config = scenario_config(args, planner, selection, scenario)
        if ray_pool is not None:
            config = ray_pool.prepare(config, resolve_planner)[2]
            results = ResultsFolder(folder, config.as_json())
            progress.bar.update(len(results.finished_rounds() & set(range(config.rounds))))
            summary = ray_pool.run(config, results, progress)
        else:
            config = resolve_planner(config, vgn)
            summary = run_episode(config, vgn, ResultsFolder(folder, config.as_json()))
        rows.append(
            {
                **table_row(planner, selection, scenario, config.as_json(), summary),
                "measured": measured_on(folder, record=True),
            }
        )
        print(
            f"{planner:9s} {selection:6s} {scenario:9s} {format_row(rows[-1])}", file=sys.stderr, flush=True
        )
    return rows


def report_all(args: argparse.Namespace) -> list[dict]:
    """Rows for every (planner, selection, scenario) folder already in ``args.out``."""
    rows = []
    for planner, selection, scenario, folder in combinations(args):
        if not (folder / "config.json").is_file():
            continue
        config = json.loads((folder / "config.json").read_text())
        results = ResultsFolder(folder, config)
        rows.append(
            table_row(planner, selection, scenario, config, summarize(results.rounds, results.grasps))
            | {"measured": measured_on(folder)}
        )
    return rows


def measured_on(folder: Path, record: bool = False) -> dict:
    """When and where a results folder's rounds ran, as its ``measured.json`` says: with ``record``
    (this process ran them) today's date (UTC) and this machine's CPU model and core count are
    written there first. A folder from before that was recorded gets its rounds.csv's date and no machine."""
    path = folder / "measured.json"
    if record:
        write_atomically(path, json.dumps(this_machine()) + "\n")
    if path.is_file():
        return json.loads(path.read_text())
    rounds = folder / "rounds.csv"
    when = (
        datetime.datetime.fromtimestamp(rounds.stat().st_mtime, datetime.timezone.utc)
        if rounds.is_file()
        else None
    )
    return {"date": when.date().isoformat() if when else None, "cpu": None, "cores": None}


def no_results(out: Path) -> int:
    """Say that ``--report`` found nothing for its options, and which runs ``out`` does hold; exit 1."""
    held = sorted(config.parent.name for config in out.glob("*/config.json"))
    print(
        f"no results for these options in {out}, table left as it was"
        + (f"; it holds {', '.join(held)} (a folder suffix -noise or -side needs that option; one without "
           "-turns, -clearance or -grip needs --no-turn-average, --no-clearance or --no-grip, unless the defaults are off)"
           if held else ""),
        file=sys.stderr,
    )  # fmt: skip
    return 1


def format_row(row: dict) -> str:
    """One run on one line, for progress: rounds, success and cleared with intervals, planning time."""

    def pct(key: str) -> str:
        low, high = row[f"{key}_ci95"]
        return f"{row[key]:5.1f} ({low:.1f}-{high:.1f})" if row[key] is not None else "    -"

    planning = row["planning_ms"]["p50"] if row.get("planning_ms") else float("nan")
    return (
        f"{row['rounds']:4d} rounds  success {pct('success_rate')}  cleared {pct('percent_cleared')}  "
        f"no grasp offered {no_grasp_cell(row)} % of rounds  planning p50 {planning:.0f} ms"
    )


def objects_text(args: argparse.Namespace) -> str:
    """Which objects the run's pile and packed scenes drop, for the settings line: a folder by its
    name, a named set by its name, and the pybullet set, named or by default, as ``pybullet_data``
    (a source no training scene draws from), as the report knows it. Blocks say nothing."""
    folders = {"pile": args.pile_objects, "packed": args.packed_objects}
    scenes = [scene for scene in folders if any(s.rsplit("-", 1)[0] == scene for s in args.scenarios)]
    names = []
    for scene in scenes:
        chosen = str(folders[scene] or DEFAULT_OBJECT_SET[scene])
        names.append(f"{scene} objects {'pybullet_data' if chosen == 'pybullet' else Path(chosen).name}")
    return ", ".join(names)


def failures_cell(row: dict) -> str:
    """Failed attempts by class, e.g. ``12 / 3 / 1 / 0``."""
    outcomes = row.get("outcomes") or {}
    return " / ".join(str(outcomes.get(key, 0)) for key, _ in FAILURE_CLASSES)


def markdown_table(rows: list[dict], args: argparse.Namespace) -> str:
    """The results beside the paper's VGN and GPD figures, as a Markdown table with a line on the settings."""
    objects = objects_text(args)
    lines = [
        f"seed {args.seed}, rounds per scenario {'as listed' if args.report else args.rounds}, "
        f"{looking(args.views, args.scan)}{', depth noise' if args.noise else ''}"
        f"{f', {args.sensor} sensor' if args.sensor else ''}{', camera pose error' if args.pose_error else ''}"
        f"{f', disturbances p={args.disturb:g}' if args.disturb else ''}{', closed loop' if args.closed_loop else ''}"
        f"{f', {objects}' if objects else ''}"
        f"{f', gripper {args.gripper.name}' if args.gripper.name != DEFAULT_GRIPPER else ''}",
        "",
        "| planner | selection | threshold | scenario | rounds | success % (95 % CI) | cleared % (95 % CI) "
        "| no grasp offered % of rounds "
        "| failures: approach contact / nothing held / slipped / collision | planning p50 ms | paper VGN ε=0.9 | paper GPD |",
        "| --- | --- | ---: | --- | ---: | --- | --- | ---: | --- | ---: | --- | --- |",
    ]
    for row in rows:
        paper, gpd = PAPER_TABLE_1.get(row["scenario"]), PAPER_GPD.get(row["scenario"])
        success, cleared = row["success_rate"], row["percent_cleared"]
        planning = row["planning_ms"]["p50"] if row.get("planning_ms") else None
        lines.append(
            f"| {row['planner']} | {row['selection']} | {row['threshold']} | {row['scenario']} | {row['rounds']} | "
            f"{'-' if success is None else f'{success:.1f}'} ({row['success_rate_ci95'][0]:.1f}-{row['success_rate_ci95'][1]:.1f}) | "
            f"{'-' if cleared is None else f'{cleared:.1f}'} ({row['percent_cleared_ci95'][0]:.1f}-{row['percent_cleared_ci95'][1]:.1f}) | "
            f"{no_grasp_cell(row)} | {failures_cell(row)} | "
            f"{'-' if planning is None else f'{planning:.0f}'} | {f'{paper[0]} / {paper[1]}' if paper else '-'} | "
            f"{f'{gpd[0]} / {gpd[1]}' if gpd else '-'} |"
        )  # fmt: skip
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Run (or with ``--report`` only tabulate) every combination; the exit status for the shell."""
    args = parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    if args.report:
        rows = report_all(with_service_defaults(args, None))
        if not rows:  # never replace a table with an empty one: the options likely do not match
            return no_results(args.out)
        return write_table(rows, args)
    if args.ray is not None:
        return run_on_ray(args)
    with contextlib.ExitStack() as stack:
        url = (
            args.url
            or stack.enter_context(
                EmbeddedService(
                    model=args.model,
                    log_path=args.out / "service.log",
                    env={"VGN_TORCH_THREADS": str(args.torch_threads)},
                )
            ).url
        )
        vgn = stack.enter_context(VGNClient(url, timeout=120.0))
        readiness = vgn.ready()
        if "vgn" in args.planners and not readiness.ready:
            print(f"error: the vgn planner cannot run: {readiness.detail} (pass --model)", file=sys.stderr)
            return 2
        rows = run_all(with_service_defaults(args, grasp_defaults(None, vgn)), vgn)
    return write_table(rows, args)


def run_on_ray(args: argparse.Namespace) -> int:
    """The benchmark with its rounds on Ray workers (sim_worker.ray_runner), one embedded
    service per node unless ``--url``."""
    from sim_worker.ray_runner import ClutterPool, RayMissing, RoundProgress

    service = {"model": args.model, "env": {"VGN_TORCH_THREADS": str(args.torch_threads)}}
    try:
        pool = ClutterPool(args.ray, args.workers, args.url, None, service)
    except (RayMissing, ConnectionError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    try:
        ready, detail, defaults = pool.prepare(
            scenario_config(args, "antipodal", "best", args.scenarios[0]), grasp_defaults
        )
        if "vgn" in args.planners and not ready:
            print(f"error: the vgn planner cannot run: {detail} (pass --model)", file=sys.stderr)
            return 2
        args = with_service_defaults(args, defaults)
        from tqdm import tqdm

        with tqdm(total=args.rounds * len(list(combinations(args))), unit="round", file=sys.stderr) as bar:
            rows = run_all(args, None, pool, RoundProgress(bar))
    finally:
        pool.close()
    return write_table(rows, args)


def write_table(rows: list[dict], args: argparse.Namespace) -> int:
    """Print the table and write it as table.md, table.json and the table.png chart under ``--out``."""
    table = markdown_table(rows, args)
    write_atomically(args.out / "table.md", table)
    write_atomically(args.out / "table.json", json.dumps(rows, indent=2) + "\n")
    print(table)
    chart = write_chart(rows, PAPER_TABLE_1, PAPER_GPD, args.out / "table.png")
    if chart:
        print(f"chart: {chart}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
