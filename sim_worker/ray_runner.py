"""Simulation spread over a Ray cluster (``--ray``): data generation and clear-scene rounds.

Each worker is a Ray actor with its own PyBullet world that plans through a service it can
reach: ``--url`` when given, else one embedded service per node (started by the driver, so a
killed worker does not take its node's service down with it). Workers return finished scenes
or rounds; the driver alone writes them, in index order, so no shared filesystem is needed,
the dataset and results layouts stay as they are, and the files come out the same on 1 or N
workers. A scene or round depends on (seed, index) alone, so a worker killed mid-way is
restarted by Ray and its item simply run again.
"""

from __future__ import annotations

import os
import socket
import sys
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any

from client.extras import missing_extra

if TYPE_CHECKING:
    import argparse

    from tqdm import tqdm

    from sim_worker.clutter import ClutterConfig
    from sim_worker.datagen import DataGenConfig
    from sim_worker.results import ResultsFolder, RoundRecord
    from vgn_data.dataset import RawDataset

#: How often Ray restarts a dead worker, and retries the item it held, before the run gives up.
WORKER_RESTARTS = 4
#: Items dispatched ahead of the oldest unwritten one, per worker: bounds what the driver holds.
LOOKAHEAD_PER_WORKER = 4
SERVICE_ACTOR_PREFIX = "vgn-service"


class RayMissing(RuntimeError):
    """``--ray`` without the ray extra installed."""


def import_ray() -> ModuleType:
    """The ``ray`` module, imported only when ``--ray`` is used; ``RayMissing`` says how to install it."""
    try:
        import ray
    except ImportError as error:
        raise RayMissing(missing_extra("--ray", "ray", error, " (on every node of the cluster)")) from None
    return ray


def connect(address: str | None) -> None:
    """Join the cluster at ``address`` ('auto' or host:port), or start a local instance when
    it is None or 'local'. A process already connected (a test, a notebook) is left as it is."""
    joining = address not in (None, "local")
    if joining and "RAY_AUTH_MODE" not in os.environ and _auth_token_available():
        # Clusters started by `ray start` use token authentication; a joining driver must ask
        # for it, before Ray loads (RAY_AUTH_MODE=disabled still opts out).
        os.environ["RAY_AUTH_MODE"] = "token"
    ray = import_ray()
    if ray.is_initialized():
        return
    options: dict[str, Any] = {"include_dashboard": False, "logging_level": "WARNING", "log_to_driver": False}
    if not joining:
        ray.init(address="local", **options)  # a new instance, even where `ray start` runs one
        return
    try:
        ray.init(address=address, **options)
    except ConnectionError as error:
        raise ConnectionError(
            f"{error}. Is the cluster up (`ray start --head`), and, where it uses token authentication, "
            "is its token here (~/.ray/auth_token or RAY_AUTH_TOKEN)?"
        ) from None


def _auth_token_available() -> bool:
    return (
        bool(os.environ.get("RAY_AUTH_TOKEN") or os.environ.get("RAY_AUTH_TOKEN_PATH"))
        or (Path.home() / ".ray" / "auth_token").is_file()
    )


def cluster_cpus() -> int:
    """CPUs of the cluster (at least 1): the default worker count."""
    return max(1, int(import_ray().cluster_resources().get("CPU", 1)))


@dataclass
class SceneResult:
    """What a worker sends back for one scene: its views, grasp rows and recipe arrays, or None when empty."""

    index: int
    depth: Any
    camera_poses: Any
    rows: Any
    seconds: float
    node: str
    recipe: Any = None


class ServiceHost:
    """Owns the embedded service of one node (a Ray actor pinned to it, using no CPU slot)."""

    def __init__(self, service_options: dict) -> None:
        from service.launch.embedded import EmbeddedService

        self.service = EmbeddedService(**service_options).start()

    def url(self) -> str:
        """Where this node's workers reach the service."""
        return self.service.url

    def stop(self) -> None:
        """Stop this node's service at the end of the run."""
        self.service.stop()


class SimWorker:
    """One simulator: a service client, a PyBullet world per settings, kept across items."""

    def __init__(self, url: str | None, api_key: str | None, service_options: dict) -> None:
        import ray

        from client.connect import connect as connect_service

        self.node = f"{socket.gethostname()}/{ray.get_runtime_context().get_node_id()[:8]}"
        self.own_service = None
        if url is None:
            url = self._node_service_url(ray, service_options)
        self.vgn = connect_service(url, api_key=api_key, timeout=120.0)
        self.labellers: dict[Any, Any] = {}
        self.episodes: dict[Any, Any] = {}

    def _node_service_url(self, ray: ModuleType, service_options: dict) -> str:
        """The service of this node, or an own one where the driver started none (a node
        that joined after the run began)."""
        node_id = ray.get_runtime_context().get_node_id()
        try:
            host = ray.get_actor(f"{SERVICE_ACTOR_PREFIX}-{node_id}")
        except ValueError:
            from service.launch.embedded import EmbeddedService

            self.own_service = EmbeddedService(**service_options).start()
            return self.own_service.url
        return ray.get(host.url.remote())

    def label_scene(self, config: DataGenConfig, index: int) -> SceneResult:
        """Label scene ``index`` in this worker's world for ``config`` (one world per distinct config)."""
        from sim_worker.datagen import SceneLabeller

        if config not in self.labellers:
            self.labellers[config] = SceneLabeller(self.vgn, config)
        started = time.perf_counter()
        labelled = self.labellers[config].label_scene(index)
        seconds = time.perf_counter() - started
        if labelled is None:
            return SceneResult(index, None, None, None, seconds, self.node)
        from sim_worker.recipes import recipe_arrays

        views, rows, recipe = labelled
        arrays = recipe_arrays(recipe, self.labellers[config].table)
        return SceneResult(index, views.depth, views.camera_poses, rows, seconds, self.node, arrays)

    def prepare_clutter(self, config: ClutterConfig, resolve: Callable) -> tuple[bool, str, Any]:
        """(service ready, its detail, ``config`` with the planner resolved by ``resolve``)."""
        readiness = self.vgn.ready()
        if not readiness.ready and config.planner == "vgn":
            return False, str(readiness.detail), config  # without weights there is nothing to resolve
        return readiness.ready, str(readiness.detail), resolve(config, self.vgn)

    def clutter_round(self, config: ClutterConfig, round_id: int) -> tuple[RoundRecord, str]:
        """Run one round for ``config`` (one world per distinct config); the record and this worker's node."""
        from sim_worker.clutter import ClutterRemoval

        if config not in self.episodes:
            self.episodes[config] = ClutterRemoval(config, self.vgn, results=None)
        record = self.episodes[config].run_round(round_id)
        return record, self.node

    def pid(self) -> int:
        """The worker process's id, to find or signal a worker from outside Ray."""
        return os.getpid()


class WorkerPool:
    """``count`` SimWorker actors (restarted when they die) and the per-node services they use."""

    def __init__(
        self,
        count: int | None,
        url: str | None,
        api_key: str | None = None,
        service_options: dict | None = None,
    ) -> None:
        ray = import_ray()
        self.ray = ray
        cpus = cluster_cpus()
        self.count = count or cpus
        self.hosts = [] if url else self._start_node_services(service_options or {})
        # A fractional share when more workers than CPUs are asked for, so they all start.
        worker = ray.remote(SimWorker).options(
            num_cpus=min(1.0, cpus / self.count),
            max_restarts=WORKER_RESTARTS,
            max_task_retries=WORKER_RESTARTS,
        )
        self.workers = [worker.remote(url, api_key, service_options or {}) for _ in range(self.count)]

    def _start_node_services(self, service_options: dict) -> list:
        from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

        hosts = []
        for node in self.ray.nodes():
            if not node["Alive"] or node["Resources"].get("CPU", 0) <= 0:
                continue
            host = self.ray.remote(ServiceHost).options(
                name=f"{SERVICE_ACTOR_PREFIX}-{node['NodeID']}",
                num_cpus=0,
                scheduling_strategy=NodeAffinitySchedulingStrategy(node["NodeID"], soft=False),
            )
            hosts.append(host.remote(service_options))
        return hosts

    def run_in_order(self, method: str, args: tuple, items: list[int]) -> Iterator[Any]:
        """Call ``worker.method(*args, item)`` for every item, each worker one item at a time,
        and yield the results in the order of ``items`` whatever order they finish in."""
        pending: dict[Any, tuple[int, Any]] = {}  # future -> (position, worker)
        finished: dict[int, Any] = {}
        idle, next_item, next_out = list(self.workers), 0, 0
        lookahead = LOOKAHEAD_PER_WORKER * len(self.workers)
        while next_out < len(items):
            while idle and next_item < len(items) and next_item < next_out + lookahead:
                worker = idle.pop()
                future = getattr(worker, method).remote(*args, items[next_item])
                pending[future] = (next_item, worker)
                next_item += 1
            done, _ = self.ray.wait(list(pending), num_returns=1)
            position, worker = pending.pop(done[0])
            finished[position] = self.ray.get(done[0])
            idle.append(worker)
            while next_out in finished:
                yield finished.pop(next_out)
                next_out += 1

    def call_one(self, method: str, *args: Any) -> Any:
        """``method(*args)`` on the first worker, waiting for its answer."""
        return self.ray.get(getattr(self.workers[0], method).remote(*args))

    def close(self) -> None:
        """Stop the node services and kill every actor; a failure to stop is reported, not raised."""
        try:
            self.ray.get([host.stop.remote() for host in self.hosts], timeout=30)
        except Exception as error:  # a service that is already gone need not be stopped
            print(f"warning: stopping the node services: {error}", file=sys.stderr)
        for actor in [*self.workers, *self.hosts]:
            self.ray.kill(actor)


def _progress(total: int, unit: str) -> tqdm:
    from tqdm import tqdm

    return tqdm(total=total, unit=unit, file=sys.stderr)


class RoundProgress:
    """Updates a progress bar per finished round with the grasps attempted per second."""

    def __init__(self, bar: tqdm) -> None:
        self.bar, self.attempts, self.started = bar, 0, time.perf_counter()

    def __call__(self, record: RoundRecord) -> None:
        """Count one finished round and show the attempt rate and its successes."""
        self.attempts += record.attempts
        self.bar.update(1)
        rate = self.attempts / (time.perf_counter() - self.started)
        self.bar.set_postfix(grasps_per_s=f"{rate:.2f}", success=f"{record.successes}/{record.attempts}")


def _node_split(nodes: Iterable[str]) -> str:
    counts: dict[str, int] = {}
    for node in nodes:
        counts[node] = counts.get(node, 0) + 1
    return ", ".join(f"{node}: {count}" for node, count in sorted(counts.items()))


def generate_on_ray(
    args: argparse.Namespace, config: DataGenConfig, dataset: RawDataset, todo: list[int]
) -> int:
    """``generate-data --sim --ray``: label scenes ``todo`` on Ray workers into ``dataset``."""
    from sim_worker.datagen import scene_id
    from vgn_data.dataset import SceneViews

    try:
        connect(args.ray)
    except (RayMissing, ConnectionError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    if args.workers is not None and args.workers < 1:
        print("error: --workers must be >= 1", file=sys.stderr)
        return 2
    count = args.workers or cluster_cpus()
    print(f"{args.scenes - len(todo)} of {args.scenes} scenes already in {dataset.root}; labelling {len(todo)} "
          f"with {count} Ray worker(s)", file=sys.stderr)  # fmt: skip
    if not todo:
        return 0
    pool = WorkerPool(count, args.url, args.api_key)
    bar = _progress(len(todo), "scene")
    grasps, nodes, started = 0, [], time.perf_counter()
    try:
        for result in pool.run_in_order("label_scene", (config,), todo):
            sid = scene_id(config.seed, result.index)
            if result.rows is None:
                dataset.mark_empty(sid)
            else:
                dataset.add_scene(
                    sid, SceneViews(result.depth, result.camera_poses), result.rows, result.recipe
                )
                grasps += len(result.rows)
            nodes.append(result.node)
            bar.update(1)
            bar.set_postfix(grasps_per_s=f"{grasps / (time.perf_counter() - started):.2f}")
    except Exception as error:
        print(f"error: a Ray worker failed: {error}\nthe scenes written so far are kept; rerun to resume",
              file=sys.stderr)  # fmt: skip
        return 1
    finally:
        bar.close()
        pool.close()
    seconds = time.perf_counter() - started
    print(f"scenes per node: {_node_split(nodes)}", file=sys.stderr)
    per_worker = grasps / seconds / count if seconds else 0.0
    print(f"labelled {grasps} grasps in {seconds:.1f} s: {grasps / seconds:.2f} grasps/s, "
          f"{per_worker:.2f} grasps/s per worker ({count} Ray worker(s))")  # fmt: skip
    return 0


class ClutterPool:
    """Clear-scene rounds on Ray workers, committed in round order into a results folder."""

    def __init__(self, address: str | None, workers: int | None, url: str | None, api_key: str | None,
                 service_options: dict | None = None) -> None:  # fmt: skip
        connect(address)
        self.pool = WorkerPool(workers, url, api_key, service_options)

    def prepare(self, config: ClutterConfig, resolve: Callable) -> tuple[bool, str, Any]:
        """(service ready, detail, config with its planner resolved), asked of one worker."""
        return self.pool.call_one("prepare_clutter", config, resolve)

    def run(self, config: ClutterConfig, results: ResultsFolder, progress: Callable | None = None) -> dict:
        """Run the rounds of ``config`` not yet in ``results``; the summary over all of them
        (as ClutterRemoval.run, whose single-process results these equal)."""
        from sim_worker.metrics import summarize

        done = results.finished_rounds()
        todo = [r for r in range(config.rounds) if r not in done]
        self.nodes: list[str] = []
        for record, node in self.pool.run_in_order("clutter_round", (config,), todo):
            results.commit(record)
            self.nodes.append(node)
            if progress:
                progress(record)
        summary = summarize(results.rounds, results.grasps)
        results.write_summary({"config": config.as_json(), **summary})
        return summary

    def close(self) -> None:
        """Stop the workers and node services."""
        self.pool.close()


def clear_scene_on_ray(
    args: argparse.Namespace, config: ClutterConfig, results_dir: Path, resolve: Callable
) -> int:
    """``clear-scene --sim --ray``: rounds on Ray workers; ``resolve`` fills in the planner."""
    from sim_worker.metrics import summary_table
    from sim_worker.results import ResultsFolder

    if args.save_images:
        print("error: --save-images is not available with --ray (the pictures would stay on the workers)",
              file=sys.stderr)  # fmt: skip
        return 2
    try:
        clutter = ClutterPool(args.ray, args.workers, args.url, args.api_key, {"model": args.model})
    except (RayMissing, ConnectionError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    try:
        ready, detail, config = clutter.prepare(config, resolve)
        if not ready and config.planner == "vgn":
            print(f"error: the service cannot plan: {detail} (pass --model PATH)", file=sys.stderr)
            return 2
        try:
            results = ResultsFolder(results_dir, config.as_json())
        except ValueError as error:
            print(f"error: {error}", file=sys.stderr)
            return 2
        remaining = config.rounds - len(results.finished_rounds() & set(range(config.rounds)))
        if remaining < config.rounds:
            print(f"resuming: {config.rounds - remaining} of {config.rounds} rounds already done",
                  file=sys.stderr)  # fmt: skip
        bar = _progress(remaining, "round")
        try:
            summary = clutter.run(config, results, RoundProgress(bar))
        except Exception as error:
            print(f"error: a Ray worker failed: {error}\nfinished rounds are kept; rerun to resume",
                  file=sys.stderr)  # fmt: skip
            return 1
        finally:
            bar.close()
    finally:
        clutter.close()
    print(f"rounds per node: {_node_split(clutter.nodes)}", file=sys.stderr)
    print(
        f"\nclear-scene --sim --ray: {config.scene}, {config.object_count} objects, "
        f"{config.looking}, {config.selection} grasp, threshold {config.threshold}, model {config.model}"
    )
    print(summary_table(summary))
    print(f"results: {results_dir}/ (rounds.csv, grasps.csv, summary.json)")
    return 0
