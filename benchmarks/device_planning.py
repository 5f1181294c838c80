"""A grasp request's planning on a recorded fused volume, on the CPU or a GPU.

    python -m benchmarks.device_planning record --out VOLUME.npz
    python -m benchmarks.device_planning time VOLUME.npz [--device cuda] [--heads whole] [--repeats N] [--json PATH]

``record`` fuses the latency benchmark's box scene (six views, as ``benchmarks.latency``) in a
planning session and saves what a grasp request reads from it: the network's grid, the surface
points of the clearance check, the voxel size and the workspace pose. ``time`` then runs the
request's planning steps on that volume, in the order ``PlanningService.plan`` runs them:

- *plain request* (``turn_average=false``, no checks): one forward pass and detection;
- *default request*: the four-turn forward pass, detection, the clearance and grip checks.

Why: a GPU machine often has torch and nothing of the web stack or Open3D, so the HTTP
benchmark cannot run there; this one needs only torch, numpy, scipy and pydantic. It leaves
out what a GPU does not change (HTTP, the session lock, fusion), so its figures are the part
of ``benchmarks.latency``'s request that the device decides. The two requests alternate and
the CPU rows of the same run are the baseline; ``--concurrent`` adds requests from several
threads at once (on a GPU the planner's micro-batcher shares their forward passes).
``--heads`` times the fast network's rotation and width computed on demand or whole
(``VGN_HEADS``) on each device, one after the other.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import statistics
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from service.runtime import apply_threads, prepare_environment, tune_malloc

prepare_environment()  # the server's OpenMP defaults (service.app), before anything loads torch

import torch  # noqa: E402

from benchmarks.report import cpu_model, device_planning_table  # noqa: E402
from service.clearance import clear_grasps  # noqa: E402
from service.grip import MIN_GRIP_FRAMES, gripping_grasps  # noqa: E402
from service.planner import HEADS, GraspPlanner, InferenceOptions  # noqa: E402
from service.vgn.checkpoint import weights_id  # noqa: E402
from vgn_contract.schemas import GraspQuery  # noqa: E402

# Not service.settings.PACKAGED_MODEL: that module needs pydantic-settings, which a GPU machine may lack.
PACKAGED_MODEL = Path(__file__).resolve().parents[1] / "service" / "models" / "vgn.safetensors"


def record(out: Path) -> dict[str, Any]:
    """Fuse the box scene's six views in a real session and save what a request reads."""
    from benchmarks.workload import render_frames
    from service.core import PlanningService
    from service.settings import Settings
    from tests.helpers.scenes import INTRINSICS
    from vgn_contract.schemas import SessionCreate

    core = PlanningService(Settings(), GraspPlanner.from_path(None, "cpu"))
    try:
        session_id = core.create_session(SessionCreate(intrinsics=INTRINSICS)).session_id
        render_frames().fuse(core.add_frame, session_id)
        with core.sessions.use(session_id) as session:
            volume = {
                "grid": session.volume.grid(),
                "surface": session.volume.surface_points(),
                "voxel_size": np.float64(session.workspace.voxel_size),
                "workspace_pose": session.volume.workspace_pose,
                "frame_count": np.int64(session.frame_count),
            }
    finally:
        core.close()
    out.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(out, **volume)
    return {name: np.shape(value) for name, value in volume.items()}


class Request:
    """The planning steps of one grasp request on a recorded volume, step times kept."""

    def __init__(self, planner: GraspPlanner, volume: dict[str, np.ndarray]) -> None:
        self.planner = planner
        self.grid = volume["grid"].astype(np.float32)
        self.surface = volume["surface"]
        self.voxel_size = float(volume["voxel_size"])
        self.pose = volume["workspace_pose"]
        self.grip = int(volume["frame_count"]) >= MIN_GRIP_FRAMES  # as the service decides
        self.query = GraspQuery()
        self.unlimited = self.query.model_copy(update={"max_grasps": None})  # checks see every grasp

    def plain(self, steps: dict[str, list[float]]) -> int:
        """``turn_average=false``, no checks; the number of grasps returned."""
        output = timed(steps, "forward (1 grid)", lambda: self.planner.infer(self.grid, False))
        grasps = timed(steps, "detection", lambda: self._detect(output, self.query))
        return len(grasps)

    def default(self, steps: dict[str, list[float]]) -> int:
        """What a request that says nothing gets: four turns, the clearance check and (from
        enough frames) the grip check."""
        output = timed(steps, "forward (4 turns)", lambda: self.planner.infer(self.grid, True))
        grasps = timed(steps, "detection (turn-averaged)", lambda: self._detect(output, self.unlimited))
        grasps = timed(steps, "clearance check", lambda: clear_grasps(grasps, self.surface))
        if self.grip:
            grasps = timed(
                steps, "grip check", lambda: gripping_grasps(grasps, self.grid, self.voxel_size, self.pose)
            )
        return len(grasps[: self.query.max_grasps])

    def _detect(self, output: Any, query: GraspQuery) -> list[Any]:
        return self.planner.detect(self.grid, output, self.voxel_size, self.pose, query)


def timed(steps: dict[str, list[float]], name: str, call: Callable[[], Any]) -> Any:
    """``call()``, its milliseconds appended to ``steps[name]``."""
    started = time.perf_counter()
    result = call()
    steps.setdefault(name, []).append((time.perf_counter() - started) * 1e3)
    return result


def summary(values: list[float]) -> dict[str, float]:
    """Median and 95th percentile of millisecond samples."""
    ordered = sorted(values)
    return {
        "p50_ms": round(statistics.median(ordered), 3),
        "p95_ms": round(ordered[min(len(ordered) - 1, int(0.95 * len(ordered)))], 3),
        "n": len(ordered),
    }


def time_device(
    volume: dict[str, np.ndarray],
    model: Path,
    device: str,
    repeats: int,
    concurrent: int,
    heads: str = "auto",
) -> dict:
    """Alternate plain and default requests ``repeats`` times each after a warm-up, then
    (``concurrent`` > 1) run default requests from that many threads at once."""
    apply_threads(), tune_malloc()  # as the service starts
    planner = GraspPlanner.from_path(model, device, InferenceOptions(heads=heads))
    request = Request(planner, volume)
    steps: dict[str, list[float]] = {}
    totals: dict[str, list[float]] = {"plain request": [], "default request": []}
    grasps: dict[str, int] = {}
    for _ in range(5):
        request.plain({}), request.default({})
    for _ in range(repeats):
        for name, run in (("plain request", request.plain), ("default request", request.default)):
            started = time.perf_counter()
            grasps[name] = run(steps)
            totals[name].append((time.perf_counter() - started) * 1e3)
    result = {
        "device": str(planner.device),
        "device_name": torch.cuda.get_device_name(planner.device)
        if planner.device.type == "cuda"
        else cpu_model(),
        "torch_threads": torch.get_num_threads(),
        "precision": str(planner.dtype).removeprefix("torch."),
        "heads": planner.heads,
        "lanes": planner.lanes,
        "requests": {name: {**summary(values), "grasps": grasps[name]} for name, values in totals.items()},
        "steps": {name: summary(values) for name, values in steps.items()},
    }
    if concurrent > 1:
        result["concurrent"] = concurrent_requests(request, concurrent, max(10, repeats // 4))
    return result


def concurrent_requests(request: Request, threads: int, per_thread: int) -> dict[str, float]:
    """Default requests from ``threads`` threads at once: requests a second and latency."""

    def client(_: int) -> list[float]:
        latencies = []
        for _ in range(per_thread):
            started = time.perf_counter()
            request.default({})
            latencies.append((time.perf_counter() - started) * 1e3)
        return latencies

    started = time.perf_counter()
    with ThreadPoolExecutor(threads) as pool:
        latencies = [value for values in pool.map(client, range(threads)) for value in values]
    elapsed = time.perf_counter() - started
    return {"threads": threads, "requests_per_s": round(len(latencies) / elapsed, 1), **summary(latencies)}


def main(argv: list[str] | None = None) -> int:
    """``record`` or ``time`` (see the module docstring)."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    commands = parser.add_subparsers(dest="command", required=True)
    record_parser = commands.add_parser(
        "record", help="fuse the box scene and save the volume a request reads"
    )
    record_parser.add_argument("--out", type=Path, required=True)
    time_parser = commands.add_parser("time", help="time the planning steps on a recorded volume")
    time_parser.add_argument("volume", type=Path)
    time_parser.add_argument(
        "--model", type=Path, default=PACKAGED_MODEL, help="weights (default: the packaged model)"
    )
    time_parser.add_argument("--device", action="append", choices=["cpu", "cuda"],
                             help="repeat for several, timed in this order (default: cpu, and cuda when there is one)")  # fmt: skip
    time_parser.add_argument("--heads", action="append", choices=HEADS,
                             help="where rotation and width are computed; repeat for several (default: auto)")  # fmt: skip
    time_parser.add_argument("--repeats", type=int, default=200)
    time_parser.add_argument(
        "--concurrent", type=int, default=8, help="threads of the concurrent row (1: none)"
    )
    time_parser.add_argument("--json", type=Path, help="write the figures here")
    args = parser.parse_args(argv)
    if args.command == "time" and (args.repeats < 1 or args.concurrent < 1):
        parser.error("--repeats and --concurrent must be >= 1")
    if args.command == "record":
        print(f"recorded {args.out}: {record(args.out)}")
        return 0
    with np.load(args.volume) as data:
        volume = {name: data[name] for name in data.files}
    devices = args.device or (["cpu", "cuda"] if torch.cuda.is_available() else ["cpu"])
    runs = [
        time_device(volume, args.model, device, args.repeats, args.concurrent, heads)
        for device in devices
        for heads in args.heads or ["auto"]
    ]
    print(device_planning_table(runs))
    if args.json:
        payload = {
            "date": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
            "machine": {
                "cpus": os.cpu_count(),
                "python": platform.python_version(),
                "torch": torch.__version__,
            },
            "model": args.model.name,
            "weights_id": weights_id(args.model),
            "runs": runs,
        }
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(payload, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
