"""``vgn-client clear-scene --sim``: the simulator against a (possibly embedded) service.

``client.cli`` imports this module only when the command runs, so the robot-side client
never needs pybullet.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import sys
from collections.abc import Callable
from pathlib import Path

from client.connect import connect
from client.embedded import EmbeddedService
from client.http import VGNClient, VGNError
from client.schemas import ANTIPODAL_DEFAULT_THRESHOLD
from sim_worker.clutter import ClutterConfig, ClutterRemoval
from sim_worker.metrics import summary_table
from sim_worker.results import ResultsFolder, RoundRecord


def resolve_planner(config: ClutterConfig, vgn: VGNClient) -> ClutterConfig:
    """``config`` with the planner's identity filled in: the weights' id (a resume with other
    weights is refused), and the threshold, turn averaging, clearance and grip checks actually used
    when not given (the service's defaults), so that config.json records what was done."""
    model = vgn.model()
    runtime = model.runtime or {}
    clearance = service_default(config.clearance, runtime, "clearance")
    grip = service_default(config.grip, runtime, "grip")
    if config.planner == "vgn":
        threshold = model.threshold if config.threshold is None else config.threshold
        turns = service_default(config.turn_average, runtime, "turn_average")
        checked = clearance or grip
        floor = runtime.get("fallback_threshold") if config.threshold is None and checked else None
        return dataclasses.replace(
            config,
            model=model.model_id,
            threshold=threshold,
            fallback_threshold=floor if floor is not None and floor < threshold else None,
            turn_average=turns,
            clearance=clearance,
            grip=grip,
        )
    threshold = ANTIPODAL_DEFAULT_THRESHOLD if config.threshold is None else config.threshold
    return dataclasses.replace(
        config, model="antipodal", threshold=threshold, turn_average=False, clearance=clearance, grip=grip
    )


def run_episode(
    config: ClutterConfig,
    vgn: VGNClient,
    results: ResultsFolder,
    image_dir: Path | None = None,
    progress: Callable[[RoundRecord], None] | None = None,
) -> dict:
    """Run the rounds of ``config`` that ``results`` does not hold yet through ``vgn``, then close
    the episode (its service session and simulator) even when a round fails; returns the summary
    over every finished round. clear-scene, the benchmark and a trained model's evaluation all run
    their rounds here."""
    episode = ClutterRemoval(config, vgn, results, image_dir)
    try:
        return episode.run(progress)
    finally:
        episode.close()


def service_default(choice: bool | None, runtime: dict, switch: str) -> bool:
    """``choice``, or when ``None`` the default the service reports in its ``/model`` runtime;
    a service from before that default did not apply the option to requests that do not say."""
    return bool(runtime.get(switch, False)) if choice is None else choice


def service_runtime(config: ClutterConfig, vgn: VGNClient) -> dict:
    """The service's ``/model`` runtime, with its defaults; a ``resolve`` for Ray's
    ``ClutterPool.prepare`` (``config`` is not used), importable on every worker."""
    return vgn.model().runtime or {}


def run(args: argparse.Namespace) -> int:
    """``vgn-client clear-scene --sim``: rounds of clutter removal,
    resumed from the results folder; returns the exit status."""
    config = ClutterConfig(
        scene=args.scene,
        objects=args.objects,
        object_count=args.object_count,
        rounds=args.rounds,
        seed=args.seed,
        threshold=args.threshold,
        views=args.views,
        selection=args.selection,
        noise=args.noise,
        sensor=getattr(args, "sensor", None),
        pose_error=getattr(args, "pose_error", False),
        planner=args.planner,
        renderer=args.renderer,
        clearance=getattr(args, "clearance", None),
        grip=getattr(args, "grip", None),
        turn_average=getattr(args, "turn_average", None),
        disturb=getattr(args, "disturb", 0.0),
        closed_loop=getattr(args, "closed_loop", False),
        scan=getattr(args, "scan", "fixed"),
    )
    results_dir = Path(args.results or f"results/clear-scene-{args.scene}-seed{args.seed}")
    results_dir.mkdir(parents=True, exist_ok=True)
    if getattr(args, "ray", None) is not None:  # the rounds spread over a Ray cluster instead
        from sim_worker.ray_runner import clear_scene_on_ray

        return clear_scene_on_ray(args, config, results_dir, resolve_planner)
    with contextlib.ExitStack() as stack:
        url = args.url
        if url is None:
            print("starting an embedded service ...", file=sys.stderr)
            try:
                service = EmbeddedService(model=args.model, log_path=results_dir / "service.log")
                url = stack.enter_context(service).url
            except (RuntimeError, TimeoutError) as error:
                print(f"error: {error}", file=sys.stderr)
                return 2
        vgn = stack.enter_context(connect(url, api_key=args.api_key))
        readiness = vgn.ready()
        if not readiness.ready and config.planner == "vgn":
            print(
                f"error: the service at {url} cannot plan: {readiness.detail} (pass --model PATH)",
                file=sys.stderr,
            )
            return 2
        # The weights are part of the run's identity: a resume with other weights is refused.
        config = resolve_planner(config, vgn)
        try:
            results = ResultsFolder(results_dir, config.as_json())
        except ValueError as error:
            print(f"error: {error}", file=sys.stderr)
            return 2
        try:
            summary = _run(config, vgn, results, results_dir / "images" if args.save_images else None)
        except VGNError as error:
            print(f"error: the service answered {error}", file=sys.stderr)
            return 1
    print(
        f"\nclear-scene --sim: {config.scene}, {config.object_count} objects, "
        f"{config.looking}, {config.selection} grasp, threshold {config.threshold}, model {config.model}"
        + (", turn averaging" if config.turn_average else "")
        + (", clearance check" if config.clearance else "")
        + (", grip check" if config.grip else "")
    )
    print(summary_table(summary))
    print(f"results: {results_dir}/ (rounds.csv, grasps.csv, summary.json)")
    return 0


def _run(config: ClutterConfig, vgn: VGNClient, results: ResultsFolder, image_dir: Path | None) -> dict:
    remaining = config.rounds - len(results.finished_rounds())
    if remaining < config.rounds:
        print(
            f"resuming: {config.rounds - remaining} of {config.rounds} rounds already done", file=sys.stderr
        )
    try:
        from tqdm import tqdm

        bar = tqdm(total=max(remaining, 0), unit="round", file=sys.stderr)
    except ImportError:  # pragma: no cover - tqdm ships with the sim extra
        bar = None

    def progress(record: RoundRecord) -> None:
        if bar is not None:
            bar.update(1)
            bar.set_postfix(
                success=f"{record.successes}/{record.attempts}",
                cleared=f"{record.cleared}/{record.object_count}",
            )

    try:
        return run_episode(config, vgn, results, image_dir, progress)
    finally:
        if bar is not None:
            bar.close()
