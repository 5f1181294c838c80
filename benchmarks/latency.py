"""Latency benchmark: what the service costs on top of calling Open3D and VGN directly.

    python -m benchmarks.latency [--repeats N] [--model PATH | --random-weights] [--threads T] [--json PATH]

One run measures the p50 and p95 latency (milliseconds) of

1. fusing a 640×480 float32 depth frame *directly* with Open3D, building the ``RGBDImage``
   per frame with ``create_from_color_and_depth`` as a naive user would (the baseline), and
   with ``service.tsdf.TSDFVolume.integrate`` (the service's cached-buffer path);
2. uploading a frame in process: ``PlanningService.add_frame`` (numpy) and
   ``PlanningService.add_encoded_frame`` (raw float32 bytes, and a 16-bit PNG, decoded + fused);
3. uploading a frame over HTTP to a real uvicorn child process (``EmbeddedService``) with
   ``VGNClient.add_frame`` (the bare image as the body, meta in ``X-Frame-Meta``): raw
   float32, and a uint16 millimetre array sent as a 16-bit PNG; and the same float32 frame
   as a multipart upload, the other form the service accepts; and the raw float32 upload
   33 ms after the previous call (a 30 Hz camera: both processes idle in between); and, as
   the floor under the client library, the same request from the standard library's
   ``http.client`` with its body and meta header built beforehand;
4. running VGN *directly* (the baseline): the naive float32 eager forward pass of the network
   as trained (``torch.inference_mode``) on a (1, 1, 40, 40, 40) grid fused from 6 views,
   then ``detect_grasps`` at the service's threshold — forward alone, detection alone, and their
   per-iteration sum; and, for comparison, the service's fast form of the network
   (``service.vgn.fast``) called directly;
5. a grasp request in process: ``PlanningService.plan`` as the service answers by default
   (turn-averaged, clearance- and grip-checked, unless ``VGN_TURN_AVERAGE``, ``VGN_CLEARANCE``
   or ``VGN_GRIP`` is false), and the other way (all three false, VGN's
   plain answer, or all true when the default is plain; its ratio to the default, paired);
6. a grasp request over HTTP: ``VGNClient.grasps``, each after a new frame (posted untimed),
   so that each runs the network, by default and the other way; and without new frames, when the
   service answers from the session's last network output;
7. steadiness: the grasp request over HTTP again, on a second server started the same way;
8. throughput of grasp requests over HTTP from 1, 8 and 32 concurrent sessions (each with its
   own client and session), which the service micro-batches into shared forward passes;
9. with the grpc extra (unless ``--skip-grpc``), the gRPC front end beside its HTTP twins on
   one server serving both (``benchmarks.grpc_latency``): a frame upload, a grasp request,
   a 60-frame and a 300-frame stream, and a cloud read right after a 60-frame stream;

and checks the project's targets:

* a frame request over HTTP (raw float32) has p50 <= 5 ms;
* a grasp request over HTTP has p50 <= 25 ms, and is >= 3x faster than the naive forward +
  detection measured in the same run;
* the second server's grasp p50 is within 1.3x of the first's, and the grasp request's p95 within
  1.6x of its p50 (the default start is steady);
* on a GPU only: grasp p50 <= 5 ms and 32 sessions get >= 8x the throughput of one.
* gRPC: frame upload p50 no slower than HTTP's, streamed frames >= 150 per second.

The servers start with the *default configuration* (``uvicorn service.app:app`` with no
``VGN_TORCH_THREADS``, ``VGN_PRECISION`` or OpenMP variables) unless ``--threads`` is given;
the baseline runs in this process with the thread count the service chose (read from
``GET /model``), so the two differ only in how the network is computed.

Why: the service is only worth putting between a robot and VGN if what it adds — sessions,
multipart parsing, decoding, validation, JSON and the HTTP round trip — is small next to the
work itself. Timing every layer beside the bare Open3D/torch calls, in the same run on the
same machine, shows where the overhead lives.

By default the operations run *interleaved*: each round times one call of every operation,
so slow drifts of the machine (shared or throttled virtual CPUs) hit every row alike and the
ratios stay meaningful; ``--schedule blocks`` times each operation's calls back to back
instead. Each operation gets ``--warmup`` untimed calls first. Frame uploads keep going to one
session per row; they queue their frames for the fine (cloud) volume and never fuse it (the
service's worker would, in a lull, once a queue is a quarter full or its cloud was read).

Depth frames are exact renderings of ``tests.helpers.scenes.BoxScene`` from ``circle_views()``.
The servers load the packaged model unless ``--model`` names other weights, and every grasp
request leaves the threshold to the service (the model card's operating threshold), as a plain
client does: the default request then returns grasps (two on the fully fused scene; the report
gives the median and least count of the timed requests), so its clearance and grip checks run
and are timed. ``--random-weights`` writes random-initialised weights to a temporary directory
instead: the network's cost does not depend on its weights, but the *number of grasps* does,
and random weights return none, so the checks cost nothing in such a run.

The benchmark process and the server share the machine's cores (the client waits while the
server works, so they do not compute at the same time). Open3D uses its own thread pool in
both. Other load on the machine skews every row alike; the load average is printed.
"""

from __future__ import annotations

import argparse
import contextlib
import http.client
import json
import os
import platform
import sys
import tempfile
import threading
import time
import urllib.parse
import warnings
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import open3d as o3d
import torch

from benchmarks.timing import Measurement, Operation, find, run_blocks, run_interleaved, timed
from benchmarks.workload import (
    DEPTH_SCALE,
    INTRINSICS,
    MAX_DEPTH,
    RESOLUTION,
    RUNTIME_VARIABLES,
    VIEWS,
    WORKSPACE_SIZE,
    Frames,
    render_frames,
)
from client.http import FRAME_META_HEADER, VGNClient
from service.core import PlanningService
from service.launch.embedded import EmbeddedService
from service.planner import resolve_device, resolve_precision
from service.runtime import configured_threads
from service.settings import PACKAGED_MODEL, Settings
from service.tsdf import TRUNCATION_VOXELS, TSDFVolume
from service.vgn.checkpoint import load_vgn, save_vgn, weights_id
from service.vgn.detection import DetectionConfig, detect_grasps
from service.vgn.fast import FastVGN
from service.vgn.network import VGN
from vgn_contract.schemas import SWITCHES, FrameMeta, GraspQuery, ModelInfo, Pose, SessionCreate

warnings.filterwarnings("ignore", category=DeprecationWarning)

FRAME_TARGET_MS = 5.0
GRASP_TARGET_MS = 25.0
GPU_GRASP_TARGET_MS = 5.0
SPEEDUP_TARGET = 3.0
STEADY_TARGET = 1.3
#: The default grasp request's p95 at most this multiple of its p50 (steady, not only fast).
TAIL_TARGET = 1.6
THROUGHPUT_TARGET = 8.0
CONCURRENCY = (1, 8, 32)
RAW_MEDIA_TYPE = "application/octet-stream"
PNG_MEDIA_TYPE = "image/png"

FRAME_HTTP = "VGNClient.add_frame (raw f32)"
FRAME_HTTP_PACED = "VGNClient.add_frame (raw f32), 33 ms after the last call"
FRAME_HTTP_BARE = "bare HTTP upload (http.client, body and meta prebuilt)"
#: Idle time before each paced upload: a 30 Hz depth camera.
CAMERA_PERIOD_S = 1 / 30
GRASPS_HTTP = "VGNClient.grasps (service default)"
FORWARD = "VGN forward, naive fp32 eager (inference_mode)"
FAST_FORWARD = "VGN forward, service's fast form"
GRASPS_HTTP_AGAIN = "VGNClient.grasps (second server)"
GRASPS_HTTP_KEPT = "VGNClient.grasps, no new frame (output reused)"
GRASPS_HTTP_KEPT_AGAIN = "VGNClient.grasps, no new frame (second server)"
DETECTION = "detect_grasps (the service's threshold)"
FORWARD_DETECTION = "forward + detection"
PLAN = "PlanningService.plan (service default)"


def service_defaults(model: ModelInfo) -> dict[str, bool]:
    """The switches a grasp request that does not say gets, as the service's ``/model`` reports them."""
    if model.defaults is None:
        raise RuntimeError(
            "the service does not report the defaults of grasp requests: it is older than this benchmark"
        )
    return model.defaults.model_dump(include=set(SWITCHES))


def other_options(defaults: dict[str, bool]) -> dict[str, bool]:
    """The grasp options of the other way than the service's default: VGN's plain answer when
    the default turns on anything, else every switch on (the service's best answer)."""
    other = not any(defaults.values())
    return {switch: other for switch in defaults}


def other_way(operation: str, options: dict[str, bool]) -> str:
    """The name of ``operation`` asked with ``options`` (the other way than the service's default)."""
    asked = ", ".join(f"{switch}={'true' if on else 'false'}" for switch, on in options.items())
    return f"{operation.split(' (')[0]}, {asked}"


# Measurement -------------------------------------------------------------------------------
def sum_of(name: str, parts: list[Measurement], note: str = "") -> Measurement:
    """Per-iteration sum of operations that ran one after the other in each iteration."""
    samples = [sum(values) for values in zip(*(p.samples_ms for p in parts), strict=True)]
    return Measurement(name, parts[0].group, samples, note)


# Inputs --------------------------------------------------------------------------------------
def weights_path(model: Path | None, random_weights: bool, directory: Path) -> tuple[Path, bool]:
    """The weights to benchmark and whether they are random: random-initialised weights written
    to ``directory`` when ``random_weights``, else ``model``, else the packaged model."""
    if not random_weights:
        return model or PACKAGED_MODEL, False
    torch.manual_seed(0)
    path = directory / "random-vgn.safetensors"
    save_vgn(VGN(), path)
    return path, True


# 1. Fusion -----------------------------------------------------------------------------------
def naive_volume() -> o3d.pipelines.integration.UniformTSDFVolume:
    """An Open3D TSDF volume over the benchmark's workspace, as a user would build it."""
    voxel = WORKSPACE_SIZE / RESOLUTION
    return o3d.pipelines.integration.UniformTSDFVolume(
        length=WORKSPACE_SIZE,
        resolution=RESOLUTION,
        sdf_trunc=TRUNCATION_VOXELS * voxel,
        color_type=o3d.pipelines.integration.TSDFVolumeColorType.NoColor,
    )


def naive_integrate(
    volume: o3d.pipelines.integration.UniformTSDFVolume,
    depth: np.ndarray,
    intrinsic: o3d.camera.PinholeCameraIntrinsic,
    pose: np.ndarray,
) -> None:
    """What a user without the service writes: new Open3D images and RGBDImage every frame."""
    color = o3d.geometry.Image(np.zeros((*depth.shape, 3), dtype=np.uint8))
    rgbd = o3d.geometry.RGBDImage.create_from_color_and_depth(
        color,
        o3d.geometry.Image(depth),
        depth_scale=1.0,
        depth_trunc=MAX_DEPTH,
        convert_rgb_to_intensity=False,
    )
    volume.integrate(rgbd, intrinsic, np.linalg.inv(pose))


def fusion_operations(frames: Frames) -> list[Operation]:
    """Direct Open3D fusion (the baseline) beside the service's ``TSDFVolume.integrate``."""
    i, n = INTRINSICS, len(frames)
    intrinsic = o3d.camera.PinholeCameraIntrinsic(i.width, i.height, i.fx, i.fy, i.cx, i.cy)
    naive, cached = naive_volume(), TSDFVolume(WORKSPACE_SIZE, RESOLUTION)

    def direct(k: int) -> None:
        naive_integrate(naive, frames.depths[k % n], intrinsic, frames.poses[k % n])

    def ours(k: int) -> None:
        cached.integrate(frames.depths[k % n], INTRINSICS, frames.poses[k % n], MAX_DEPTH)

    return [
        Operation("direct Open3D integrate (naive RGBDImage)", "1 fusion", direct, "baseline"),
        Operation("TSDFVolume.integrate (cached buffer)", "1 fusion", ours),
    ]


# 2 + 5. The planning core in process -------------------------------------------------------
def new_session(core: PlanningService) -> str:
    """An empty session with the benchmark's intrinsics."""
    return core.create_session(SessionCreate(intrinsics=INTRINSICS)).session_id


def core_frame_operations(core: PlanningService, frames: Frames) -> list[Operation]:
    """In-process uploads of a numpy frame, raw float32 bytes and a 16-bit PNG, a session each."""
    n, group = len(frames), "2 frame in-process"
    metas = [
        FrameMeta(camera_pose=Pose.from_matrix(p), depth_scale=DEPTH_SCALE, max_depth=MAX_DEPTH)
        for p in frames.poses
    ]
    numpy_id, raw_id, png_id = (new_session(core) for _ in range(3))

    def numpy_frame(k: int) -> None:
        core.add_frame(numpy_id, frames.depths[k % n], frames.poses[k % n], max_depth=MAX_DEPTH)

    def raw_frame(k: int) -> None:
        core.add_encoded_frame(raw_id, frames.raw[k % n], RAW_MEDIA_TYPE, metas[k % n])

    def png_frame(k: int) -> None:
        core.add_encoded_frame(png_id, frames.png[k % n], PNG_MEDIA_TYPE, metas[k % n])

    return [
        Operation("PlanningService.add_frame (numpy)", group, numpy_frame),
        Operation("PlanningService.add_encoded_frame (raw f32)", group, raw_frame),
        Operation("PlanningService.add_encoded_frame (PNG16)", group, png_frame),
    ]


def core_plan_operation(
    core: PlanningService, frames: Frames, query: GraspQuery, name: str = PLAN
) -> tuple[Operation, int]:
    """``PlanningService.plan`` on a session with every view fused, and its grasp count."""
    session_id = new_session(core)
    frames.fuse(core.add_frame, session_id)
    grasps = len(core.plan(session_id, query).grasps)
    n = len(frames)

    def post_frame(k: int) -> None:  # so that every call runs the network
        if k % 15 == 0:  # every view again, so that every request sees the whole scene
            core.reset_session(session_id)
            frames.fuse(core.add_frame, session_id)
        core.add_frame(session_id, frames.depths[k % n], frames.poses[k % n], max_depth=MAX_DEPTH)

    operation = Operation(name, "5 grasps in-process", lambda k: core.plan(session_id, query), "", post_frame)
    return operation, grasps


# 4. Network baseline -------------------------------------------------------------------------
def fused_grid(frames: Frames) -> np.ndarray:
    """The network's input grid after fusing every view, for the direct network rows."""
    volume = TSDFVolume(WORKSPACE_SIZE, RESOLUTION)
    for depth, pose in zip(frames.depths, frames.poses, strict=True):
        volume.integrate(depth, INTRINSICS, pose, MAX_DEPTH)
    return volume.grid()


def network_operations(
    weights: Path, device: torch.device, grid: np.ndarray, threshold: float
) -> tuple[list[Operation], int]:
    """Direct forward then direct detection at ``threshold`` (run in this order; detection
    reads the forward's output), and the grasp count."""
    network = load_vgn(weights).to(device)
    tensor = torch.from_numpy(grid)[None, None].to(device)
    voxel_size, pose = WORKSPACE_SIZE / RESOLUTION, np.eye(4)
    config = DetectionConfig(threshold=threshold)
    output: list[np.ndarray] = []

    def forward(_: int) -> None:
        with torch.inference_mode():
            quality, rotation, width = network(tensor)
        output[:] = [quality[0, 0].cpu().numpy(), rotation[0].cpu().numpy(), width[0, 0].cpu().numpy()]

    def detect(_: int) -> int:
        return len(detect_grasps(grid, *output, voxel_size, pose, config))

    fast = FastVGN.from_vgn(load_vgn(weights), resolve_precision("auto", device)).to(device)

    def fast_forward(_: int) -> None:
        with torch.inference_mode():
            [t.cpu() for t in fast(tensor)]

    group = "4 network direct"
    forward(0)
    return [
        Operation(FORWARD, group, forward, "baseline"),
        Operation(DETECTION, group, detect, "baseline"),
        Operation(FAST_FORWARD, group, fast_forward),
    ], detect(0)


# 3 + 6. Over HTTP --------------------------------------------------------------------------
@contextlib.contextmanager
def running_service(
    weights: Path, threads: int | None, device: str, extra: dict[str, str] | None = None
) -> Iterator[VGNClient]:
    """A real uvicorn child process on loopback, and a client talking to it. Without
    ``threads`` it runs the default configuration: none of ``RUNTIME_VARIABLES`` reach it."""
    env = {"VGN_DEVICE": device, "VGN_API_KEY": "", **(extra or {})}
    if threads is not None:
        env["VGN_TORCH_THREADS"] = str(threads)
    unset = RUNTIME_VARIABLES if threads is None else ()
    with (
        EmbeddedService(model=weights, env=env, unset=unset) as service,
        VGNClient(service.url) as client,
    ):
        yield client


def http_frame_operations(client: VGNClient, frames: Frames) -> list[Operation]:
    """Frame uploads over HTTP: raw float32 (the target), a multipart upload and a 16-bit PNG."""
    n, group = len(frames), "3 frame HTTP"
    raw_id = client.create_session(intrinsics=INTRINSICS).session_id
    png_id = client.create_session(intrinsics=INTRINSICS).session_id

    def raw_frame(k: int) -> None:
        client.add_frame(raw_id, frames.depths[k % n], frames.poses[k % n], max_depth=MAX_DEPTH)

    paced_id = client.create_session(intrinsics=INTRINSICS).session_id

    def paced_frame(k: int) -> None:
        client.add_frame(paced_id, frames.depths[k % n], frames.poses[k % n], max_depth=MAX_DEPTH)

    multipart = httpx.Client(base_url=client.url, timeout=60)
    multipart_id = client.create_session(intrinsics=INTRINSICS).session_id
    metas = [
        FrameMeta(camera_pose=Pose.from_matrix(p), max_depth=MAX_DEPTH).model_dump_json()
        for p in frames.poses
    ]

    def multipart_frame(k: int) -> None:
        files = {
            "meta": (None, metas[k % n], "application/json"),
            "depth": ("d.raw", frames.raw[k % n], RAW_MEDIA_TYPE),
        }
        multipart.post(f"/sessions/{multipart_id}/frames", files=files).raise_for_status()

    # The floor under the client library: the same bytes on the wire (the body and the meta
    # header VGNClient would send), from the standard library's client with nothing to build.
    url = urllib.parse.urlsplit(client.url)
    bare = http.client.HTTPConnection(url.hostname or "127.0.0.1", url.port, timeout=60)
    bare_id = client.create_session(intrinsics=INTRINSICS).session_id

    def bare_frame(k: int) -> None:
        headers = {"Content-Type": RAW_MEDIA_TYPE, FRAME_META_HEADER: metas[k % n]}
        bare.request("POST", f"/sessions/{bare_id}/frames", body=frames.raw[k % n], headers=headers)
        response = bare.getresponse()
        body = response.read()
        if response.status != 200:
            raise RuntimeError(f"bare upload answered {response.status}: {body[:200]!r}")

    def png_frame(k: int) -> None:
        client.add_frame(
            png_id,
            frames.millimetres[k % n],
            frames.poses[k % n],
            depth_scale=DEPTH_SCALE,
            max_depth=MAX_DEPTH,
        )

    return [
        Operation(FRAME_HTTP, group, raw_frame, "target"),
        # A camera streaming at 30 Hz leaves both processes idle between frames: caches and
        # clocks go cold, which a tight loop never shows (and the interleaved schedule only partly).
        Operation(FRAME_HTTP_PACED, group, paced_frame, "", lambda k: time.sleep(CAMERA_PERIOD_S)),
        Operation(FRAME_HTTP_BARE, group, bare_frame, "baseline"),
        Operation("multipart upload (raw f32 part, httpx)", group, multipart_frame),
        Operation("VGNClient.add_frame (PNG16 from uint16 mm)", group, png_frame),
    ]


def fused_session(client: VGNClient, frames: Frames) -> str:
    """A session of ``client``'s service with every view fused."""
    session_id = client.create_session(intrinsics=INTRINSICS).session_id
    frames.fuse(client.add_frame, session_id)
    return session_id


def http_grasp_operation(
    client: VGNClient,
    frames: Frames,
    name: str = GRASPS_HTTP,
    group: str = "6 grasps HTTP",
    new_frame: bool = True,
    switches: dict[str, bool] | None = None,
    counts: list[int] | None = None,
) -> tuple[Operation, int]:
    """``VGNClient.grasps`` on a session with every view fused, and its grasp count. With
    ``new_frame`` a frame is posted (untimed) before each request, so that every request runs
    the network (every 15 requests the session is reset and every view fused again); without,
    the service answers from its last network output. ``switches`` ``None`` leaves turn
    averaging and the checks to the service's default, as a plain client does. ``counts``
    collects the grasp count of every call (how much the timed checks had to check)."""
    session_id = fused_session(client, frames)
    options = switches or {}
    grasps = len(client.grasps(session_id, **options).grasps)
    n = len(frames)

    def post_frame(k: int) -> None:
        if k % 15 == 0:  # few frames queued for the cloud; every view again, so each request sees the scene
            client.reset_session(session_id)
            frames.fuse(client.add_frame, session_id)
        client.add_frame(session_id, frames.depths[k % n], frames.poses[k % n], max_depth=MAX_DEPTH)

    def ask(_: int) -> None:
        answer = client.grasps(session_id, **options)
        if counts is not None:
            counts.append(len(answer.grasps))

    operation = Operation(
        name,
        group,
        ask,
        "target" if new_frame and switches is None else "",
        post_frame if new_frame else None,
    )
    return operation, grasps


# 8. Concurrent sessions ------------------------------------------------------------------------
def throughput(url: str, frames: Frames, sessions: int, requests: int) -> dict[str, Any]:
    """Grasp requests per second when ``sessions`` clients, each on its own session, ask
    ``requests`` times each as fast as they can, all starting together."""
    clients = [VGNClient(url) for _ in range(sessions)]
    try:
        ids = [fused_session(client, frames) for client in clients]
        for client, session_id in zip(clients, ids, strict=True):
            client.grasps(session_id)  # warm
        start = threading.Barrier(sessions + 1)

        def ask(index: int) -> list[float]:
            start.wait()
            return [timed(lambda _: clients[index].grasps(ids[index]), k) for k in range(requests)]

        with ThreadPoolExecutor(sessions) as pool:
            futures = [pool.submit(ask, index) for index in range(sessions)]
            start.wait()
            began = time.perf_counter()
            latencies = [ms for future in futures for ms in future.result()]
            elapsed = time.perf_counter() - began
    finally:
        for client in clients:
            client.close()
    return {
        "sessions": sessions,
        "requests": len(latencies),
        "requests_per_s": round(len(latencies) / elapsed, 2),
        "p50_ms": round(float(np.percentile(latencies, 50)), 3),
        "p95_ms": round(float(np.percentile(latencies, 95)), 3),
    }


def concurrency_rows(url: str, frames: Frames, requests: int) -> list[dict[str, Any]]:
    """A throughput row per session count in ``CONCURRENCY``, each with its speed-up over one session."""
    rows = [throughput(url, frames, sessions, requests) for sessions in CONCURRENCY]
    single = rows[0]["requests_per_s"]
    for row in rows:
        row["vs_one_session"] = round(row["requests_per_s"] / single, 2)
    return rows


# Report ------------------------------------------------------------------------------------
def check(name: str, value: float, unit: str, target: float, at_most: bool = True) -> dict[str, Any]:
    """One target check: the value, its target and whether it
    passed (``at_most``: the value must not exceed it)."""
    return {
        "name": name,
        "value": round(value, 3),
        "unit": unit,
        "target": target,
        "at_most": at_most,
        "pass": value <= target if at_most else value >= target,
    }


def targets(rows: list[Measurement], concurrency: list[dict[str, Any]], gpu: bool) -> list[dict[str, Any]]:
    """The project's targets checked on this run; the throughput one only on a GPU."""
    grasp = find(rows, GRASPS_HTTP).p50
    again = find(rows, GRASPS_HTTP_AGAIN).p50
    checks = [
        check("frame request over HTTP p50 (raw f32)", find(rows, FRAME_HTTP).p50, "ms", FRAME_TARGET_MS),
        check("grasp request over HTTP p50", grasp, "ms", GPU_GRASP_TARGET_MS if gpu else GRASP_TARGET_MS),
        check(
            "naive fp32 eager forward+detection p50 / grasp request over HTTP p50",
            find(rows, FORWARD_DETECTION).p50 / grasp,
            "x",
            SPEEDUP_TARGET,
            at_most=False,
        ),
        check(
            "grasp p50, slower / faster of two server starts",
            max(grasp, again) / min(grasp, again),
            "x",
            STEADY_TARGET,
        ),  # fmt: skip
        check("grasp request over HTTP p95 / p50", find(rows, GRASPS_HTTP).p95 / grasp, "x", TAIL_TARGET),
    ]
    if gpu and concurrency:
        checks.append(
            check(
                f"throughput, {CONCURRENCY[-1]} sessions / 1 session",
                concurrency[-1]["vs_one_session"],
                "x",
                THROUGHPUT_TARGET,
                at_most=False,
            )
        )
    return checks


def format_table(rows: list[Measurement]) -> str:
    """The rows as a fixed-width text table: group, name, p50, p95, sample count and note."""
    width = max(len(row.name) for row in rows) + 2
    header = f"{'group':<20}{'name':<{width}}{'p50 ms':>9}{'p95 ms':>9}{'n':>5}  note"
    lines = [header, "-" * (len(header) + 4)]
    for row in rows:
        lines.append(
            f"{row.group:<20}{row.name:<{width}}{row.p50:>9.2f}{row.p95:>9.2f}"
            f"{len(row.samples_ms):>5}  {row.note}"
        )
    return "\n".join(lines)


def format_targets(checks: list[dict[str, Any]]) -> str:
    """One line per target check, with its value, target and PASS or MISS."""
    lines = []
    for check in checks:
        unit = " ms" if check["unit"] == "ms" else "x"
        verdict = "PASS" if check["pass"] else "MISS"
        relation = "<=" if check["at_most"] else ">="
        lines.append(
            f"  {check['name']}: {check['value']:.2f}{unit} (target {relation} {check['target']:g}{unit})  {verdict}"
        )
    return "\n".join(lines)


def environment(
    args: argparse.Namespace, weights: Path, random_weights: bool, threshold: float
) -> dict[str, Any]:
    """Versions, machine, settings and inputs of the run, so that its figures can be compared."""
    return {
        "python": platform.python_version(),
        "torch": torch.__version__,
        "open3d": o3d.__version__,
        "cpu_count": os.cpu_count(),
        "torch_threads": args.threads,
        "device": str(resolve_device(args.device)),
        "repeats": args.repeats,
        "warmup": args.warmup,
        "schedule": args.schedule,
        "weights": shown_path(weights),
        "weights_id": weights_id(weights),
        "random_weights": random_weights,
        "frame": f"{INTRINSICS.width}x{INTRINSICS.height} float32",
        "grid": f"{RESOLUTION}^3 from {VIEWS} views",
        "threshold": threshold,
        "load_average_at_start": load_average(),
    }


def shown_path(path: Path) -> str:
    """``path`` relative to the working directory when inside it: result files carry no
    machine's folders."""
    try:
        return str(path.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return path.name


def load_average() -> list[float]:
    """1, 5 and 15 minute load averages: other work on the machine skews every row."""
    return [round(value, 2) for value in os.getloadavg()] if hasattr(os, "getloadavg") else []


def format_header(env: dict[str, Any]) -> str:
    """The environment as the lines that open the printed report."""
    weights = (
        "random-initialised (the network's cost does not depend on its weights; the number of grasps does)"
        if env["random_weights"]
        else env["weights"]
    )
    return "\n".join(
        [
            f"vgn-service latency benchmark: {env['repeats']} timed + {env['warmup']} warm-up "
            f"calls per operation, schedule {env['schedule']}",
            f"  python {env['python']}, torch {env['torch']}, open3d {env['open3d']}, "
            f"{env['cpu_count']} CPU cores, device {env['device']}",
            f"  torch threads: {env['torch_threads']} in this process and in the servers; benchmark and "
            "servers share the cores",
            f"  server runtime: {env.get('server_runtime')}",
            f"  weights: {weights}",
            f"  input: {env['frame']} BoxScene depth frames; grid {env['grid']}; "
            f"threshold {env['threshold']} (the service's default for these weights)",
            f"  load average at start (1/5/15 min): {env['load_average_at_start']}",
        ]
    )


def write_json(path: Path, payload: dict[str, Any]) -> None:
    """Write ``payload`` atomically: a temp file in the same directory, then ``os.replace``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(handle, "w") as stream:
            json.dump(payload, stream, indent=2)
            stream.write("\n")
        os.replace(temporary, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(temporary)
        raise


# Main --------------------------------------------------------------------------------------
def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line (``--repeats``, ``--model``, ``--threads``, ...), checked for sane counts."""
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.latency",
        description=__doc__.split("\n\n")[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--repeats", type=int, default=50, help="timed calls per operation")
    parser.add_argument(
        "--warmup",
        type=int,
        default=5,
        help="untimed calls per operation before timing (default: %(default)s)",
    )
    parser.add_argument(
        "--model",
        type=Path,
        default=None,
        help="VGN weights (.safetensors/.pt/.pth); default: the packaged model",
    )
    parser.add_argument(
        "--random-weights",
        action="store_true",
        help="random-initialised weights instead: the network's cost alone (they return no grasps)",
    )
    parser.add_argument(
        "--threads",
        type=int,
        default=None,
        help="torch threads here and in the servers (default: the service's own choice)",
    )
    parser.add_argument(
        "--concurrent-requests",
        type=int,
        default=8,
        help="grasp requests per session in the throughput rows (0 skips them; default: %(default)s)",
    )
    parser.add_argument(
        "--device",
        choices=("auto", "cpu", "cuda"),
        default="auto",
        help="torch device of the baseline, the core and the server",
    )
    parser.add_argument(
        "--schedule",
        choices=("interleaved", "blocks"),
        default="interleaved",
        help="round-robin over operations, or each operation back to back",
    )
    parser.add_argument("--json", type=Path, default=None, help="also write the results here")
    parser.add_argument("--skip-grpc", action="store_true", help="leave out the gRPC rows")
    args = parser.parse_args(argv)
    if args.model is not None and args.random_weights:
        parser.error("--model and --random-weights exclude each other")
    if args.model is None and not args.random_weights and not PACKAGED_MODEL.is_file():
        parser.error(f"no packaged model at {PACKAGED_MODEL}: give --model or --random-weights")
    if args.repeats < 1 or args.warmup < 0 or (args.threads is not None and args.threads < 1):
        parser.error("--repeats and --threads must be >= 1, --warmup >= 0")
    return args


@dataclass
class Results:
    """Everything ``measure_all`` collects, for printing and the JSON file."""

    rows: list[Measurement]
    grasps: dict[str, int]
    concurrency: list[dict[str, Any]]
    server_runtime: dict[str, Any]
    threshold: float  # the service's default for the weights: every row's


def measure_all(args: argparse.Namespace, weights: Path) -> Results:
    """Every measurement in table order, the grasp count of each grasp path, the throughput
    rows and what the (first) server reported about its runtime."""
    frames = render_frames()
    with (
        running_service(weights, args.threads, args.device) as client,
        running_service(weights, args.threads, args.device) as second,
    ):
        reported = client.model()
        threads = (
            args.threads or (reported.runtime and reported.runtime.torch_threads) or configured_threads()
        )
        torch.set_num_threads(threads)  # the baseline gets the threads the service chose
        args.threads = threads
        core = PlanningService.from_settings(
            Settings(model=weights, torch_threads=threads, device=args.device, api_key=None)
        )
        other = other_options(service_defaults(reported))  # refuses a service that reports no defaults
        threshold = reported.defaults.threshold  # type: ignore[union-attr]  # present: refused above otherwise
        network, direct_grasps = network_operations(
            weights, resolve_device(args.device), fused_grid(frames), threshold
        )
        plan, core_grasps = core_plan_operation(core, frames, GraspQuery())
        other_query = GraspQuery(**other)
        plan_other, _ = core_plan_operation(core, frames, other_query, other_way(PLAN, other))
        timed_counts: list[int] = []
        grasps_http, http_grasps = http_grasp_operation(client, frames, counts=timed_counts)
        grasps_again, _ = http_grasp_operation(second, frames, GRASPS_HTTP_AGAIN, "7 steadiness")
        grasps_kept, _ = http_grasp_operation(client, frames, GRASPS_HTTP_KEPT, new_frame=False)
        kept_again, _ = http_grasp_operation(
            second, frames, GRASPS_HTTP_KEPT_AGAIN, "7 steadiness", new_frame=False
        )
        grasps_other, _ = http_grasp_operation(client, frames, other_way(GRASPS_HTTP, other), switches=other)
        operations = (
            fusion_operations(frames)
            + core_frame_operations(core, frames)
            + http_frame_operations(client, frames)
            + network
            # The two servers' default requests are compared for steadiness, so each follows the
            # same light request on its own server: what runs just before a request (in-process
            # planning here) slows it by a few milliseconds on 2 cores.
            + [plan, plan_other, grasps_other, grasps_kept, grasps_http, kept_again, grasps_again]
        )
        schedule = run_interleaved if args.schedule == "interleaved" else run_blocks
        rows = schedule(operations, args.repeats, args.warmup)
        concurrency = []
        if args.concurrent_requests:
            # Repeated requests on unchanged sessions would be answered from kept outputs:
            # this server runs the network for every request, to measure the batching.
            no_reuse = {"VGN_REUSE_OUTPUT": "false"}
            with running_service(weights, args.threads, args.device, no_reuse) as batching:
                concurrency = concurrency_rows(batching.url, frames, args.concurrent_requests)
        model = client.model()
        runtime = {
            **(model.runtime.model_dump(exclude_none=True) if model.runtime else {}),
            "device": model.device,
        }
    total = sum_of(FORWARD_DETECTION, [find(rows, FORWARD), find(rows, DETECTION)], "baseline")
    rows.insert(rows.index(find(rows, DETECTION)) + 1, total)
    for default in (PLAN, GRASPS_HTTP):
        row = find(rows, other_way(default, other))
        row.note = f"{row.p50 / find(rows, default).p50:.2f}x the default row above (paired)"
    bare = find(rows, FRAME_HTTP_BARE).p50
    find(rows, FRAME_HTTP).note += f" ({find(rows, FRAME_HTTP).p50 / bare:.2f}x the bare upload)"
    grasps = {"direct": direct_grasps, "in_process": core_grasps, "http": http_grasps,
              "http_timed_median": float(np.median(timed_counts)), "http_timed_min": min(timed_counts)}  # fmt: skip
    return Results(rows, grasps, concurrency, runtime, threshold)


def format_concurrency(rows: list[dict[str, Any]]) -> str:
    """The throughput rows as a text table."""
    lines = [f"{'sessions':>8}{'requests':>10}{'req/s':>9}{'x one':>8}{'p50 ms':>9}{'p95 ms':>9}"]
    for row in rows:
        lines.append(
            f"{row['sessions']:>8}{row['requests']:>10}{row['requests_per_s']:>9.1f}"
            f"{row['vs_one_session']:>8.2f}{row['p50_ms']:>9.2f}{row['p95_ms']:>9.2f}"
        )
    return "\n".join(lines)


def grpc_section(
    args: argparse.Namespace, weights: Path, threads: int | None
) -> tuple[list[Measurement], list[dict[str, Any]]]:
    """The gRPC rows beside their HTTP twins (``benchmarks.grpc_latency``), and their targets;
    none with ``--skip-grpc`` or without the grpc extra. Like the other servers, theirs runs
    the default configuration unless ``--threads`` was given."""
    if args.skip_grpc:
        return [], []
    try:
        from benchmarks import grpc_latency
    except ImportError as error:
        print(f"gRPC rows left out: {error} (pip install 'vgn-service[grpc]')", flush=True)
        return [], []
    rows = grpc_latency.measure(weights, threads, args.device, render_frames(), args.repeats,
                                args.warmup, args.schedule == "interleaved")  # fmt: skip
    return rows, grpc_latency.targets(rows)


def main(argv: list[str] | None = None) -> int:
    """Measure, print the report and the target checks, and write the JSON file if asked."""
    args = parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="vgn-bench-") as directory:
        weights, random_weights = weights_path(args.model, args.random_weights, Path(directory))
        load_at_start = load_average()
        requested_threads = args.threads  # measure_all replaces it with the service's choice
        results = measure_all(args, weights)
        grpc_rows, grpc_checks = grpc_section(args, weights, requested_threads)
    env = environment(args, weights, random_weights, results.threshold)
    env["load_average_at_start"] = load_at_start
    env["server_runtime"] = results.server_runtime
    gpu = str(results.server_runtime.get("device", env["device"])).startswith("cuda")
    checks = targets(results.rows, results.concurrency, gpu)
    env["load_average_at_end"] = load_average()
    print(format_header(env), flush=True)
    print()
    print(format_table(results.rows))
    grasps = results.grasps
    print(
        f"\ngrasps returned at threshold {results.threshold}: direct {grasps['direct']}, "
        f"in-process {grasps['in_process']}, HTTP {grasps['http']} (every view fused); the timed default "
        f"requests over HTTP: median {grasps['http_timed_median']:g}, least {grasps['http_timed_min']}"
    )
    if results.concurrency:
        print("\ngrasp requests over HTTP from concurrent sessions (micro-batched; VGN_REUSE_OUTPUT=false):")
        print(format_concurrency(results.concurrency))
    print(f"load average at end (1/5/15 min): {env['load_average_at_end']}")
    print("targets:" + ("" if gpu else " (no GPU: the GPU targets are not checked)"))
    print(format_targets(checks))
    if grpc_rows:
        from benchmarks import grpc_latency

        print("\ngRPC beside HTTP (one server serving both):")
        print(format_table(grpc_rows))
        print(grpc_latency.format_rates(grpc_rows))
        print("gRPC targets:")
        print(grpc_latency.format_targets(grpc_checks))
    if args.json is not None:
        write_json(
            args.json,
            {
                "environment": env,
                "grasps": grasps,
                "targets": checks,
                "concurrency": results.concurrency,
                "results": [row.as_dict() for row in results.rows],
                "grpc": {"targets": grpc_checks, "results": [row.as_dict() for row in grpc_rows]},
            },
        )
        print(f"\nresults written to {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
