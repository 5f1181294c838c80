"""Labelling throughput of ``generate-data --ray`` against ``--workers`` in the same run.

    python -m benchmarks.ray_generation --workers 2 --scenes 8 --points 40 --repeats 2

Both modes label the same scenes (same seed, fresh folders) through one shared service, in
alternation, so background load hits both alike. Each command reports grasps and seconds from
its workers' start to its last scene (service start excluded, worker start included); the
ratio of the Ray rate to the local rate is the figure that matters (>= 0.9 is the goal). The
load average is printed too: figures from a busy machine are only comparable within a run.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from service.launch.embedded import EmbeddedService

LABELLED = re.compile(r"labelled (\d+) grasps in ([\d.]+) s")


def label(url: str, out: Path, args: argparse.Namespace, ray: bool) -> dict:
    """Run one ``generate-data`` command (``--ray`` or
    ``--workers``) and read its labelling rate from its output."""
    command = [sys.executable, "-m", "client.cli", "generate-data", "--sim", "--url", url, "--scene", "pile",
               "--objects", args.objects, "--scenes", str(args.scenes), "--points", str(args.points),
               "--renderer", args.renderer, "--workers", str(args.workers), "--out", str(out)]  # fmt: skip
    if ray:
        command += ["--ray", args.ray_address] if args.ray_address else ["--ray"]
    started = time.perf_counter()
    run = subprocess.run(command, capture_output=True, text=True, timeout=3600)
    wall = time.perf_counter() - started
    found = LABELLED.search(run.stdout)
    if run.returncode != 0 or not found:
        raise SystemExit(f"generate-data failed ({run.returncode}):\n{run.stderr[-3000:]}")
    grasps, seconds = int(found.group(1)), float(found.group(2))
    return {"mode": "ray" if ray else "workers", "grasps": grasps, "seconds": seconds,
            "grasps_per_s": grasps / seconds, "wall_s": round(wall, 1)}  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    """Alternate the two modes on one embedded service; print their rates and the Ray/workers ratio."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--scenes", type=int, default=8)
    parser.add_argument("--points", type=int, default=40)
    parser.add_argument("--repeats", type=int, default=2, help="alternating runs of each mode")
    parser.add_argument("--objects", default="blocks")
    parser.add_argument("--renderer", choices=["auto", "egl", "tiny"], default="auto")
    parser.add_argument("--ray-address", help="join this Ray cluster (default: a local instance per run)")
    parser.add_argument("--json", type=Path, help="also write the runs and the ratio here")
    args = parser.parse_args(argv)
    runs = []
    with tempfile.TemporaryDirectory() as scratch, EmbeddedService(env={"VGN_TORCH_THREADS": "1"}) as service:
        for repeat in range(args.repeats):
            for ray in (False, True):
                load = os.getloadavg()[0]
                result = label(service.url, Path(scratch) / f"{repeat}-{ray}", args, ray)
                result["load_avg_1min_before"] = round(load, 2)
                runs.append(result)
                print(json.dumps(result), file=sys.stderr, flush=True)
    rate = {mode: sum(r["grasps"] for r in runs if r["mode"] == mode) /
            sum(r["seconds"] for r in runs if r["mode"] == mode) for mode in ("workers", "ray")}  # fmt: skip
    ratio = rate["ray"] / rate["workers"]
    print(f"{args.workers} worker(s), {args.scenes} scenes x {args.points} points, {args.repeats} repeat(s), "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}")  # fmt: skip
    print(f"--workers {args.workers}: {rate['workers']:.2f} grasps/s; --ray: {rate['ray']:.2f} grasps/s; "
          f"ratio ray/workers {ratio:.2f}")  # fmt: skip
    if args.json:
        args.json.write_text(
            json.dumps({"runs": runs, "grasps_per_s": rate, "ratio": ratio}, indent=2) + "\n"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
