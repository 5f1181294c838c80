"""Would the service's OpenMP defaults slow ``vgn-train``?

    python -m benchmarks.training_openmp [--processes 3] [--steps 5] [--threads 2]

The server sets ``OMP_WAIT_POLICY=PASSIVE`` (``service.runtime``, from ``service.app``),
chosen for steady inference. Training runs other work through
OpenMP (bigger batches, a backward pass) with its own thread count, so this times a VGN
training step — forward, loss, backward, Adam — on a (4, 1, 40, 40, 40) batch in the
channels-last layout ``vgn-train`` uses, in fresh processes, alternately

* with what ``service.runtime.prepare_environment`` sets, as the server does, and
* with those variables removed again before torch loads (libgomp's own default),

and reports each condition's median step time and their ratio. Fresh processes, because
libgomp reads its environment once, when torch loads it; alternation, so that drifts in
the machine's load hit both alike. The load average is printed: on a shared machine it
decides more than the policy does.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from typing import Any

CONDITIONS = ("service", "libgomp-default")
BATCH_SHAPE = (4, 1, 40, 40, 40)


def child(condition: str, steps: int, threads: int) -> dict[str, Any]:
    """Time ``steps`` training steps (after one untimed) in this fresh process."""
    from service.runtime import _prepared, prepare_environment

    prepare_environment()  # the server's OpenMP defaults, before torch loads

    if condition == "libgomp-default":
        for name in _prepared.get("set_by_service", []):
            os.environ.pop(name, None)
    import torch

    from service.vgn.network import VGN

    torch.set_num_threads(threads)
    torch.manual_seed(0)
    network = VGN().to(memory_format=torch.channels_last_3d).train()
    optimizer = torch.optim.Adam(network.parameters(), lr=1e-4)
    grids = torch.randn(BATCH_SHAPE).to(memory_format=torch.channels_last_3d)
    samples = []
    for step in range(steps + 1):
        started = time.perf_counter()
        quality, rotation, width = network(grids)
        loss = quality.mean() + rotation.square().mean() + width.mean()
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        if step:
            samples.append((time.perf_counter() - started) * 1e3)
    return {
        "condition": condition,
        "omp_wait_policy": os.environ.get("OMP_WAIT_POLICY"),
        "threads": torch.get_num_threads(),
        "median_ms": statistics.median(samples),
    }


def run_child(condition: str, steps: int, threads: int) -> dict[str, Any]:
    """Run ``child`` in a fresh interpreter, without the OpenMP variables this process inherited."""
    command = [sys.executable, "-m", "benchmarks.training_openmp", "--child", condition]
    command += ["--steps", str(steps), "--threads", str(threads)]
    env = {
        name: value for name, value in os.environ.items() if name not in ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT")
    }
    done = subprocess.run(command, env=env, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    """Alternate the two conditions in fresh processes and print their median step times and ratio; with
    ``--child``, be one of those processes."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--processes", type=int, default=3, help="fresh processes per condition")
    parser.add_argument("--steps", type=int, default=5, help="timed steps per process")
    parser.add_argument("--threads", type=int, default=2, help="torch threads, as vgn-train --threads")
    parser.add_argument("--child", choices=CONDITIONS, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.processes < 1 or args.steps < 1 or args.threads < 1:
        parser.error("--processes, --steps and --threads must be >= 1")
    if args.child:
        print(json.dumps(child(args.child, args.steps, args.threads)))
        return 0
    print(f"load average at start (1/5/15 min): {os.getloadavg()}", flush=True)
    runs: dict[str, list[float]] = {condition: [] for condition in CONDITIONS}
    for index in range(args.processes):
        order = CONDITIONS if index % 2 == 0 else CONDITIONS[::-1]
        for condition in order:
            result = run_child(condition, args.steps, args.threads)
            runs[condition].append(result["median_ms"])
            print(f"  {condition:>16} (OMP_WAIT_POLICY={result['omp_wait_policy']}): "
                  f"{result['median_ms']:.0f} ms a step", flush=True)  # fmt: skip
    medians = {condition: statistics.median(values) for condition, values in runs.items()}
    ratio = medians["service"] / medians["libgomp-default"]
    print(f"load average at end (1/5/15 min): {os.getloadavg()}")
    print(
        f"median step, {args.threads} threads: with the service's import {medians['service']:.0f} ms, "
        f"libgomp's default {medians['libgomp-default']:.0f} ms; ratio {ratio:.2f} (< 1: the import is faster)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
