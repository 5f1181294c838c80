"""Fleet benchmark: what HAProxy adds to a grasp request, and what a second replica adds to throughput.

    python -m benchmarks.fleet [--repeats N] [--rounds R] [--window S] [--workers W] [--json PATH]

One run starts two fleets side by side (``service.launch.fleet``: uvicorn replicas behind HAProxy), one
with one replica and one with two, in the service's default configuration, and measures

1. the proxy's added latency: a grasp request (the default one, turn-averaged and
   clearance- and grip-checked, on a 6-view session, answered from the session's kept network output so
   that the request's own cost is small and steady) sent to the one-replica fleet's replica
   directly and through HAProxy, over HTTP and over gRPC, the four interleaved call by call on
   one session, each round starting with the next of them; reported as p50 and p95 of each and
   their differences, proxy minus direct;
2. throughput: ``--workers`` clients, each on its own session, loop a robot's cycle (a new
   640×480 frame, then a default grasp request, which then runs the network) through the
   proxy as fast as they can for ``--window`` seconds; the one-replica and the two-replica
   fleet take turns, ``--rounds`` windows each in the order ABBA, so that slow drifts of the
   machine hit both alike. Reported: cycles per second of each (median and range over the
   windows), the speed-up (median of the paired window ratios) and the per-core efficiency,
   speed-up over the cores two replicas could use (min(2, cores)).

Target: the proxy adds at most 1 ms to a grasp request's p50 over HTTP.

The fleets' processes and this one share the machine's cores; between windows each session is
reset, so no fleet has frames queued for its cloud volume that its worker could fuse while the
other fleet is measured. Other load on the machine skews every row; the load average is recorded.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.latency import load_average, write_json
from benchmarks.timing import Measurement, Operation, find, run_interleaved
from benchmarks.workload import INTRINSICS, MAX_DEPTH, RUNTIME_VARIABLES, Frames, render_frames
from client.grpc_client import GRPCClient
from client.http import VGNClient
from service.launch.embedded import free_port
from service.launch.fleet import Fleet, FleetConfig
from service.settings import PACKAGED_MODEL

ADDED_TARGET_MS = 1.0
HTTP_DIRECT, HTTP_PROXY = "HTTP grasps, direct to the replica", "HTTP grasps, through HAProxy"
GRPC_DIRECT, GRPC_PROXY = "gRPC grasps, direct to the replica", "gRPC grasps, through HAProxy"


def fleet_config(replicas: int) -> FleetConfig:
    """A fleet on free loopback ports in the service's default configuration."""
    return FleetConfig(replicas=replicas, http_port=free_port(), grpc_port=free_port(), env={"VGN_API_KEY": ""},
                       unset=RUNTIME_VARIABLES, restart=False)  # fmt: skip


def fused(client: VGNClient | GRPCClient, frames: Frames) -> str:
    """A new session holding every view of ``frames``."""
    session_id = client.create_session(intrinsics=INTRINSICS).session_id
    for depth, pose in zip(frames.depths, frames.poses, strict=True):
        client.add_frame(session_id, depth, pose, max_depth=MAX_DEPTH)
    return session_id


# Proxy latency ---------------------------------------------------------------------------------
def latency_rows(fleet: Fleet, frames: Frames, repeats: int, warmup: int) -> list[Measurement]:
    """The four ways to one session interleaved call by call: direct and proxied, HTTP and gRPC."""
    replica = fleet.replicas[0]
    assert fleet.grpc_url is not None and replica.grpc_url is not None
    with (
        VGNClient(fleet.url) as proxied,
        VGNClient(replica.url) as direct,
        GRPCClient(fleet.grpc_url) as proxied_rpc,
        GRPCClient(replica.grpc_url) as direct_rpc,
    ):
        session_id = fused(proxied, frames)
        operations = [
            Operation(HTTP_DIRECT, "proxy", lambda _: direct.grasps(session_id), "baseline"),
            Operation(HTTP_PROXY, "proxy", lambda _: proxied.grasps(session_id), "target"),
            Operation(GRPC_DIRECT, "proxy", lambda _: direct_rpc.grasps(session_id), "baseline"),
            Operation(GRPC_PROXY, "proxy", lambda _: proxied_rpc.grasps(session_id), ""),
        ]
        return run_interleaved(operations, repeats, warmup, rotate=True)


def added(rows: list[Measurement], direct: str, proxied: str, resamples: int = 2000) -> dict[str, Any]:
    """What the proxy adds: the differences of the p50s and of the p95s, in ms, with a 95 %
    bootstrap interval of the p50 difference (the rounds resampled, keeping each round's pair)."""
    a, b = find(rows, direct), find(rows, proxied)
    pairs = np.array(list(zip(a.samples_ms, b.samples_ms, strict=True)))
    draws = np.random.default_rng(0).integers(0, len(pairs), size=(resamples, len(pairs)))
    differences = np.median(pairs[draws, 1], axis=1) - np.median(pairs[draws, 0], axis=1)
    low, high = np.percentile(differences, [2.5, 97.5])
    return {
        "p50_ms": round(b.p50 - a.p50, 3),
        "p50_ci95_ms": [round(float(low), 3), round(float(high), 3)],
        "p95_ms": round(b.p95 - a.p95, 3),
    }


# Throughput ------------------------------------------------------------------------------------
class Load:
    """``workers`` clients of one fleet, each on its own session, looping frame + grasp request."""

    def __init__(self, fleet: Fleet, frames: Frames, workers: int) -> None:
        self.frames = frames
        self.clients = [VGNClient(fleet.url) for _ in range(workers)]
        self.sessions = [fused(client, frames) for client in self.clients]

    def window(self, seconds: float) -> float:
        """Cycles per second of all workers together over ``seconds``, each session reset first."""
        for client, session_id in zip(self.clients, self.sessions, strict=True):
            client.reset_session(session_id)
            client.add_frame(session_id, self.frames.depths[0], self.frames.poses[0], max_depth=MAX_DEPTH)
        start, counts = threading.Barrier(len(self.clients) + 1), [0] * len(self.clients)
        deadline: list[float] = []

        def loop(index: int) -> None:
            client, session_id, n = self.clients[index], self.sessions[index], len(self.frames)
            start.wait()
            k = 0
            while time.perf_counter() < deadline[0]:
                k += 1
                client.add_frame(
                    session_id, self.frames.depths[k % n], self.frames.poses[k % n], max_depth=MAX_DEPTH
                )
                client.grasps(session_id)
                counts[index] += 1

        threads = [threading.Thread(target=loop, args=(i,)) for i in range(len(self.clients))]
        for thread in threads:
            thread.start()
        began = time.perf_counter()
        deadline.append(began + seconds)
        start.wait()
        for thread in threads:
            thread.join()
        return sum(counts) / (time.perf_counter() - began)

    def close(self) -> None:
        """Close the workers' clients (their sessions end with the fleet)."""
        for client in self.clients:
            client.close()


def throughput(
    one: Fleet, two: Fleet, frames: Frames, workers: int, rounds: int, window_s: float
) -> dict[str, Any]:
    """Windows of the one- and two-replica fleets in ABBA order, and their paired ratios."""
    loads = {1: Load(one, frames, workers), 2: Load(two, frames, workers)}
    try:
        for load in loads.values():
            load.window(min(window_s, 2.0))  # warm-up, not recorded
        rates: dict[int, list[float]] = {1: [], 2: []}
        for round_ in range(rounds):
            for replicas in (1, 2) if round_ % 2 == 0 else (2, 1):
                rates[replicas].append(round(loads[replicas].window(window_s), 3))
                print(
                    f"  round {round_ + 1}: {replicas} replica(s) {rates[replicas][-1]:.2f} cycles/s",
                    file=sys.stderr,
                )
    finally:
        for load in loads.values():
            load.close()
    ratios = [b / a for a, b in zip(rates[1], rates[2], strict=True)]
    speedup = statistics.median(ratios)
    cores = min(2, os.cpu_count() or 1)
    return {
        "workers": workers,
        "window_s": window_s,
        "rounds": rounds,
        "cycle": "a 640x480 float32 frame, then a default grasp request (runs the network)",
        "one_replica": summary(rates[1]),
        "two_replicas": summary(rates[2]),
        "speedup": round(speedup, 3),
        "speedup_range": [round(min(ratios), 3), round(max(ratios), 3)],
        "cores": cores,
        "efficiency_per_core": round(speedup / cores, 3),
    }


def summary(rates: list[float]) -> dict[str, Any]:
    """Median and range of a fleet's window rates, with the rates themselves."""
    return {
        "cycles_per_s": round(statistics.median(rates), 3),
        "min": min(rates),
        "max": max(rates),
        "windows": rates,
    }


# Report ----------------------------------------------------------------------------------------
def haproxy_version() -> str:
    """``HAProxy 2.6.12-1+deb12u4``: the version ``haproxy -v`` prints first."""
    result = subprocess.run(["haproxy", "-v"], capture_output=True, text=True, timeout=10)
    words = result.stdout.split()
    return f"HAProxy {words[2]}" if len(words) > 2 else "HAProxy, version unknown"


def run(args: argparse.Namespace) -> dict[str, Any]:
    """Start both fleets, measure, and return the report."""
    frames = render_frames()
    env = {
        "python": platform.python_version(),
        "cpu_count": os.cpu_count(),
        "haproxy": haproxy_version(),
        "weights": str(PACKAGED_MODEL.relative_to(PACKAGED_MODEL.parents[2])),
        "repeats": args.repeats,
        "warmup": args.warmup,
        "load_average_at_start": load_average(),
    }
    with Fleet(fleet_config(1)) as one, Fleet(fleet_config(2)) as two:
        print("proxy latency ...", file=sys.stderr)
        rows = latency_rows(one, frames, args.repeats, args.warmup)
        print("throughput ...", file=sys.stderr)
        rates = throughput(one, two, frames, args.workers, args.rounds, args.window)
    env["load_average_at_end"] = load_average()
    added_http, added_grpc = added(rows, HTTP_DIRECT, HTTP_PROXY), added(rows, GRPC_DIRECT, GRPC_PROXY)
    return {
        "environment": env,
        "latency": {
            "results": [row.as_dict() for row in rows],
            "added": {"http": added_http, "grpc": added_grpc},
        },
        "throughput": rates,
        "targets": [
            {
                "name": "HAProxy's added latency on a grasp request over HTTP, p50",
                "value": added_http["p50_ms"],
                "unit": "ms",
                "target": ADDED_TARGET_MS,
                "pass": added_http["p50_ms"] <= ADDED_TARGET_MS,
            }
        ],
    }


def format_report(report: dict[str, Any]) -> str:
    """The figures as the lines printed at the end."""
    lines = [f"{'operation':44s} {'p50 ms':>8s} {'p95 ms':>8s}"]
    lines += [
        f"{row['name']:44s} {row['p50_ms']:8.2f} {row['p95_ms']:8.2f}" for row in report["latency"]["results"]
    ]
    for transport, diff in report["latency"]["added"].items():
        low, high = diff["p50_ci95_ms"]
        lines.append(
            f"added by HAProxy, {transport}: p50 {diff['p50_ms']:+.3f} ms (95 % interval {low:+.3f} to {high:+.3f}), "
            f"p95 {diff['p95_ms']:+.3f} ms"
        )
    rates = report["throughput"]
    lines.append(
        f"throughput ({rates['workers']} workers): 1 replica {rates['one_replica']['cycles_per_s']:.2f} cycles/s "
        f"({rates['one_replica']['min']:.2f}-{rates['one_replica']['max']:.2f}), 2 replicas "
        f"{rates['two_replicas']['cycles_per_s']:.2f} ({rates['two_replicas']['min']:.2f}-{rates['two_replicas']['max']:.2f}); "
        f"speed-up {rates['speedup']:.2f}x ({rates['speedup_range'][0]:.2f}-{rates['speedup_range'][1]:.2f}), "
        f"{rates['efficiency_per_core']:.2f} per core"
    )
    for target in report["targets"]:
        verdict = "PASS" if target["pass"] else "MISS"
        lines.append(f"target: {target['name']} {target['value']:g} ms (<= {target['target']:g})  {verdict}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark, print its figures and write them as JSON when asked."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--repeats", type=int, default=300, help="timed calls per latency row (default %(default)s)"
    )
    parser.add_argument("--warmup", type=int, default=20, help="untimed calls per latency row first")
    parser.add_argument("--workers", type=int, default=4, help="concurrent clients in the throughput windows")
    parser.add_argument(
        "--rounds", type=int, default=6, help="throughput windows per fleet (default %(default)s)"
    )
    parser.add_argument("--window", type=float, default=10.0, help="seconds per throughput window")
    parser.add_argument(
        "--json", type=Path, help="also write the report here (e.g. docs/results/fleet/fleet.json)"
    )
    args = parser.parse_args(argv)
    report = run(args)
    print(format_report(report))
    if args.json is not None:
        write_json(args.json, report)
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
