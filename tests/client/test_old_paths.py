"""The modules that moved out of ``client`` keep their old import paths for one release: the wire
contract (now ``vgn_contract``) re-exported, the server's process management (now
``service.launch``) forwarded on first use. Each old name is the very object of the new module."""

from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
CONTRACT = ["schemas", "geometry", "gripper_description", "snapshot", "tracking", "grpc_api.convert"]
STUBS = ["grpc_api.grasp_planning_pb2", "grpc_api.grasp_planning_pb2_grpc"]
LAUNCH = ["embedded", "fleet", "haproxy", "lifetime"]
MOVES = [(f"client.{m}", f"vgn_contract.{m}") for m in CONTRACT + STUBS] + [
    (f"client.{m}", f"service.launch.{m}") for m in LAUNCH
]


@pytest.mark.parametrize(("old", "new"), MOVES, ids=[old for old, _ in MOVES])
def test_an_old_path_gives_the_new_objects(old: str, new: str) -> None:
    if "grpc_api" in old:
        pytest.importorskip("grpc", reason="the gRPC stubs need the grpc extra")
    before, after = importlib.import_module(old), importlib.import_module(new)
    assert before.__all__, old
    for name in before.__all__:
        assert getattr(before, name) is getattr(after, name), f"{old}.{name}"
    namespace: dict[str, object] = {}
    exec(f"from {old} import *", namespace)
    assert set(before.__all__) <= set(namespace)


@pytest.mark.parametrize("old", [f"client.{m}" for m in LAUNCH])
def test_a_forwarding_module_knows_only_its_names(old: str) -> None:
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        importlib.import_module(old).nothing  # noqa: B018


def test_the_old_haproxy_command_still_runs() -> None:
    command = [sys.executable, "-m", "client.haproxy", "--replicas", "1", "--server", "r{i}"]
    result = subprocess.run(command, cwd=REPO, capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert "server r0 r0:8000 check" in result.stdout
