"""``vgn-client clear-scene --sim`` and ``generate-data`` print their own output only: PyBullet's
C code (``argv[0]=`` on connect, the EGL plugin's ``ven = ...`` whenever it makes its buffers)
stays off stdout.

The world runs in a child process with stdout a pipe, as when a command's output is piped or
captured: C's stdout is fully buffered then, so what was printed while stdout was silenced
would surface at the next flush or at exit.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]

# Renders the sizes the EGL plugin makes new buffers for (the first, a larger one, a larger one
# after a reset), closes one world and drops another unclosed; prints one JSON line at the end.
WORLD_LIFE = textwrap.dedent("""
    import json, sys
    import numpy as np
    from vgn_contract.schemas import Intrinsics
    from sim_worker.camera import Camera, six_views
    from sim_worker.world import World

    world = World(renderer=sys.argv[1])
    small = Intrinsics(width=64, height=48, fx=60.0, fy=60.0, cx=32.0, cy=24.0)
    big = Intrinsics(width=320, height=240, fx=300.0, fy=300.0, cx=160.0, cy=120.0)
    seen = []
    for intrinsics in (small, big, small):
        seen.append(float(Camera(world, intrinsics).render_depth(six_views()[0]).max()))
    world.reset()
    huge = Intrinsics(width=480, height=360, fx=450.0, fy=450.0, cx=240.0, cy=180.0)
    seen.append(float(Camera(world, huge).render_depth(six_views()[1]).max()))
    egl = world.egl
    world.close()
    dropped = World(renderer=sys.argv[1])
    Camera(dropped, small).render_depth(six_views()[2])
    del dropped
    print(json.dumps({"egl": egl, "seen": seen}))
""")


def run_world(renderer: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", WORLD_LIFE, renderer],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
    )


@pytest.mark.parametrize("renderer", ["auto", "egl", "tiny"])
def test_a_world_prints_nothing_on_stdout(renderer: str) -> None:
    result = run_world(renderer)
    if renderer == "egl" and "EGL renderer cannot be loaded" in result.stderr:
        pytest.skip("no EGL on this machine; 'auto' still runs")
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert len(lines) == 1, f"stdout holds more than the script's own line: {lines}"
    report = json.loads(lines[0])
    assert all(depth > 0 for depth in report["seen"]), "the renders saw the table"
    if renderer == "egl":
        assert report["egl"] is True
    if renderer == "tiny":
        assert report["egl"] is False


def test_stdout_written_by_the_program_itself_still_appears() -> None:
    """Silencing PyBullet must not swallow what the program printed just before or after."""
    script = textwrap.dedent("""
        import sys
        from sim_worker.world import World
        print("before", flush=False)
        world = World(renderer="auto")
        print("between", flush=False)
        world.close()
        print("after")
    """)
    result = subprocess.run(
        [sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == ["before", "between", "after"]
