"""Child processes that end with their parent, however the parent ends.

A command killed with SIGKILL (an operator's ``kill -9``, the OOM killer, a CI timeout) runs
no cleanup, so its simulator workers and embedded service would live on: orphans that keep
writing into the folder a rerun resumes, or hold a port and memory for good. On Linux the
kernel can signal a child when its parent dies; elsewhere this is a no-op.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys
import threading

_PR_SET_PDEATHSIG = 1
# Loaded here, not in the child: a forked child must not import or load libraries.
_libc = ctypes.CDLL(None, use_errno=True) if sys.platform.startswith("linux") else None


#: Names, in a child's environment, the process the child should end with (its pid).
PARENT_VARIABLE = "VGN_END_WITH_PARENT"


def end_with_parent(sig: int = signal.SIGTERM, parent: int | None = None) -> None:
    """Ask the kernel to send ``sig`` to this process when its parent dies. Call it in the
    child, first thing. ``parent``: the pid the parent had when it started this process; if
    the parent is already another one (the first died and this process was re-parented), the
    signal comes at once."""
    if _libc is None:
        return
    expected = os.getppid() if parent is None else parent
    if _libc.prctl(_PR_SET_PDEATHSIG, sig, 0, 0, 0) != 0:
        return  # not fatal: the child still works, it merely may outlive a killed parent
    if os.getppid() != expected:  # the parent died before the request took effect
        os.kill(os.getpid(), sig)


def ending_with_this_process(env: dict[str, str]) -> dict[str, str]:
    """``env`` for a child that should end with this process, however this process ends; the
    child calls :func:`end_with_parent_if_asked` (the service's entry, ``service.app``,
    does).

    The child asks for it after ``exec``, not through ``Popen(preexec_fn=...)``: a
    ``preexec_fn`` makes Python ``fork`` instead of ``vfork``, and a fork runs every library's
    fork handlers in the child. gRPC's (grpcio 1.80 and later) restart its poller thread
    there, which can abort the child before it runs anything when this process uses gRPC.
    The kernel watches the thread that forks, so only the main thread (which lives as long
    as the process) asks for it.
    """
    if _libc is None or threading.current_thread() is not threading.main_thread():
        return {name: value for name, value in env.items() if name != PARENT_VARIABLE}  # none inherited
    return {**env, PARENT_VARIABLE: str(os.getpid())}


def end_with_parent_if_asked(environ: dict[str, str] | os._Environ = os.environ) -> None:
    """In a child started with :func:`ending_with_this_process`: end with that parent. The
    variable is removed, so that this process's own children do not inherit a parent that
    is not theirs."""
    value = environ.pop(PARENT_VARIABLE, "")
    if value.isdigit():
        end_with_parent(parent=int(value))
