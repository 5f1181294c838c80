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
from collections.abc import Callable

_PR_SET_PDEATHSIG = 1
# Loaded here, not in the child: a forked child must not import or load libraries.
_libc = ctypes.CDLL(None, use_errno=True) if sys.platform.startswith("linux") else None


def end_with_parent(sig: int = signal.SIGTERM) -> None:
    """Ask the kernel to send ``sig`` to this process when its parent dies. Call it in the
    child: first thing in a worker, or through ``preexec_for_child``."""
    if _libc is None:
        return
    parent = os.getppid()
    if _libc.prctl(_PR_SET_PDEATHSIG, sig, 0, 0, 0) != 0:
        return  # not fatal: the child still works, it merely may outlive a killed parent
    if os.getppid() != parent:  # the parent died before the request took effect
        os.kill(os.getpid(), sig)


def preexec_for_child() -> Callable[[], None] | None:
    """``Popen(preexec_fn=...)`` making the child end with this process, or None where that is
    not possible. The kernel watches the thread that forks, so only the main thread (which
    lives as long as the process) asks for it."""
    if _libc is None or threading.current_thread() is not threading.main_thread():
        return None
    return end_with_parent
