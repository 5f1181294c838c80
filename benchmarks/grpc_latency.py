"""gRPC rows of the latency benchmark, each beside its HTTP twin on the same server and run.

One uvicorn child serves both front ends (``EmbeddedService(grpc=True)``), in the default
configuration like the other benchmark servers unless ``--threads`` is given, so the HTTP and
gRPC rows differ only in the transport. Measured:

* a frame upload (640×480 raw float32): ``VGNClient.add_frame`` vs ``GRPCClient.add_frame``;
* a grasp request on a 6-view session: ``VGNClient.grasps`` vs ``GRPCClient.grasps``, each
  after a new frame (posted untimed), so that every request runs the network rather than
  being answered from the session's kept output;
* a stream of ``STREAM_FRAMES`` frames: ``GRPCClient.stream_frames`` (one call), against the
  same frames uploaded one request after another over HTTP; reported as frames per second.

Targets: gRPC frame upload p50 no slower than HTTP's (ratio <= 1), streaming >= 150 frames/s.

The server queues up to ``STREAM_FRAMES`` + 4 frames for the fine (cloud) volume
(``VGN_CLOUD_MAX_PENDING_FRAMES``) and every stream starts on a reset session, so these rows
time the transport and the coarse fusion: with the default queue of 16, a long stream also
fuses each frame into the 120³ cloud volume (~25 ms a frame on the 2-core VM), whatever the
front end.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from benchmarks.latency import (
    INTRINSICS,
    MAX_DEPTH,
    RUNTIME_VARIABLES,
    THRESHOLD,
    Frames,
    Measurement,
    Operation,
    find,
    run_blocks,
    run_interleaved,
)
from client.embedded import EmbeddedService
from client.grpc_client import GRPCClient
from client.http import VGNClient

STREAM_FRAMES = 60
STREAM_RATE_TARGET = 150.0
FRAME_HTTP = "HTTP VGNClient.add_frame (raw f32)"
FRAME_GRPC = "gRPC GRPCClient.add_frame (raw f32)"
GRASPS_HTTP = "HTTP VGNClient.grasps"
GRASPS_GRPC = "gRPC GRPCClient.grasps"
STREAM_HTTP = f"HTTP {STREAM_FRAMES} add_frame calls"
STREAM_GRPC = f"gRPC stream_frames ({STREAM_FRAMES} frames)"


def frame_operations(http: VGNClient, rpc: GRPCClient, frames: Frames) -> list[Operation]:
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
    session_id = http.create_session(intrinsics=INTRINSICS).session_id  # one session, both front ends
    for depth, pose in zip(frames.depths, frames.poses, strict=True):
        http.add_frame(session_id, depth, pose, max_depth=MAX_DEPTH)
    group, n = "10 grasps HTTP|gRPC", len(frames)

    def post_frame(k: int) -> None:  # so that every request runs the network
        if k % 15 == 0:  # keep the session's pending cloud frames below the flush point
            http.reset_session(session_id)
        http.add_frame(session_id, frames.depths[k % n], frames.poses[k % n], max_depth=MAX_DEPTH)

    return [
        Operation(
            GRASPS_HTTP, group, lambda k: http.grasps(session_id, threshold=THRESHOLD), "baseline", post_frame
        ),
        Operation(GRASPS_GRPC, group, lambda k: rpc.grasps(session_id, threshold=THRESHOLD), "", post_frame),
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


def measure(weights: Path, threads: int | None, device: str, frames: Frames, repeats: int, warmup: int,
            interleaved: bool) -> list[Measurement]:  # fmt: skip
    """The gRPC rows and their HTTP twins, from one server serving both; without ``threads``
    it runs the service's default configuration (none of ``RUNTIME_VARIABLES`` reach it)."""
    env = {"VGN_DEVICE": device, "VGN_API_KEY": "", "VGN_CLOUD_MAX_PENDING_FRAMES": str(STREAM_FRAMES + 4)}
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
    return rows


def frames_per_second(row: Measurement) -> float:
    return STREAM_FRAMES / (row.p50 / 1e3)


def targets(rows: list[Measurement]) -> list[dict[str, Any]]:
    ratio = find(rows, FRAME_GRPC).p50 / find(rows, FRAME_HTTP).p50
    rate = frames_per_second(find(rows, STREAM_GRPC))
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
    ]


def format_rates(rows: list[Measurement]) -> str:
    http, rpc = frames_per_second(find(rows, STREAM_HTTP)), frames_per_second(find(rows, STREAM_GRPC))
    return (
        f"frames per second: HTTP one request per frame {http:.1f}, gRPC stream {rpc:.1f} ({rpc / http:.2f}x)"
    )


def format_targets(checks: list[dict[str, Any]]) -> str:
    lines = []
    for check in checks:
        comparison = ">=" if check["unit"] == "frames/s" else "<="
        verdict = "PASS" if check["pass"] else "MISS"
        lines.append(
            f"  {check['name']}: {check['value']:g} {check['unit']} "
            f"(target {comparison} {check['target']:g})  {verdict}"
        )
    return "\n".join(lines)
