"""Importing ``service`` changes nothing in the process; starting the server does.

A library import that rewrites the environment or arms a parent-death signal surprises every
program that imports it (a notebook, a benchmark, a training run). The server's own process
preparation lives in its entry, ``service.app`` (``uvicorn service.app:app``). Each check
runs in a fresh interpreter, since an import happens once per process.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

# Prints what the imports changed: variables added, removed or changed, and the signal this
# process gets when its parent dies (prctl PR_GET_PDEATHSIG; 0: none, None: not Linux).
PROBE = """
import ctypes, json, os, sys
before = dict(os.environ)
for module in sys.argv[1:]:
    __import__(module)
after = dict(os.environ)
changed = sorted(name for name in before.keys() | after.keys() if before.get(name) != after.get(name))
pdeathsig = None
if sys.platform.startswith("linux"):
    value = ctypes.c_int(-1)
    assert ctypes.CDLL(None, use_errno=True).prctl(2, ctypes.byref(value), 0, 0, 0) == 0
    pdeathsig = value.value
print(json.dumps({"changed": changed, "pdeathsig": pdeathsig, "omp": after.get("OMP_WAIT_POLICY")}))
"""


def probe(*modules: str) -> dict:
    """Import ``modules`` in a fresh interpreter that was asked to end with this process, with
    none of the variables the server would set."""
    env = {name: value for name, value in os.environ.items() if name not in ("OMP_WAIT_POLICY",)}
    env["VGN_END_WITH_PARENT"] = str(os.getpid())  # as service.launch.embedded asks its child
    done = subprocess.run(
        [sys.executable, "-c", PROBE, *modules],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_importing_service_and_its_application_leaves_the_process_alone():
    result = probe("service", "service.http_app")
    assert result["changed"] == []
    assert result["pdeathsig"] in (0, None)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="parent-death signals are Linux's")
def test_the_server_entry_prepares_its_process():
    result = probe("service.app")
    assert result["omp"] == "PASSIVE"
    assert set(result["changed"]) == {"OMP_WAIT_POLICY", "VGN_END_WITH_PARENT"}  # the latter consumed
    assert result["pdeathsig"] == signal.SIGTERM
