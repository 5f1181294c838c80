"""``vgn-client generate-data --sim``: K simulator processes labelling scenes through one service.

``client.cli`` imports this module only when the command runs, so the robot-side client
never needs pybullet.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import multiprocessing
import queue
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from service.launch.embedded import EmbeddedService
from sim_worker.datagen import DataGenConfig, dataset_setup, scene_id
from sim_worker.hand_urdf import hand_urdf
from vgn_contract.gripper_description import check_version, default_gripper
from vgn_data.dataset import RawDataset
from vgn_data.files import check_settings, remove_stale_temporaries

if TYPE_CHECKING:
    from multiprocessing.queues import Queue

    from tqdm import tqdm

    #: What a worker reports per scene: (scene id, grasps labelled, seconds).
    Reports = Queue[tuple[str, int, float]]


def _worker(
    url: str, api_key: str | None, out: str, config: DataGenConfig, indices: list[int], reports: Reports
) -> None:
    """One simulator process: its own PyBullet world and client, its share of the scenes."""
    from client.connect import connect
    from service.launch.lifetime import end_with_parent

    end_with_parent()  # a killed command must not leave workers labelling on
    from sim_worker.datagen import generate

    with connect(url, api_key=api_key, timeout=120.0) as vgn:
        generate(vgn, RawDataset(Path(out)), config, indices,
                 report=lambda sid, grasps, seconds: reports.put((sid, grasps, seconds)))  # fmt: skip


def run(args: argparse.Namespace) -> int:
    """``vgn-client generate-data --sim``: label the scenes missing from the dataset folder in worker
    processes (or on Ray); returns the exit status."""
    first = getattr(args, "first", 0)
    if (args.workers is not None and args.workers < 1) or args.scenes < 0 or first < 0:
        print("error: --workers must be >= 1, --scenes and --first >= 0", file=sys.stderr)
        return 2
    try:
        config = DataGenConfig(scene=args.scene, objects=tuple(args.objects or ()), seed=args.seed,
                               points_per_scene=args.points, noise=args.noise,
                               noise_fraction=args.noise_fraction, side_view_fraction=args.side_view_fraction,
                               answer_grasps=args.answer_grasps, answer_threshold=args.answer_threshold,
                               renderer=args.renderer, hand=getattr(args, "gripper", None) or default_gripper())  # fmt: skip
        check_version(config.hand)
        hand_urdf(config.hand)  # a hand the simulator cannot build stops the run here, not in a worker
    except ValueError as error:  # a GripperDescriptionError too
        print(f"error: {error}", file=sys.stderr)
        return 2
    out = Path(args.out)
    try:
        dataset = RawDataset(out, dataset_setup(config.hand))
    except ValueError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    if not config.answer_grasps:  # answer runs are checked once the answering model is known
        failed = _check_settings(out, config)
        if failed:
            return failed
    for leftover in remove_stale_temporaries(out):
        print(f"removed {leftover}, left by a killed writer", file=sys.stderr)
    done = dataset.done_scene_ids()
    indices = range(first, first + args.scenes)
    todo = [i for i in indices if scene_id(args.seed, i) not in done]
    if getattr(args, "ray", None) is not None:  # the scenes spread over a Ray cluster instead
        from sim_worker.ray_runner import generate_on_ray

        if config.answer_grasps:
            if args.url is None:
                print("error: --answer-grasps with --ray needs --url: one service whose model's answers are "
                      "labelled", file=sys.stderr)  # fmt: skip
                return 2
            config, failed = _with_answer_model(args.url, args.api_key, out, config)
            if failed:
                return failed
        return generate_on_ray(args, config, dataset, todo)
    args.workers = args.workers or 1
    print(f"{args.scenes - len(todo)} of {args.scenes} scenes already in {out}; labelling {len(todo)} "
          f"with {args.workers} worker(s)", file=sys.stderr)  # fmt: skip
    if not todo:
        return 0
    with contextlib.ExitStack() as stack:
        url = args.url
        if url is None:
            try:
                url = stack.enter_context(EmbeddedService(log_path=out / "service.log")).url
            except (RuntimeError, TimeoutError) as error:
                print(f"error: {error}", file=sys.stderr)
                return 2
        if config.answer_grasps:
            config, failed = _with_answer_model(url, args.api_key, out, config)
            if failed:
                return failed
        grasps, seconds = _run_workers(url, args, config, todo)
    per_worker = grasps / seconds / args.workers if seconds else 0.0
    print(
        f"labelled {grasps} grasps in {seconds:.1f} s: {per_worker:.2f} grasps/s per worker "
        f"({args.workers} worker(s), {1 / per_worker if per_worker else float('nan'):.3f} s per grasp point per worker)"
    )
    return 0


def _check_settings(out: Path, config: DataGenConfig) -> int:
    """Record the run's settings, or refuse to resume a folder made with others; the exit status."""
    # Labels are what this hand can do: a folder made with another hand is never resumed into.
    # ``gripper`` is the hand's version, the label training and the shards read.
    hand = config.hand
    settings = config.recorded() | {
        "gripper": hand.version,
        "gripper_name": hand.name,
        "gripper_digest": hand.digest,
    }
    path = out / "generation.json"
    # A folder made before the hand's name and digest were recorded resumes when its version matches.
    previous = json.loads(path.read_text()) if path.is_file() else {}
    added = tuple(key for key in ("gripper_name", "gripper_digest") if previous and key not in previous)
    try:
        check_settings(path, settings, may_change=added)
    except ValueError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    return 0


def _with_answer_model(
    url: str, api_key: str | None, out: Path, config: DataGenConfig
) -> tuple[DataGenConfig, int]:
    """``config`` naming the weights the service at ``url`` answers the run's hand with (its own
    network where it has one), its settings checked: a folder holds one model's answers, so a
    resume with other weights is refused."""
    from client.connect import connect

    with connect(url, api_key=api_key, timeout=120.0) as vgn:
        info = vgn.model()
    if not info.loaded or info.model_id is None:
        print(f"error: --answer-grasps labels the network's answers, but the service has no model ({info.detail})",
              file=sys.stderr)  # fmt: skip
        return config, 2
    own = info.hand_model(config.hand.name)
    config = dataclasses.replace(config, answer_model=info.model_id if own is None else own.model_id)
    return config, _check_settings(out, config)


def _run_workers(
    url: str, args: argparse.Namespace, config: DataGenConfig, todo: list[int]
) -> tuple[int, float]:
    context = multiprocessing.get_context("spawn")  # PyBullet and fork do not mix
    reports = context.Queue()
    shares = [todo[w :: args.workers] for w in range(args.workers)]
    processes = [context.Process(target=_worker, args=(url, args.api_key, args.out, config, share, reports))
                 for share in shares if share]  # fmt: skip
    started = time.perf_counter()
    for process in processes:
        process.start()
    bar = _progress(len(todo))
    grasps = finished = 0
    try:
        while finished < len(todo):
            try:
                _, count, _ = reports.get(timeout=1.0)
            except queue.Empty:
                if not any(p.is_alive() for p in processes):
                    break
                continue
            finished += 1
            grasps += count
            bar.update(1)
            bar.set_postfix(grasps=grasps)
    finally:
        bar.close()
        for process in processes:
            process.join(timeout=60)
            if process.is_alive():
                process.terminate()
    failed = [p.exitcode for p in processes if p.exitcode]
    if failed:
        raise SystemExit(f"error: {len(failed)} worker(s) failed (exit codes {failed}); rerun to resume")
    return grasps, time.perf_counter() - started


def _progress(total: int) -> tqdm:
    from tqdm import tqdm

    return tqdm(total=total, unit="scene", file=sys.stderr)
