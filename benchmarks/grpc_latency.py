"""gRPC rows of the latency benchmark, each beside its HTTP twin on the same server and run.

One uvicorn child serves both front ends (``EmbeddedService(grpc=True)``), in the default
configuration like the other benchmark servers unless ``--threads`` is given, so the HTTP and
gRPC rows differ only in the transport. Measured:

* a frame upload (640×480 raw float32): ``VGNClient.add_frame`` vs ``GRPCClient.add_frame``;
* a grasp request on a 6-view session: ``VGNClient.grasps`` vs ``GRPCClient.grasps``, each
  after a new frame (posted untimed), so that every request runs the network rather than
  being answered from the session's kept output;
* a stream of ``STREAM_FRAMES`` frames: ``GRPCClient.stream_frames`` (one call), against the
  same frames uploaded one request after another over HTTP; reported as frames per second;
* a long stream of ``LONG_STREAM_FRAMES`` frames over gRPC, beside fusing the same frames
  into a bare coarse ``TSDFVolume`` in this process (what a frame costs at the least);
* the cost the queue moves to the reader: ``GRPCClient.cloud`` right after a stream of
  ``STREAM_FRAMES`` frames (posted untimed), which fuses the frames still queued, beside
  fusing the same frames into a bare 120³ ``TSDFVolume`` in this process.

Targets: gRPC frame upload p50 no slower than HTTP's (ratio <= 1), streaming >= 150 frames/s,
the long stream included.

The server runs the default cloud queue (``VGN_CLOUD_MAX_PENDING_FRAMES``): uploads queue
their frames for the 120³ cloud volume and never fuse it; every stream starts on a reset
session. Frames of the upload rows' sessions are fused by the service's background worker
in lulls, between rows, as they would be in real use.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from benchmarks.timing import Measurement, Operation, find, run_blocks, run_interleaved
from benchmarks.workload import (
    INTRINSICS,
    MAX_DEPTH,
    RESOLUTION,
    RUNTIME_VARIABLES,
    WORKSPACE_SIZE,
    Frames,
)
from client.grpc_client import GRPCClient
from client.http import VGNClient
from service.launch.embedded import EmbeddedService
from service.tsdf import TSDFVolume

STREAM_FRAMES = 60
LONG_STREAM_FRAMES = 300
STREAM_RATE_TARGET = 150.0
#: The service's default ``VGN_CLOUD_RESOLUTION``.
CLOUD_RESOLUTION = 120
FRAME_HTTP = "HTTP VGNClient.add_frame (raw f32)"
FRAME_GRPC = "gRPC GRPCClient.add_frame (raw f32)"
GRASPS_HTTP = "HTTP VGNClient.grasps"
GRASPS_GRPC = "gRPC GRPCClient.grasps"
STREAM_HTTP = f"HTTP {STREAM_FRAMES} add_frame calls"
STREAM_GRPC = f"gRPC stream_frames ({STREAM_FRAMES} frames)"
LONG_STREAM_GRPC = f"gRPC stream_frames ({LONG_STREAM_FRAMES} frames)"
LONG_STREAM_COARSE = f"TSDFVolume.integrate, coarse 40³ only ({LONG_STREAM_FRAMES} frames, in process)"
CLOUD_AFTER_STREAM = f"gRPC cloud right after a {STREAM_FRAMES}-frame stream"
FINE_FUSION = f"TSDFVolume.integrate, fine {CLOUD_RESOLUTION}³ ({STREAM_FRAMES} frames, in process)"


def frame_operations(http: VGNClient, rpc: GRPCClient, frames: Frames) -> list[Operation]:
    """One frame upload over each front end, on a session of its own, cycling through ``frames``."""
    n, group = len(frames), "9 frame HTTP|gRPC"
    http_id = http.create_session(intrinsics=INTRINSICS).session_id
    grpc_id = rpc.create_session(intrinsics=INTRINSICS).session_id

    def over_http(k: int) -> None:
        http.add_frame(http_id, frames.depths[k % n], frames.poses[k % n], max_depth=MAX_DEPTH)

    def over_grpc(k: int) -> None:
        rpc.add_frame(grpc_id, frames.depths[k % n], frames.poses[k % n], max_depth=MAX_DEPTH)

    return [
        Operation(FRAME_HTTP, group, over_http, "baseline"),
        Operation(FRAME_GRPC, group, over_grpc, "target"),
    ]


def grasp_operations(http: VGNClient, rpc: GRPCClient, frames: Frames) -> list[Operation]:
    """A grasp request over each front end on one shared 6-view session, each after an untimed new frame."""
    session_id = http.create_session(intrinsics=INTRINSICS).session_id  # one session, both front ends
    frames.fuse(http.add_frame, session_id)
    group, n = "10 grasps HTTP|gRPC", len(frames)

    def post_frame(k: int) -> None:  # so that every request runs the network
        if k % 15 == 0:  # few frames queued for the cloud; every view again, so each request sees the scene
            http.reset_session(session_id)
            frames.fuse(http.add_frame, session_id)
        http.add_frame(session_id, frames.depths[k % n], frames.poses[k % n], max_depth=MAX_DEPTH)

    return [
        Operation(GRASPS_HTTP, group, lambda k: http.grasps(session_id), "baseline", post_frame),
        Operation(GRASPS_GRPC, group, lambda k: rpc.grasps(session_id), "", post_frame),
    ]


def stream_operations(http: VGNClient, rpc: GRPCClient, frames: Frames) -> list[Operation]:
    """``STREAM_FRAMES`` frames per call; each call starts on a freshly reset session."""
    n, group = len(frames), "11 stream HTTP|gRPC"
    batch = [(frames.depths[i % n], frames.poses[i % n]) for i in range(STREAM_FRAMES)]
    http_id = http.create_session(intrinsics=INTRINSICS).session_id
    grpc_id = rpc.create_session(intrinsics=INTRINSICS).session_id

    def over_http(_: int) -> None:
        http.reset_session(http_id)
        for depth, pose in batch:
            http.add_frame(http_id, depth, pose, max_depth=MAX_DEPTH)

    def over_grpc(_: int) -> None:
        rpc.reset_session(grpc_id)
        result = rpc.stream_frames(grpc_id, batch, max_depth=MAX_DEPTH)
        assert result.frames_received == STREAM_FRAMES, result

    return [
        Operation(STREAM_HTTP, group, over_http, "baseline"),
        Operation(STREAM_GRPC, group, over_grpc, "target"),
    ]


def long_stream_operations(rpc: GRPCClient, frames: Frames) -> list[Operation]:
    """A long stream on a reset session, and the bare coarse fusion of the same frames."""
    n, group = len(frames), "12 long stream|coarse fusion"
    batch = [(frames.depths[i % n], frames.poses[i % n]) for i in range(LONG_STREAM_FRAMES)]
    session_id = rpc.create_session(intrinsics=INTRINSICS).session_id

    def over_grpc(_: int) -> None:
        rpc.reset_session(session_id)
        result = rpc.stream_frames(session_id, batch, max_depth=MAX_DEPTH)
        assert result.frames_received == LONG_STREAM_FRAMES, result

    def coarse_only(_: int) -> None:
        volume = TSDFVolume(WORKSPACE_SIZE, RESOLUTION)
        for depth, pose in batch:
            volume.integrate(depth, INTRINSICS, pose, MAX_DEPTH)

    return [
        Operation(LONG_STREAM_COARSE, group, coarse_only, "baseline"),
        Operation(LONG_STREAM_GRPC, group, over_grpc, "target"),
    ]


def cloud_read_operations(rpc: GRPCClient, frames: Frames) -> list[Operation]:
    """A cloud read after a stream, and the bare fine fusion of the stream's frames."""
    n, group = len(frames), "13 cloud read|fine fusion"
    batch = [(frames.depths[i % n], frames.poses[i % n]) for i in range(STREAM_FRAMES)]
    session_id = rpc.create_session(intrinsics=INTRINSICS).session_id

    def stream(_: int) -> None:
        rpc.reset_session(session_id)
        rpc.stream_frames(session_id, batch, max_depth=MAX_DEPTH)

    def read(_: int) -> None:
        assert len(rpc.cloud(session_id)) > 0

    def fine_only(_: int) -> None:
        volume = TSDFVolume(WORKSPACE_SIZE, CLOUD_RESOLUTION)
        for depth, pose in batch:
            volume.integrate(depth, INTRINSICS, pose, MAX_DEPTH)

    return [
        Operation(FINE_FUSION, group, fine_only, "baseline"),
        Operation(CLOUD_AFTER_STREAM, group, read, "", stream),
    ]


def measure(weights: Path, threads: int | None, device: str, frames: Frames, repeats: int, warmup: int,
            interleaved: bool) -> list[Measurement]:  # fmt: skip
    """The gRPC rows and their HTTP twins, from one server serving both; without ``threads``
    it runs the service's default configuration (none of ``RUNTIME_VARIABLES`` reach it)."""
    env = {"VGN_DEVICE": device, "VGN_API_KEY": ""}
    if threads is not None:
        env["VGN_TORCH_THREADS"] = str(threads)
    unset = RUNTIME_VARIABLES if threads is None else ()
    with (
        EmbeddedService(model=weights, env=env, unset=unset, grpc=True) as service,
        VGNClient(service.url) as http,
        GRPCClient(service.grpc_url) as rpc,
    ):
        schedule = run_interleaved if interleaved else run_blocks
        rows = schedule(
            frame_operations(http, rpc, frames) + grasp_operations(http, rpc, frames), repeats, warmup
        )
        stream_repeats = max(3, repeats // 5)
        rows += schedule(stream_operations(http, rpc, frames), stream_repeats, min(warmup, 1))
        rows += schedule(long_stream_operations(rpc, frames), max(3, repeats // 10), min(warmup, 1))
        rows += schedule(cloud_read_operations(rpc, frames), max(3, repeats // 10), min(warmup, 1))
    return rows


def frames_per_second(row: Measurement, frames: int = STREAM_FRAMES) -> float:
    """The rate a row's median stream call reaches, ``frames`` being the frames in one call."""
    return frames / (row.p50 / 1e3)


def targets(rows: list[Measurement]) -> list[dict[str, Any]]:
    """The gRPC targets, each with its value and whether it was met: upload ratio and stream rates."""
    ratio = find(rows, FRAME_GRPC).p50 / find(rows, FRAME_HTTP).p50
    rate = frames_per_second(find(rows, STREAM_GRPC))
    long_rate = frames_per_second(find(rows, LONG_STREAM_GRPC), LONG_STREAM_FRAMES)
    return [
        {
            "name": "gRPC frame upload p50 / HTTP frame upload p50",
            "value": round(ratio, 3),
            "unit": "x",
            "target": 1.0,
            "pass": ratio <= 1.0,
        },
        {
            "name": f"gRPC streamed frames per second (p50 of {STREAM_FRAMES}-frame streams)",
            "value": round(rate, 1),
            "unit": "frames/s",
            "target": STREAM_RATE_TARGET,
            "pass": rate >= STREAM_RATE_TARGET,
        },
        {
            "name": f"gRPC streamed frames per second (p50 of {LONG_STREAM_FRAMES}-frame streams, default queue)",
            "value": round(long_rate, 1),
            "unit": "frames/s",
            "target": STREAM_RATE_TARGET,
            "pass": long_rate >= STREAM_RATE_TARGET,
        },
    ]


def format_rates(rows: list[Measurement]) -> str:
    """The stream rows as rates, and the cost of a cloud read next to the fusion it waits for."""
    http, rpc = frames_per_second(find(rows, STREAM_HTTP)), frames_per_second(find(rows, STREAM_GRPC))
    long = find(rows, LONG_STREAM_GRPC).p50 / LONG_STREAM_FRAMES
    coarse = find(rows, LONG_STREAM_COARSE).p50 / LONG_STREAM_FRAMES
    read, fine = find(rows, CLOUD_AFTER_STREAM).p50, find(rows, FINE_FUSION).p50
    return (
        f"frames per second: HTTP one request per frame {http:.1f}, gRPC stream {rpc:.1f} ({rpc / http:.2f}x)\n"
        f"{LONG_STREAM_FRAMES}-frame gRPC stream: {1e3 / long:.1f} frames/s, {long:.2f} ms a frame = "
        f"{long / coarse:.2f}x the bare coarse fusion ({coarse:.2f} ms)\n"
        f"cloud read right after a {STREAM_FRAMES}-frame stream: {read:.0f} ms = {read / fine:.2f}x the "
        f"bare fine fusion of those frames ({fine:.0f} ms): the cost the queue moves from uploads to readers"
    )


def format_targets(checks: list[dict[str, Any]]) -> str:
    """One line per target check, with its comparison and PASS or MISS."""
    lines = []
    for check in checks:
        comparison = ">=" if check["unit"] == "frames/s" else "<="
        verdict = "PASS" if check["pass"] else "MISS"
        lines.append(
            f"  {check['name']}: {check['value']:g} {check['unit']} "
            f"(target {comparison} {check['target']:g})  {verdict}"
        )
    return "\n".join(lines)
