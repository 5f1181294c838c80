"""A child started to end with this process does, however this process ends; it asks for that
itself after exec (importing the server's entry, ``service.app``), so Popen needs no ``preexec_fn`` (see service.launch.lifetime)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import threading

import pytest

from service.launch.lifetime import PARENT_VARIABLE, ending_with_this_process
from tests.helpers.processes import alive, wait_until_gone

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the kernel feature is Linux's")

#: What the service's process does on start, then waits: prints whether the variable reached it.
CHILD = "import os, sys, time, service.app; print(os.environ.get(sys.argv[1], 'unset'), flush=True); time.sleep(60)"


def test_the_child_ends_when_its_parent_is_killed():
    parent_script = textwrap.dedent(f"""
        import os, subprocess, sys, time
        from service.launch.lifetime import ending_with_this_process
        child = subprocess.Popen([sys.executable, "-c", {CHILD!r}, {PARENT_VARIABLE!r}],
                                 env=ending_with_this_process(dict(os.environ)))
        print(child.pid, flush=True)
        time.sleep(60)
    """)
    parent = subprocess.Popen([sys.executable, "-c", parent_script], stdout=subprocess.PIPE, text=True)
    try:
        child = int(parent.stdout.readline())
        # Importing the server's entry took the variable out: the service's own children do not inherit it.
        assert parent.stdout.readline().strip() == "unset"
        assert alive(child)
        parent.kill()  # SIGKILL: the parent runs no cleanup
        parent.wait()
        assert wait_until_gone({child}, timeout=10.0) == set(), "the child outlived its killed parent"
    finally:
        parent.kill()
        parent.stdout.close()


def test_a_child_whose_parent_is_already_gone_ends_at_once():
    env = {
        **os.environ,
        PARENT_VARIABLE: "1",
    }  # not our pid: as if the parent had died before the child started
    child = subprocess.run(
        [sys.executable, "-c", CHILD, PARENT_VARIABLE], env=env, timeout=30, capture_output=True
    )
    assert child.returncode == -signal.SIGTERM


def test_only_the_main_thread_asks():
    """The kernel watches the thread that forks: one that ends early would take the child with it."""
    env = {"A": "1"}
    assert ending_with_this_process(env) == {"A": "1", PARENT_VARIABLE: str(os.getpid())}
    assert env == {"A": "1"}, "the caller's mapping is left as it was"
    from_thread = []
    inherited = {**env, PARENT_VARIABLE: "12345"}  # a stale one must not reach the child either
    thread = threading.Thread(target=lambda: from_thread.append(ending_with_this_process(inherited)))
    thread.start()
    thread.join()
    assert from_thread == [{"A": "1"}]
