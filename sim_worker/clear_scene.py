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
from client.http import VGNClient, VGNError
from service.launch.embedded import EmbeddedService
from sim_worker.clutter import SERVICE_OPTIONS, ClutterConfig, ClutterRemoval, ServiceDefaultsError
from sim_worker.hand_urdf import hand_urdf
from sim_worker.metrics import summary_table
from sim_worker.results import ResultsFolder, RoundRecord
from vgn_contract.gripper_description import GripperDescriptionError, default_gripper
from vgn_contract.schemas import GraspDefaults, OneViewModel


def resolve_planner(config: ClutterConfig, vgn: VGNClient) -> ClutterConfig:
    """``config`` with the planner's identity filled in: the id of the weights that answer the run's
    hand (its own network where the service has one, else the main one; a resume with other weights
    is refused), and for the threshold, turn averaging, clearance and grip checks it leaves unset,
    what the service's ``/model`` says it will use, so that config.json records what is done.
    Requests still leave those options to the service (``left_to_service``), and each answer is
    checked against the record."""
    model = vgn.model()
    defaults = known_defaults(model.defaults)
    left = config.left_to_service | {name for name in SERVICE_OPTIONS if getattr(config, name) is None}
    clearance = defaults.clearance if config.clearance is None else config.clearance
    grip = defaults.grip if config.grip is None else config.grip
    if config.planner == "vgn":
        own = model.hand_model(config.hand.name)  # it answers every look, at its own threshold
        network_threshold = defaults.threshold if own is None else own.threshold
        threshold = network_threshold if config.threshold is None else config.threshold
        turns = defaults.turn_average if config.turn_average is None else config.turn_average
        # The service falls back only for requests that name no threshold and run a check.
        floor = defaults.fallback_threshold if config.threshold is None and (clearance or grip) else None
        one_view = model.one_view if own is None and _one_view_answers(model.one_view, config) else None
        return dataclasses.replace(
            config,
            model=model.model_id if own is None else own.model_id,
            one_view_model=one_view.model_id if one_view is not None else None,
            one_view_threshold=(one_view.threshold if config.threshold is None else config.threshold)
            if one_view is not None
            else None,
            threshold=threshold,
            fallback_threshold=floor if floor is not None and floor < threshold else None,
            turn_average=turns,
            clearance=clearance,
            grip=grip,
            left_to_service=left,
        )
    threshold = defaults.antipodal_threshold if config.threshold is None else config.threshold
    return dataclasses.replace(config, model="antipodal", threshold=threshold, turn_average=False,
                               clearance=clearance, grip=grip, left_to_service=left)  # fmt: skip


def _one_view_answers(one_view: OneViewModel | None, config: ClutterConfig) -> bool:
    """Whether the one-view network answers the run's one-frame looks: only its hand's."""
    return one_view is not None and one_view.gripper == config.hand.name


def grasp_defaults(config: ClutterConfig | None, vgn: VGNClient) -> GraspDefaults:
    """What the service's grasp requests get for the options they leave unset; a ``resolve`` for
    Ray's ``ClutterPool.prepare`` (``config`` is not used), importable on every worker."""
    return known_defaults(vgn.model().defaults)


def known_defaults(defaults: GraspDefaults | None) -> GraspDefaults:
    """``defaults`` as ``/model`` reported them; ``ServiceDefaultsError`` when it did not (a
    service older than this client), since a run could not record what it does."""
    if defaults is None:
        raise ServiceDefaultsError(
            "the service does not report the defaults of grasp requests (GET /model: defaults): "
            "it is older than this client; upgrade it"
        )
    return defaults


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
        hand=getattr(args, "gripper", None) or default_gripper(),
    )
    try:
        hand_urdf(config.hand)  # a hand the simulator cannot build stops the run here
    except GripperDescriptionError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
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
        try:
            config = resolve_planner(config, vgn)
            results = ResultsFolder(results_dir, config.as_json())
        except (ValueError, ServiceDefaultsError) as error:
            print(f"error: {error}", file=sys.stderr)
            return 2
        try:
            summary = _run(config, vgn, results, results_dir / "images" if args.save_images else None)
        except VGNError as error:
            print(f"error: the service answered {error}", file=sys.stderr)
            return 1
        except ServiceDefaultsError as error:
            print(f"error: {error}", file=sys.stderr)
            return 1
    print(
        f"\nclear-scene --sim: {config.scene}, {config.object_count} objects, "
        f"{config.looking}, {config.selection} grasp, threshold {config.threshold}, model {config.model}, "
        f"gripper {config.hand.name}"
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
