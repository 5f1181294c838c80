"""The robot-side install is light: every client module, the dataset layout and ``vgn-client``
work with torch, open3d, pybullet, the service and the simulator made unimportable.

The blocker goes in as ``sitecustomize`` on a fresh ``PYTHONPATH`` entry, so it is active from
interpreter start in every child process, the installed ``vgn-client`` script included.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from vgn_contract.schemas import Intrinsics
from vgn_data.dataset import DatasetSetup, RawDataset, SceneViews

REPO = Path(__file__).resolve().parents[2]
HEAVY = ["torch", "open3d", "pybullet", "service", "sim_worker", "fastapi", "uvicorn"]
GRPC = ["grpc", "grpc_health", "grpc_reflection", "google.protobuf"]

SITECUSTOMIZE = textwrap.dedent("""
    import os
    import sys

    BLOCKED = os.environ["VGN_TEST_BLOCKED"].split(",")
    ATTEMPTS = []


    class Blocker:
        # Imports of the blocked packages fail as if they were not installed, and are recorded.
        def find_spec(self, name, path=None, target=None):
            if any(name == b or name.startswith(b + ".") for b in BLOCKED):
                ATTEMPTS.append(name)
                raise ModuleNotFoundError(f"No module named {name!r} (blocked)", name=name)
            return None


    sys.meta_path.insert(0, Blocker())
""")

# Imports every module of the client package and the dataset package; prints what failed and
# which blocked packages anything tried to import.
IMPORT_ALL = textwrap.dedent("""
    import importlib, json, pkgutil, sys
    import sitecustomize, client, vgn_data

    failed = {}
    names = []
    for package in (client, vgn_data):
        names.append(package.__name__)
        names += [m.name for m in pkgutil.walk_packages(package.__path__, package.__name__ + ".")]
    for name in names:
        try:
            importlib.import_module(name)
        except ImportError as error:
            failed[name] = str(error)
    print(json.dumps({"modules": names, "failed": failed, "attempts": sitecustomize.ATTEMPTS}))
""")


def _blocked_env(tmp_path: Path, blocked: list[str]) -> dict[str, str]:
    (tmp_path / "sitecustomize.py").write_text(SITECUSTOMIZE)
    env = dict(os.environ, VGN_TEST_BLOCKED=",".join(blocked))
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(tmp_path), str(REPO), env.get("PYTHONPATH")) if p)
    return env


def _grpc_installed() -> bool:
    try:
        import grpc  # noqa: F401
    except ImportError:
        return False
    return True


@pytest.mark.parametrize(
    "grpc_blocked",
    [
        True,
        pytest.param(False, marks=pytest.mark.skipif(not _grpc_installed(), reason="grpcio not installed")),
    ],
    ids=["without-grpcio", "with-grpcio"],
)
def test_every_client_module_imports_without_heavy_packages(tmp_path, grpc_blocked):
    env = _blocked_env(tmp_path, HEAVY + (GRPC if grpc_blocked else []))
    result = subprocess.run(
        [sys.executable, "-c", IMPORT_ALL], env=env, cwd=tmp_path, capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert {"client.cli", "client.http", "client.connect", "client.grpc_client"} <= set(report["modules"])
    assert {"vgn_data.dataset", "vgn_data.files"} <= set(report["modules"])
    if grpc_blocked:
        # Only the gRPC transport may be missing, and only for want of grpcio/protobuf.
        for name, error in report["failed"].items():
            assert name == "client.grpc_client" or name.startswith("vgn_contract.grpc_api."), (name, error)
            assert "grpc" in error or "google" in error, (name, error)
        assert "client.grpc_client" in report["failed"]
        assert all(attempt.startswith(("grpc", "google")) for attempt in report["attempts"]), report
    else:
        assert report["failed"] == {}
        assert report["attempts"] == []


def _vgn_client(env: dict[str, str], cwd: Path, *args: str) -> subprocess.CompletedProcess:
    script = shutil.which("vgn-client")
    if script is None:
        pytest.skip("vgn-client is not installed (pip install -e .)")
    return subprocess.run([script, *args], env=env, cwd=cwd, capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("args", [["--help"], ["clear-scene", "--help"], ["generate-data", "--help"]])
def test_vgn_client_help_without_heavy_packages(tmp_path, args):
    result = _vgn_client(_blocked_env(tmp_path, HEAVY + GRPC), tmp_path, *args)
    assert result.returncode == 0, result.stderr
    assert "usage: vgn-client" in result.stdout


@pytest.mark.parametrize(
    "args", [["clear-scene", "--sim"], ["generate-data", "--sim", "--out", "data-out", "--scenes", "1"]]
)
def test_sim_commands_say_they_need_the_sim_extra(tmp_path, args):
    result = _vgn_client(_blocked_env(tmp_path, HEAVY + GRPC), tmp_path, *args)
    assert result.returncode == 2
    assert f"{args[0]} --sim needs the sim extra" in result.stderr
    assert "vgn-service[sim]" in result.stderr
    assert "Traceback" not in result.stderr
    assert not (tmp_path / "data-out").exists()


def test_clean_data_runs_on_the_light_install(tmp_path):
    """clean-data only reads and writes the dataset layout, so it needs nothing heavy."""
    intrinsics = Intrinsics(width=8, height=6, fx=10.0, fy=10.0, cx=4.0, cy=3.0)
    source = RawDataset(tmp_path / "raw", DatasetSetup(intrinsics=intrinsics))
    views = SceneViews(np.full((1, 6, 8), 0.5, np.float32), np.eye(4)[None])
    inside, outside = [0.15, 0.15, 0.10], [0.0, 0.0, 0.0]
    rows = [[0, 0, 0, 1, *inside, 0.04, 1], [0, 0, 0, 1, *inside, 0.04, 0], [0, 0, 0, 1, *outside, 0.04, 1]]
    source.add_scene("s0-0", views, np.array(rows, dtype=np.float64))

    result = _vgn_client(_blocked_env(tmp_path, HEAVY + GRPC), tmp_path, "clean-data", "raw", "clean")
    assert result.returncode == 0, result.stderr
    assert "2 grasps" in result.stdout
    ids, grasps = RawDataset(tmp_path / "clean").grasps()
    assert ids == ["s0-0", "s0-0"] and sorted(grasps[:, 8]) == [0.0, 1.0]
