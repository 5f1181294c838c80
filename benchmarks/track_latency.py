"""The closed loop's cycle: fuse one frame and plan, over a gRPC ``Track`` stream.

    python -m benchmarks.track_latency --out docs/results/closed-loop-latency

One uvicorn child serves both front ends in its default configuration (the default request:
turn averaging, the clearance and grip checks). Measured, interleaved round by round:

* ``Track`` cycle: one frame sent on an open ``Track`` stream until its grasps come back
  (``plan_every`` 1), client side; the stream stays open for the whole run;
* the same work as two unary calls: ``GRPCClient.add_frame`` then ``GRPCClient.grasps``;
* the same over HTTP: ``VGNClient.add_frame`` then ``VGNClient.grasps``;
* what forgetting costs: a frame upload into a session with ``decay`` beside one without.

Target: the ``Track`` cycle p50 at most 33 ms (30 Hz) on 2 cores. Writes ``latency.json`` (the
rows and the targets, read by ``python -m benchmarks.report``).
"""

from __future__ import annotations

import argparse
import json
import os
import queue
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from benchmarks.timing import Measurement, Operation, find, run_interleaved
from benchmarks.workload import INTRINSICS, Frames, render_frames
from client.grpc_client import GRPCClient
from client.http import VGNClient
from service.launch.embedded import EmbeddedService
from vgn_data.files import write_atomically

CYCLE_TARGET_MS = 33.0
DECAY = 0.5
TRACK = "gRPC Track: one frame in, its grasps out"
UNARY_GRPC = "gRPC add_frame + grasps"
UNARY_HTTP = "HTTP add_frame + grasps"
FRAME_PLAIN = "HTTP add_frame, static session"
FRAME_DECAY = f"HTTP add_frame, forgetting session (decay {DECAY})"


class TrackLoop:
    """An open ``Track`` stream driven one frame at a time: ``cycle(depth, pose)`` sends a frame
    and waits for the grasps planned after it."""

    def __init__(self, rpc: GRPCClient, session_id: str) -> None:
        self._frames: queue.Queue = queue.Queue()
        self._updates = rpc.track(session_id, self._next_frames())

    def _next_frames(self) -> Iterator[tuple[Any, Any]]:
        while (frame := self._frames.get()) is not None:
            yield frame

    def cycle(self, depth: Any, pose: Any) -> None:
        """Send one frame and wait for the grasps planned after it."""
        self._frames.put((depth, pose))
        next(self._updates)

    def close(self) -> None:
        """End the stream (no more frames) and read what is left of it."""
        self._frames.put(None)
        for _ in self._updates:  # drain: the stream ends with its last frame
            pass


def operations(http: VGNClient, rpc: GRPCClient, frames: Frames, loop: TrackLoop,
               sessions: dict[str, str]) -> list[Operation]:  # fmt: skip
    """The timed calls; each round uses the next frame of the six views, so every plan runs
    the network on a volume that just changed."""

    def frame(i: int) -> tuple[Any, Any]:
        return frames.depths[i % len(frames)], frames.poses[i % len(frames)]

    def unary(client: VGNClient | GRPCClient, session: str) -> Callable[[int], None]:
        def call(i: int) -> None:
            client.add_frame(session, *frame(i))
            client.grasps(session)

        return call

    return [
        Operation(TRACK, "cycle", lambda i: loop.cycle(*frame(i))),
        Operation(UNARY_GRPC, "cycle", unary(rpc, sessions["grpc"])),
        Operation(UNARY_HTTP, "cycle", unary(http, sessions["http"])),
        Operation(FRAME_PLAIN, "forgetting", lambda i: http.add_frame(sessions["plain"], *frame(i))),
        Operation(FRAME_DECAY, "forgetting", lambda i: http.add_frame(sessions["decay"], *frame(i))),
    ]


def measure(repeats: int, warmup: int) -> list[Measurement]:
    """Every row, on one embedded service in its default configuration."""
    frames = render_frames()
    with (
        EmbeddedService(grpc=True) as service,
        VGNClient(service.url) as http,
        GRPCClient(service.grpc_url) as rpc,
    ):
        sessions = {
            name: http.create_session(intrinsics=INTRINSICS).session_id for name in ("grpc", "http", "plain")
        }
        sessions["decay"] = http.create_session(intrinsics=INTRINSICS, decay=DECAY).session_id
        tracked = rpc.create_session(intrinsics=INTRINSICS).session_id
        loop = TrackLoop(rpc, tracked)
        try:
            return run_interleaved(operations(http, rpc, frames, loop, sessions), repeats, warmup)
        finally:
            loop.close()


def report(rows: list[Measurement], repeats: int, load: tuple[float, float, float]) -> dict[str, Any]:
    """Rows and targets in the form of ``benchmarks.latency``'s report, which
    ``python -m benchmarks.report`` tabulates (date and machine: ``--stamp``)."""
    track, plain, decay = find(rows, TRACK), find(rows, FRAME_PLAIN), find(rows, FRAME_DECAY)
    cycle = track.percentile(50)
    return {
        "environment": {
            "repeats": repeats,
            "schedule": "interleaved",
            "cpu_count": os.cpu_count(),
            "load_average_at_start": [round(x, 2) for x in load],
        },  # fmt: skip
        "results": [
            {
                "name": r.name,
                "group": r.group,
                "p50_ms": round(r.percentile(50), 2),
                "p95_ms": round(r.percentile(95), 2),
                "n": len(r.samples_ms),
            }
            for r in rows
        ],  # fmt: skip
        "targets": [
            {
                "name": f"Track cycle p50 (ms), target <= {CYCLE_TARGET_MS:g}",
                "value": round(cycle, 2),
                "pass": cycle <= CYCLE_TARGET_MS,
            },
            {
                "name": "forgetting frame upload / static one, p50 (what forgetting costs)",
                "value": round(decay.percentile(50) / plain.percentile(50), 2),
            },
        ],  # fmt: skip
    }


def main(argv: list[str] | None = None) -> int:
    """Measure, write ``--out``/latency.json and print the rows and targets."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--repeats", type=int, default=200)
    parser.add_argument("--warmup", type=int, default=20)
    parser.add_argument("--out", type=Path, default=Path("results/closed-loop-latency"))
    args = parser.parse_args(argv)
    load = os.getloadavg()
    result = report(measure(args.repeats, args.warmup), args.repeats, load)
    args.out.mkdir(parents=True, exist_ok=True)
    write_atomically(args.out / "latency.json", json.dumps(result, indent=2) + "\n")
    for row in result["results"]:
        print(f"{row['name']:55s} p50 {row['p50_ms']:7.2f} ms  p95 {row['p95_ms']:7.2f} ms", file=sys.stderr)
    for target in result["targets"]:
        print(f"{target['name']}: {target['value']}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
