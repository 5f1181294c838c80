"""The lock files in requirements/ match pyproject.toml and the environment the tests run in.

A lock made before a change to pyproject.toml's dependency lists would install something other
than what pyproject.toml asks for; and a run whose packages differ from the lock did not test
what a fresh install gets. Both fail here, so CI fails on a stale lock.
"""

from __future__ import annotations

import importlib.util
import platform
import sys
from importlib import metadata
from pathlib import Path
from types import ModuleType

import pytest
from packaging.version import Version

ROOT = Path(__file__).resolve().parent.parent
REQUIREMENTS = ROOT / "requirements"


def _load_lock_script() -> ModuleType:
    spec = importlib.util.spec_from_file_location("vgn_requirements_lock", REQUIREMENTS / "lock.py")
    assert spec and spec.loader
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


lock = _load_lock_script()
LOCK_FILES = list(lock.LOCKS)


@pytest.mark.parametrize("name", LOCK_FILES)
def test_lock_was_made_from_current_pyproject(name: str) -> None:
    recorded = lock.read_header_hash(REQUIREMENTS / name)
    assert recorded is not None, f"requirements/{name} has no `# {lock.HASH_KEY}:` header line"
    assert recorded == lock.pyproject_deps_hash(), (
        f"requirements/{name} is stale: pyproject.toml's dependency lists changed after it was made; "
        f"run `{lock.REGENERATE}` and commit the locks"
    )


def test_locks_agree_on_shared_packages() -> None:
    full = lock.read_pins(REQUIREMENTS / lock.FULL)
    for name in LOCK_FILES:
        pins = lock.read_pins(REQUIREMENTS / name)
        differ = {p: (v, full.get(p)) for p, v in pins.items() if full.get(p) != v}
        assert not differ, (
            f"requirements/{name} pins other versions than {lock.FULL} (or more packages): {differ}"
        )


def test_locks_pin_the_cpu_torch_and_a_pytest_schemathesis_runs_on() -> None:
    pins = lock.read_pins(REQUIREMENTS / lock.FULL)
    assert pins["torch"] == lock.torch_cpu_pin().removeprefix("torch==").removesuffix("+cpu")
    assert not [p for p in pins if p.startswith(("nvidia-", "triton"))], "the CUDA build of torch was locked"
    assert Version(pins["pytest"]) < Version("9.1"), "schemathesis 4.32.5 breaks on pytest >= 9.1"


def _public(version: str) -> Version:
    """The version without its local label: torch's CPU wheel is 2.13.0+cpu, locked as 2.13.0."""
    return Version(Version(version).public)


@pytest.mark.skipif(
    not (sys.platform == "linux" and platform.machine() == "x86_64" and sys.version_info[:2] == (3, 11)),
    reason="the locks are resolved for Linux x86-64 and CPython 3.11; elsewhere versions may differ",
)
@pytest.mark.parametrize("name", LOCK_FILES)
def test_installed_packages_are_the_locked_versions(name: str) -> None:
    wrong = {}
    for package, locked in lock.read_pins(REQUIREMENTS / name).items():
        try:
            installed = metadata.version(package)
        except metadata.PackageNotFoundError:
            continue  # not part of this install (main.txt's packages are all in full.txt)
        if _public(installed) != Version(locked):
            wrong[package] = f"installed {installed}, locked {locked}"
    assert not wrong, (
        f"this environment does not hold what requirements/{name} pins (install with "
        f"`bash install.sh --dev`): {wrong}"
    )
