"""The robot-side install is light: every client module, the wire contract, the dataset layout and
``vgn-client`` work with torch, open3d, pybullet, the service and the simulator made unimportable,
and the package that starts services (``service.launch``) with the rest of the server so too.

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
#: What needs grpcio and protobuf: the stubs, the conversions, and their old paths in ``client``.
GRPC_MODULES = ("vgn_contract.grpc_api.", "client.grpc_api.")

SITECUSTOMIZE = textwrap.dedent("""
    import os
    import sys

    BLOCKED = os.environ["VGN_TEST_BLOCKED"].split(",")
    # Subpackages of a blocked package that stay importable (their parents too).
    ALLOWED = [a for a in os.environ.get("VGN_TEST_ALLOWED", "").split(",") if a]
    ATTEMPTS = []


    def allowed(name):
        return any(name == a or name.startswith(a + ".") or a.startswith(name + ".") for a in ALLOWED)


    class Blocker:
        # Imports of the blocked packages fail as if they were not installed, and are recorded.
        def find_spec(self, name, path=None, target=None):
            if any(name == b or name.startswith(b + ".") for b in BLOCKED) and not allowed(name):
                ATTEMPTS.append(name)
                raise ModuleNotFoundError(f"No module named {name!r} (blocked)", name=name)
            return None


    sys.meta_path.insert(0, Blocker())
""")

# Imports every module of the packages named on the command line; prints what failed, which
# blocked packages anything tried to import, and which of the server's modules were loaded.
IMPORT_ALL = textwrap.dedent("""
    import importlib, json, pkgutil, sys
    import sitecustomize

    failed = {}
    names = []
    for package in map(importlib.import_module, sys.argv[1:]):
        names.append(package.__name__)
        names += [m.name for m in pkgutil.walk_packages(package.__path__, package.__name__ + ".")]
    for name in names:
        try:
            importlib.import_module(name)
        except ImportError as error:
            failed[name] = str(error)
    server = sorted(name for name in sys.modules if name == "service" or name.startswith("service."))
    print(json.dumps({"modules": names, "failed": failed, "attempts": sitecustomize.ATTEMPTS, "server": server}))
""")
LIGHT_PACKAGES = ["client", "vgn_contract", "vgn_data"]


def _blocked_env(tmp_path: Path, blocked: list[str], allowed: tuple[str, ...] = ()) -> dict[str, str]:
    (tmp_path / "sitecustomize.py").write_text(SITECUSTOMIZE)
    env = dict(os.environ, VGN_TEST_BLOCKED=",".join(blocked), VGN_TEST_ALLOWED=",".join(allowed))
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
    report = _import_all(env, tmp_path, LIGHT_PACKAGES)
    assert {"client.cli", "client.http", "client.connect", "client.grpc_client"} <= set(report["modules"])
    assert {"vgn_contract.schemas", "vgn_contract.gripper_description"} <= set(report["modules"])
    assert {"vgn_data.dataset", "vgn_data.files"} <= set(report["modules"])
    # The old paths of the server's process management forward lazily: importing them loads no server code.
    assert {"client.embedded", "client.fleet", "client.lifetime"} <= set(report["modules"])
    assert report["server"] == []
    if grpc_blocked:
        # Only the gRPC transport may be missing, and only for want of grpcio/protobuf.
        for name, error in report["failed"].items():
            assert name == "client.grpc_client" or name.startswith(GRPC_MODULES), (name, error)
            assert "grpc" in error or "google" in error, (name, error)
        assert "client.grpc_client" in report["failed"]
        assert all(attempt.startswith(("grpc", "google")) for attempt in report["attempts"]), report
    else:
        assert report["failed"] == {}
        assert report["attempts"] == []


def test_the_launch_package_imports_without_the_rest_of_the_server(tmp_path):
    """The simulator, the ROS bridge and ``vgn-client serve`` start services from ``service.launch``
    on installs without the service extra: it loads none of the server's other modules."""
    env = _blocked_env(tmp_path, HEAVY + GRPC, allowed=("service.launch",))
    report = _import_all(env, tmp_path, ["service.launch"])
    assert {"service.launch.embedded", "service.launch.fleet", "service.launch.serve"} <= set(
        report["modules"]
    )
    assert report["failed"] == {} and report["attempts"] == []
    assert all(
        name in ("service", "service.launch") or name.startswith("service.launch.")
        for name in report["server"]
    )


def test_serve_says_it_needs_the_service_extra(tmp_path):
    env = _blocked_env(tmp_path, HEAVY + GRPC, allowed=("service.launch",))
    result = _vgn_client(env, tmp_path, "serve", "--port", "0")
    assert result.returncode == 2, result.stderr
    assert "serving needs the service extra" in result.stderr and "Traceback" not in result.stderr


def _import_all(env: dict[str, str], cwd: Path, packages: list[str]) -> dict:
    result = subprocess.run(
        [sys.executable, "-c", IMPORT_ALL, *packages],
        env=env,
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)


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
