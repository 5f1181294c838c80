"""The CPU runtime settings the service chooses for itself, applied before torch loads.

On small or shared machines the network's cost depends more on OpenMP and the allocator than
on the network, so unless the operator says otherwise (variables already set are never
overridden) the server gets: half the usable cores as intra-op threads, 1 to 8 (the rest is
left to fusion and HTTP); ``OMP_WAIT_POLICY=PASSIVE``, so threads sleep at barriers instead of
spinning against other processes and a preempted thread does not stall the rest (children
inherit it); and glibc's allocator keeping freed blocks of up to 32 MB (:func:`tune_malloc`),
so a request's network outputs do not pay page faults on every allocation. libgomp reads its
environment once, when torch loads it, so the server's entry (``service.app``) runs
:func:`prepare_environment` before anything imports torch. Figures: docs/design.md.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys
from typing import Any

#: Environment defaults the service sets when the operator has not.
WAIT_POLICY = "PASSIVE"
MAX_DEFAULT_THREADS = 8

#: glibc ``mallopt`` parameters (malloc.h) and the service's values: keep freed blocks up to
#: the largest mmap threshold glibc accepts on 64-bit systems (32 MB), and trim the heap top
#: only beyond 256 MB.
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
MALLOC_SETTINGS = {
    "mmap_threshold": (M_MMAP_THRESHOLD, 32 << 20),
    "trim_threshold": (M_TRIM_THRESHOLD, 256 << 20),
}
#: glibc's own variables for the same: an operator who sets one keeps glibc's reading of it.
MALLOC_VARIABLES = ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_", "GLIBC_TUNABLES")

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


def tune_malloc(environ: dict[str, str] | os._Environ = os.environ) -> dict[str, Any]:
    """Apply :data:`MALLOC_SETTINGS` with glibc's ``mallopt`` (process-wide, at once), unless the
    operator tuned malloc through its variables or the C library is not glibc; returns what
    was set, for ``GET /model``."""
    if any(environ.get(name) for name in MALLOC_VARIABLES):
        report: dict[str, Any] = {"set_by_service": False, "reason": "set by the operator's variables"}
    else:
        mallopt = _glibc_mallopt()
        if mallopt is None:
            report = {"set_by_service": False, "reason": "not glibc"}
        else:
            applied = {
                name: value for name, (param, value) in MALLOC_SETTINGS.items() if mallopt(param, value) == 1
            }
            report = {"set_by_service": bool(applied), **applied}
    _prepared["malloc"] = report
    return report


def _glibc_mallopt() -> Any | None:
    name = ctypes.util.find_library("c")
    if sys.platform != "linux" or not name:
        return None
    try:
        libc = ctypes.CDLL(name)
        if not hasattr(libc, "gnu_get_libc_version"):  # musl and others have no mallopt thresholds
            return None
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return None
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return mallopt


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
        "malloc": _prepared.get("malloc", {"set_by_service": False, "reason": "not applied in this process"}),
        "torch": torch.__version__,
    }
