"""The client must import and work without torch, open3d, pybullet or grpcio (robot-side installs)."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest


def test_client_runs_without_heavy_dependencies(server):
    script = textwrap.dedent(f"""
        import sys

        class Blocked:
            # Any import of these packages raises ImportError, as if they were not installed.
            def find_spec(self, name, path=None, target=None):
                if name.split(".")[0] in ("torch", "open3d", "pybullet", "service", "fastapi", "grpc", "grpc_health"):
                    raise ImportError(name + " is not installed")

        sys.meta_path.insert(0, Blocked())
        import numpy as np
        import client, client.cli
        from client import VGNClient, Intrinsics
        with VGNClient({server.url!r}) as vgn:
            session = vgn.create_session(intrinsics=Intrinsics(width=64, height=48, fx=50, fy=50, cx=32, cy=24))
            pose = np.eye(4); pose[:3, 3] = [0.15, 0.15, 0.5]; pose[:3, :3] = np.diag([1.0, -1.0, -1.0])
            print(vgn.add_frame(session.session_id, np.full((48, 64), 0.4, np.float32), pose).frame_count)
    """)
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "1"
    assert "torch" not in result.stderr


@pytest.mark.parametrize("command", [["status"], ["sessions"]])
def test_cli_against_a_live_service(server, command):
    result = subprocess.run(
        [sys.executable, "-m", "client.cli", *command, "--url", server.url],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    expected = f"service   {server.url}: up" if command == ["status"] else "sessions"
    assert expected in result.stdout


def test_cli_grasps_and_errors(server, vgn):
    session_id = vgn.create_session().session_id
    ok = subprocess.run(
        [sys.executable, "-m", "client.cli", "grasps", session_id, "--url", server.url],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert ok.returncode == 0, ok.stderr
    assert "0 grasps" in ok.stdout  # nothing fused yet
    missing = subprocess.run(
        [sys.executable, "-m", "client.cli", "grasps", "nope", "--url", server.url],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert missing.returncode == 1 and "404" in missing.stderr and "nope" in missing.stderr
    unreachable = subprocess.run(
        [sys.executable, "-m", "client.cli", "status", "--url", "http://127.0.0.1:9"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert unreachable.returncode == 1 and "cannot reach" in unreachable.stderr
