"""The CPU runtime settings the service chooses for itself, applied before torch loads.

Why: on small or shared machines the network's cost depends more on OpenMP than on the
network. With two torch threads on a 2-core VM shared with niced background jobs, the same
forward pass took 60-680 ms depending on ``OMP_WAIT_POLICY`` (libgomp's default spins, then
sleeps, and a preempted thread stalls the other at every barrier), while one thread took
the same time on every run. So, unless the operator says otherwise:

* intra-op threads: half the usable cores, at least 1 and at most 8 (1 on a 2-core machine:
  the other core is left to frame fusion, HTTP and whatever else runs there);
* ``OMP_WAIT_POLICY=PASSIVE``: threads sleep at barriers instead of spinning against other
  processes (child processes inherit it, which is what they want too). ``vgn-train`` imports
  this package as well and so trains with it; ``benchmarks/training_openmp.py`` checks that
  this does not slow a training step (it made one about 2x faster on the loaded 2-core VM).

libgomp reads its environment once, when torch's import loads it, so
:func:`prepare_environment` runs from ``service/__init__.py``: ``uvicorn service.app:app``
and the client's embedded service (a child process running the same command) import the
package before anything imports torch. Variables already set are never overridden.
"""

from __future__ import annotations

import os
import sys
from typing import Any

#: Environment defaults the service sets when the operator has not.
WAIT_POLICY = "PASSIVE"
MAX_DEFAULT_THREADS = 8

#: What :func:`prepare_environment` found and did, for ``GET /model``.
_prepared: dict[str, Any] = {}


def usable_cores() -> int:
    """CPU cores this process may run on (affinity and container limits included)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def default_threads(cores: int) -> int:
    """Intra-op threads when ``VGN_TORCH_THREADS`` is unset: half the cores, 1 to 8."""
    return max(1, min(MAX_DEFAULT_THREADS, cores // 2))


def configured_threads(environ: dict[str, str] | os._Environ = os.environ) -> int:
    """``VGN_TORCH_THREADS`` when it is a positive integer, else :func:`default_threads`."""
    value = environ.get("VGN_TORCH_THREADS", "").strip()
    if value.isdigit() and int(value) > 0:
        return int(value)
    return default_threads(usable_cores())


def prepare_environment(environ: dict[str, str] | os._Environ = os.environ) -> dict[str, Any]:
    """Set the OpenMP defaults in ``environ`` (only where unset) and remember whether torch
    had already been imported, in which case they come too late for this process."""
    defaults = {"OMP_WAIT_POLICY": WAIT_POLICY}
    applied = {name: value for name, value in defaults.items() if not environ.get(name)}
    environ.update(applied)
    report = {
        "threads": configured_threads(environ),
        "set_by_service": sorted(applied),
        "before_torch": "torch" not in sys.modules,
    }
    if environ is os.environ:
        _prepared.update(report)
    return report


def apply_threads() -> int:
    """Give torch the configured intra-op thread count (after the environment is prepared)."""
    import torch

    threads = _prepared.get("threads") or configured_threads()
    torch.set_num_threads(threads)
    return threads


def runtime_report() -> dict[str, Any]:
    """What the network runs with, as ``GET /model`` reports it."""
    import torch

    return {
        "torch_threads": torch.get_num_threads(),
        "usable_cores": usable_cores(),
        "omp_wait_policy": os.environ.get("OMP_WAIT_POLICY"),
        "omp_set_by_service": _prepared.get("set_by_service", []),
        "omp_applied_before_torch": bool(_prepared.get("before_torch", False)),
        "torch": torch.__version__,
    }
