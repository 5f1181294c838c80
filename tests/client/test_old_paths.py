"""The modules that moved out of ``client`` keep their old import paths for one release: the wire
contract (now ``vgn_contract``) re-exported, the server's process management (now
``service.launch``) forwarded on first use. Each old name is the very object of the new module;
importing an old path warns, naming the new one, and nothing of ours imports one."""

from __future__ import annotations

import importlib
import subprocess
import sys
import warnings
from pathlib import Path
from types import ModuleType

import pytest

from tests.test_architecture import references, top_level_packages

REPO = Path(__file__).resolve().parents[2]
CONTRACT = ["schemas", "geometry", "gripper_description", "snapshot", "tracking", "grpc_api.convert"]
STUBS = ["grpc_api.grasp_planning_pb2", "grpc_api.grasp_planning_pb2_grpc"]
LAUNCH = ["embedded", "fleet", "haproxy", "lifetime"]
MOVES = [(f"client.{m}", f"vgn_contract.{m}") for m in CONTRACT + STUBS] + [
    (f"client.{m}", f"service.launch.{m}") for m in LAUNCH
]


OLD_PATHS = {old for old, _ in MOVES} | {"client.grpc_api"}


def import_afresh(old: str, new: str, monkeypatch: pytest.MonkeyPatch) -> ModuleType:
    """``old`` imported as a user's code would the first time: it warns, from the importing line,
    that it is ``new`` now. The module imported before (if any) is back after the test."""
    if "grpc_api" in old:
        pytest.importorskip("grpc", reason="the gRPC stubs need the grpc extra")
    if old.startswith("client.grpc_api."):  # the old package, which warns of itself, is imported already
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            importlib.import_module("client.grpc_api")
    monkeypatch.delitem(sys.modules, old, raising=False)
    with pytest.warns(DeprecationWarning, match=f"^{old} moved to {new}: import it from there") as caught:
        module = importlib.import_module(old)
    assert [w.filename for w in caught if issubclass(w.category, DeprecationWarning)] == [__file__]
    return module


@pytest.mark.parametrize(("old", "new"), MOVES, ids=[old for old, _ in MOVES])
def test_an_old_path_gives_the_new_objects(old: str, new: str, monkeypatch: pytest.MonkeyPatch) -> None:
    before, after = import_afresh(old, new, monkeypatch), importlib.import_module(new)
    assert before.__all__, old
    for name in before.__all__:
        assert getattr(before, name) is getattr(after, name), f"{old}.{name}"
    namespace: dict[str, object] = {}
    exec(f"from {old} import *", namespace)
    assert set(before.__all__) <= set(namespace)


def test_the_old_grpc_package_warns_too(monkeypatch: pytest.MonkeyPatch) -> None:
    import_afresh("client.grpc_api", "vgn_contract.grpc_api", monkeypatch)


@pytest.mark.parametrize("name", LAUNCH)
def test_a_forwarding_module_knows_only_its_names(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        import_afresh(f"client.{name}", f"service.launch.{name}", monkeypatch).nothing  # noqa: B018


def test_nothing_of_ours_imports_an_old_path() -> None:
    """The old paths are for users' code: the repository imports the new ones."""
    folders = sorted(top_level_packages(REPO) | {"tests", "examples", "docs"})
    ours = [path for folder in folders for path in sorted((REPO / folder).rglob("*.py"))]
    old_files = {REPO / f"{old.replace('.', '/')}.py" for old in OLD_PATHS} | {
        REPO / "client/grpc_api/__init__.py"
    }
    found = [
        f"{ref.path}:{ref.line}: {ref.module}"
        for path in ours
        if path not in old_files and path != Path(__file__)
        for ref in references(REPO, path)
        if ref.how != "string" and any(ref.module == o or ref.module.startswith(o + ".") for o in OLD_PATHS)
    ]
    assert not found, found


def test_the_old_haproxy_command_still_runs() -> None:
    command = [sys.executable, "-m", "client.haproxy", "--replicas", "1", "--server", "r{i}"]
    result = subprocess.run(command, cwd=REPO, capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert "server r0 r0:8000 check" in result.stdout
    assert "client.haproxy moved to service.launch.haproxy" in result.stderr, "run by name, it warns too"
