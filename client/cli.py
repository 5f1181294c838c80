"""vgn-client: talk to a grasp-planning service, or start one.

    vgn-client serve                      # run the service on 127.0.0.1:8000 (needs the service extra)
    vgn-client serve --replicas 2         # two service processes behind HAProxy on the same ports
    vgn-client status                     # health, readiness and model of a running service
    vgn-client sessions                   # list live sessions
    vgn-client grasps SESSION --top 5     # best grasps of a session as a table
    vgn-client view SESSION --out v.html  # save the 3D session viewer (or open it in a browser)
    vgn-client clear-scene --sim          # simulated clutter removal (needs the service and sim extras)

--url (or VGN_URL, grpc://HOST:PORT for gRPC) picks the service and --api-key (or VGN_API_KEY)
its key; --log-level sets what the libraries report on stderr.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import sys
import tempfile
import webbrowser
from collections.abc import Sequence
from pathlib import Path
from types import UnionType
from typing import Literal, get_args, get_origin

import httpx

from client.connect import connect, is_grpc_url
from client.extras import missing_extra
from client.http import DEFAULT_URL, InvalidRequest, VGNClient, VGNError
from client.log_level import add_log_level_option, configure_logging
from vgn_contract.gripper_description import (
    DEFAULT_GRIPPER,
    GripperDescription,
    GripperDescriptionError,
    builtin_grippers,
    load_gripper,
)
from vgn_contract.schemas import ANTIPODAL_DEFAULT_THRESHOLD, SWITCHES, GraspQuery


def add_looking_options(parser: argparse.ArgumentParser) -> None:
    """How a clutter-removal run sees and disturbs the scene: ``--views``, ``--noise``, ``--sensor``,
    ``--pose-error``, ``--disturb``, ``--closed-loop`` and ``--scan``. clear-scene and the
    benchmark (``benchmarks.clutter``) declare them here, once."""
    parser.add_argument(
        "--views",
        choices=["six", "side", "random"],
        default="six",
        help="six views on a circle (VGN), a single fixed side view (GIGA), or a single view drawn anew for "
        "every look (a random point of the upper hemisphere)",
    )
    parser.add_argument(
        "--noise", action="store_true", help="Dex-Net depth noise on every view (robustness runs)"
    )
    parser.add_argument("--sensor", choices=["dex", "structured-light"],
                        help="a depth sensor's errors on every view: Dex-Net noise, or a structured-light camera's "
                        "(distance-squared noise, shadows, dropouts at edges and steep surfaces, flying pixels, 1 mm "
                        "steps); see docs/sensors.md")  # fmt: skip
    parser.add_argument("--pose-error", action="store_true",
                        help="report each view's camera pose with a random error (5 mm, 1 degree), as a real arm would")  # fmt: skip
    parser.add_argument("--disturb", type=float, default=0.0, metavar="P",
                        help="with probability P per attempt, push the aimed-at object a few cm (or drop it onto the "
                        "pile) during the approach, after the plan (default 0); see docs/closed-loop.md")  # fmt: skip
    parser.add_argument("--closed-loop", action="store_true",
                        help="keep looking while approaching (fixed cameras at 10 Hz, the hand filtered out, a session "
                        "that forgets), re-plan, and re-target or give up when the aimed-at grasp is gone")  # fmt: skip
    parser.add_argument("--scan", choices=["fixed", "wrist"], default="fixed",
                        help="look with the fixed --views, or with a wrist camera circling the scene (three frames a third "
                        "of a turn apart), planning after every frame and stopping once the best grasp is stable "
                        "(default %(default)s)")  # fmt: skip


def gripper_argument(text: str) -> GripperDescription:
    """``--gripper``'s value: a built-in hand by name, or the description file at a path ending in ``.json``."""
    try:
        return load_gripper(text)
    except GripperDescriptionError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def add_gripper_option(parser: argparse.ArgumentParser) -> None:
    """``--gripper NAME|FILE``: the simulated hand and the hand the service's session plans for.
    clear-scene, generate-data and the benchmark declare it here, once."""
    parser.add_argument("--gripper", type=gripper_argument, default=DEFAULT_GRIPPER, metavar="NAME|FILE",
                        help=f"the simulated hand: a built-in one ({', '.join(builtin_grippers())}) or a gripper "
                        "description file (.json, docs/your-gripper.md); a session that plans grasps for the run "
                        "names it to the service; default %(default)s")  # fmt: skip


def add_query_options(parser: argparse.ArgumentParser, max_grasps: int) -> None:
    """One flag per grasp query option (``vgn_contract.schemas.GraspQuery``), derived from its fields:
    choices, types and help as the schema declares them; the switches as :func:`add_check_switches`.
    ``max_grasps`` is the command's default (``--top`` is its older name)."""
    for name, field in GraspQuery.model_fields.items():
        if name in SWITCHES:
            continue  # add_check_switches adds them, as it does for clear-scene and the benchmark
        flag, kind = "--" + name.replace("_", "-"), _flag_type(field.annotation)
        names = (flag, "--top") if name == "max_grasps" else (flag,)
        default = max_grasps if name == "max_grasps" else None  # None: the service's default
        if get_origin(kind) is Literal:
            parser.add_argument(
                *names, dest=name, choices=get_args(kind), default=default, help=field.description
            )
        else:
            parser.add_argument(*names, dest=name, type=kind, default=default, help=field.description)
    add_check_switches(parser)


def query_options(args: argparse.Namespace) -> dict:
    """The grasp query options given on the command line (:func:`add_query_options`)."""
    return {name: getattr(args, name) for name in GraspQuery.model_fields if getattr(args, name) is not None}


def _flag_type(annotation: object) -> object:
    """The type a flag parses to: ``X`` of ``X | None``."""
    kinds = [kind for kind in get_args(annotation) if kind is not type(None)]
    return kinds[0] if get_origin(annotation) is UnionType and len(kinds) == 1 else annotation


def add_check_switches(parser: argparse.ArgumentParser, recorded: str = "") -> None:
    """``--clearance/--no-clearance``, ``--grip/--no-grip`` and ``--turn-average/--no-turn-average``,
    derived from GraspQuery's fields like every query flag, help included; left out, each is ``None``:
    the service's default, which is its best answer. clear-scene and the benchmark take only these,
    which is why they are added here rather than in :func:`add_query_options`' loop."""
    for name in SWITCHES:
        parser.add_argument(
            "--" + name.replace("_", "-"),
            dest=name,
            action=argparse.BooleanOptionalAction,
            help=GraspQuery.model_fields[name].description + recorded,
        )


def _add_connection(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--url",
        default=os.environ.get("VGN_URL", DEFAULT_URL),
        help="service address, http://... or grpc://HOST:PORT (env VGN_URL; default %(default)s)",
    )
    parser.add_argument(
        "--api-key",
        default=os.environ.get("VGN_API_KEY"),
        help="API key, if the service requires one (env VGN_API_KEY)",
    )


def build_parser() -> argparse.ArgumentParser:
    """The ``vgn-client`` command line: one subcommand per task, each with its own options; the
    module docstring, written as plain text, is its help."""
    parser = argparse.ArgumentParser(
        prog="vgn-client", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    serve = commands.add_parser(
        "serve",
        help="run the service (uvicorn service.app:app), or a fleet of replicas behind HAProxy",
        description="Run the service. With --replicas N, run N service processes on loopback ports of their "
        "own behind HAProxy, which listens on --host/--port (HTTP) and --grpc-port and routes each session to "
        "one replica (docs/fleet.md); a replica that dies is started again. Ctrl-C or SIGTERM stops them all.",
    )
    serve.add_argument("--host", default="127.0.0.1",
                       help="address to listen on for HTTP, and for gRPC unless VGN_GRPC_HOST names another "
                       "(0.0.0.0: every interface; default %(default)s)")  # fmt: skip
    serve.add_argument("--port", type=int, default=8000, help="HTTP port (default %(default)s)")
    serve.add_argument("--model", help="weights file (sets VGN_MODEL)")
    serve.add_argument("--grpc-port", type=int, help="gRPC port (sets VGN_GRPC_PORT; default 50051, 0: off)")
    serve.add_argument(
        "--replicas", type=int, help="run this many service processes behind HAProxy (needs haproxy)"
    )

    status = commands.add_parser("status", help="health, readiness and model of a service")
    _add_connection(status)

    sessions = commands.add_parser("sessions", help="list live sessions")
    _add_connection(sessions)

    grasps = commands.add_parser("grasps", help="plan grasps on a session and print them")
    _add_connection(grasps)
    grasps.add_argument("session_id")
    grasps.add_argument("--json", action="store_true", help="print the raw JSON answer")
    add_query_options(grasps, max_grasps=10)

    view = commands.add_parser(
        "view",
        help="the 3D session viewer: save it as a self-contained HTML file, or open it in a browser",
        description="Fetch the session viewer (fused surface, workspace and best grasps in 3D, with a grasp "
        "list) as one offline HTML file. With --out it is saved there; without, it is written to a "
        "temporary file and opened in the default browser. The file is a snapshot; the page served at "
        "/sessions/SESSION/view refreshes itself as frames arrive.",
    )
    _add_connection(view)
    view.add_argument("session_id")
    view.add_argument("--out", help="save the page to this file instead of opening it")
    add_query_options(view, max_grasps=20)

    _add_clear_scene(commands)
    _add_generate_data(commands)
    # On each subcommand rather than on vgn-client itself, so it goes after the command name like
    # every other option (a top-level default would be overwritten by a subcommand's anyway).
    for command in commands.choices.values():
        add_log_level_option(command)
    return parser


def _add_generate_data(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    gen = commands.add_parser(
        "generate-data",
        help="label grasps in simulation through the service (VGN's raw dataset layout)",
        description="Generate training data as VGN: each scene gets a session, 1-6 random views are posted, "
        "the fused cloud with normals is read back, and 120 grasp points are labelled by trying 6 yaws each in "
        "PyBullet. Output: DIR/setup.json, DIR/grasps.csv, DIR/scenes/<id>.npz and each scene's recipe "
        "(objects and settled poses) DIR/recipes/<id>.npz. A rerun resumes.",
    )
    _add_sim_options(gen)
    add_gripper_option(gen)
    gen.add_argument("--scene", choices=["pile", "packed"], default="pile")
    gen.add_argument(
        "--objects",
        action="append",
        help="object set ('blocks', 'shapes', 'pybullet') or URDF folder; repeat to mix (default: the scene's set)",
    )
    gen.add_argument("--scenes", type=int, default=10, help="scenes to generate (default %(default)s)")
    gen.add_argument("--first", type=int, default=0,
                     help="index of the first scene (default 0): scenes --first .. --first + --scenes - 1")  # fmt: skip
    gen.add_argument("--workers", type=int,
                     help="simulator processes (default 1; with --ray, one per CPU of the cluster)")  # fmt: skip
    gen.add_argument("--out", required=True, help="dataset folder (created or resumed)")
    gen.add_argument("--seed", type=int, default=0, help="scene i uses (seed, i); ids are s<seed>-<i>")
    gen.add_argument("--points", type=int, default=120, help="grasp points per scene (default %(default)s)")
    gen.add_argument("--noise", action="store_true", help="depth noise on the rendered views of every scene")
    gen.add_argument(
        "--noise-fraction",
        type=float,
        default=0.0,
        help="share of scenes with depth noise (default %(default)s)",
    )
    gen.add_argument(
        "--side-view-fraction",
        type=float,
        default=0.0,
        help="share of scenes seen from one side view instead of 1-6 views from above (default %(default)s)",
    )
    gen.add_argument(
        "--answer-grasps",
        type=int,
        default=0,
        metavar="K",
        help="also label up to K of the service's own plain answers per scene (network only, drawn at random "
        "among those reaching --answer-threshold), each tried once as answered: the network's mistakes "
        "become labels where it makes them (default 0: none)",
    )
    gen.add_argument("--answer-threshold", type=float, default=0.5, metavar="T",
                     help="quality the labelled answers must reach (default %(default)s)")  # fmt: skip

    clean = commands.add_parser(
        "clean-data",
        help="drop grasps outside the valid region and balance positives/negatives into a new folder",
    )
    clean.add_argument("source", help="raw dataset folder (kept unchanged)")
    clean.add_argument("destination", help="new dataset folder")
    clean.add_argument("--seed", type=int, default=0)


def _add_clear_scene(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    clear = commands.add_parser(
        "clear-scene",
        help="clutter removal: grasp objects off a table until it is clear",
        description="Clutter removal as in the VGN paper. With --sim a PyBullet world plays the robot: "
        "it renders depth views, posts them to the service through this client, executes the best grasp "
        "and repeats until the table is clear, no grasp is found, or two grasps in a row fail. "
        "Without --url an embedded service is started on a free port and stopped at the end.",
    )
    _add_sim_options(clear)
    add_gripper_option(clear)
    clear.add_argument("--model", help="weights for the embedded service (sets its VGN_MODEL)")
    clear.add_argument("--scene", choices=["blocks", "pile", "packed"], default="blocks",
                       help="what the table holds: blocks, a pile of objects, or objects packed upright")  # fmt: skip
    clear.add_argument(
        "--objects",
        help="object set: 'blocks', 'shapes', 'pybullet' or a folder of URDFs (default: the scene's built-in set)",
    )
    clear.add_argument("--object-count", type=int, default=5, help="objects per round (default %(default)s)")
    clear.add_argument("--rounds", type=int, default=1, help="rounds to run (default %(default)s)")
    clear.add_argument("--workers", type=int, help="with --ray: simulator workers (default: one per CPU)")
    clear.add_argument("--seed", type=int, default=1, help="scene seed; round r uses (seed, r)")
    clear.add_argument(
        "--threshold",
        type=float,
        help="grasp quality threshold (default: the model's operating threshold, from its card; "
        f"{ANTIPODAL_DEFAULT_THRESHOLD} for --planner antipodal)",
    )
    clear.add_argument(
        "--selection",
        choices=["best", "random"],
        default="best",
        help="execute the best grasp, or a random one above threshold (as the paper)",
    )
    clear.add_argument("--planner", choices=["vgn", "antipodal"], default="vgn",
                       help="the VGN network, or the service's geometric antipodal baseline (no model needed)")  # fmt: skip
    add_looking_options(clear)
    add_check_switches(clear, " (what was used is recorded in config.json)")
    clear.add_argument(
        "--results",
        help="results folder (default results/clear-scene-SCENE-seedSEED); an interrupted run resumes there",
    )
    clear.add_argument(
        "--save-images", action="store_true", help="write a PNG per attempt into the results folder"
    )


def _status(vgn: VGNClient) -> int:
    vgn.health()
    readiness = vgn.ready()
    model = vgn.model()
    print(f"service   {vgn.url}: up")
    print(f"ready     {readiness.ready} ({readiness.detail})")
    print(f"model     {model.model_id or '-'} from {model.source or '-'} on {model.device}")
    if model.one_view is not None:  # answers on volumes fused from one frame
        print(f"one-view  {model.one_view.model_id} from {model.one_view.source}")
    for hand in model.hand_models:  # answers every session of its hand
        print(f"hand      {hand.gripper}: {hand.model_id} from {hand.source}")
    return 0 if readiness.ready else 1


def _sessions(vgn: VGNClient) -> int:
    listing = vgn.sessions()
    print(f"{len(listing.sessions)} of at most {listing.max_sessions} sessions")
    for s in listing.sessions:
        print(
            f"  {s.session_id:34s} frames {s.frame_count:4d}  size {s.workspace.size:.3f} m"
            f"  resolution {s.workspace.resolution}"
        )
    return 0


def _grasps(vgn: VGNClient, args: argparse.Namespace) -> int:
    result = vgn.grasps(args.session_id, **query_options(args))
    if args.json:
        print(result.model_dump_json(indent=2))
        return 0
    dropped = (
        "" if result.workspace_dropped is None else f", {result.workspace_dropped} outside the workspace"
    )
    dropped += (
        "" if result.clearance_dropped is None else f", {result.clearance_dropped} dropped by clearance"
    )
    dropped += "" if result.grip_dropped is None else f", {result.grip_dropped} dropped by grip"
    print(
        f"{len(result.grasps)} grasps in {result.planning_ms:.1f} ms (model {result.model}, "
        f"{result.frame_count} frames{dropped})"
    )
    print(f"{'#':>3} {'quality':>7} {'x':>7} {'y':>7} {'z':>7} {'width':>6}  approach")
    for rank, g in enumerate(result.grasps, 1):
        x, y, z = g.position
        approach = ", ".join(f"{a:+.2f}" for a in g.approach)
        print(f"{rank:>3} {g.quality:7.3f} {x:7.3f} {y:7.3f} {z:7.3f} {g.width:6.3f}  [{approach}]")
    return 0


def _view(vgn: VGNClient, args: argparse.Namespace) -> int:
    options = query_options(args)
    try:
        page = vgn.view_page(args.session_id, **options)
    except ValueError as error:  # the options broke GraspQuery's rules before anything was sent
        print(f"error: {error}", file=sys.stderr)
        return 2
    if args.out:
        Path(args.out).write_text(page, encoding="utf-8")
        print(f"wrote {args.out}")
        return 0
    with tempfile.NamedTemporaryFile(
        "w", suffix=".html", prefix="vgn-view-", delete=False, encoding="utf-8"
    ) as file:
        file.write(page)
    print(f"wrote {file.name}")
    if not webbrowser.open(Path(file.name).as_uri()):
        print("no browser could be started here; open the file above in one", file=sys.stderr)
    return 0


#: ``serve`` starts the server (one process, or a fleet behind HAProxy): it lives beside the server it
#: starts, in the launch package, which needs no more than this one to import.
SERVE_COMMAND = "service.launch.serve"
#: The simulator commands live in sim_worker (they import pybullet); this is where each one runs.
SIM_COMMANDS = {"clear-scene": "sim_worker.clear_scene", "generate-data": "sim_worker.generate_data"}
#: The dataset commands belong to vgn_data (which builds on this package, so it is never imported
#: here); numpy only, so they run on the light install too.
DATA_COMMANDS = {"clean-data": "vgn_data.clean_data"}


def _run_sim_command(args: argparse.Namespace) -> int:
    """Simulator commands load only when they run, so a robot-side install without the sim
    extra keeps every other command."""
    if not args.sim:
        print(f"error: {args.command} runs in simulation only so far: add --sim", file=sys.stderr)
        return 2
    try:
        module = importlib.import_module(SIM_COMMANDS[args.command])
    except ImportError as error:
        then = " (and the service extra for the embedded service, or point --url at a running one)"
        print(f"error: {missing_extra(f'{args.command} --sim', 'sim', error, then)}", file=sys.stderr)
        return 2
    return module.run(args)


def _add_sim_options(parser: argparse.ArgumentParser) -> None:
    """Options every simulator command shares."""
    parser.add_argument("--sim", action="store_true", help="run in simulation (the only mode so far)")
    parser.add_argument("--url", default=os.environ.get("VGN_URL"),
                        help="service address (env VGN_URL); when absent, an embedded service is started")  # fmt: skip
    parser.add_argument("--api-key", default=os.environ.get("VGN_API_KEY"),
                        help="the service's API key, if it requires one (env VGN_API_KEY)")  # fmt: skip
    parser.add_argument("--renderer", choices=["auto", "egl", "tiny"], default="auto",
                        help="PyBullet renderer: EGL when it loads, else TinyRenderer (same depth)")  # fmt: skip
    add_ray_option(parser)


def add_ray_option(parser: argparse.ArgumentParser) -> None:
    """``--ray [ADDRESS]``: absent runs in local processes, bare starts a local Ray instance."""
    parser.add_argument("--ray", nargs="?", const="local", metavar="ADDRESS",
                        help="spread the work over Ray workers: a local Ray instance, or 'auto' / an address "
                        "to join a running cluster (needs the ray extra)")  # fmt: skip


def main(argv: Sequence[str] | None = None) -> int:
    """Run one ``vgn-client`` command. Exit status: 0 done, 1 the service refused, is not ready or cannot be
    reached, 2 a usage error or a missing extra."""
    args = build_parser().parse_args(argv)
    configure_logging(args.log_level)
    if args.command == "serve":
        return importlib.import_module(SERVE_COMMAND).run(args)
    if args.command in SIM_COMMANDS:
        return _run_sim_command(args)
    if args.command in DATA_COMMANDS:
        return importlib.import_module(DATA_COMMANDS[args.command]).run(args)
    if args.command == "view" and is_grpc_url(args.url):
        print(
            "error: the session viewer is an HTML page served over HTTP only; give the service's "
            "http:// URL (the same sessions are reachable over both front ends)",
            file=sys.stderr,
        )
        return 2
    try:
        with connect(args.url, api_key=args.api_key) as vgn:
            if args.command == "status":
                return _status(vgn)
            if args.command == "sessions":
                return _sessions(vgn)
            if args.command == "view":
                return _view(vgn, args)
            return _grasps(vgn, args)
    except InvalidRequest as error:  # refused here, before anything was sent
        print(f"error: {error}", file=sys.stderr)
        return 2
    except VGNError as error:
        detail = error.detail if isinstance(error.detail, str) else json.dumps(error.detail)
        print(f"error: the service answered {error.status}: {detail}", file=sys.stderr)
        return 1
    except ImportError as error:  # a grpc:// URL without the grpc extra
        print(f"error: {error}", file=sys.stderr)
        return 2
    except (httpx.TransportError, ConnectionError, TimeoutError) as error:
        print(f"error: cannot reach the service at {args.url}: {error}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
