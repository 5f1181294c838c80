"""The lock files in requirements/ match pyproject.toml and the environment the tests run in.

A lock made before a change to pyproject.toml's dependency lists would install something other
than what pyproject.toml asks for; and a run whose packages differ from the lock did not test
what a fresh install gets. Both fail here, so CI fails on a stale lock.
"""

from __future__ import annotations

import importlib.util
import platform
import re
import sys
from importlib import metadata
from pathlib import Path
from types import ModuleType

import pytest
from packaging.requirements import Requirement
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


#: The platform the locks are resolved for (requirements/lock.py), as environment markers see it.
LOCK_PLATFORM = {
    "platform_system": "Linux",
    "platform_machine": "x86_64",
    "sys_platform": "linux",
    "python_version": lock.PYTHON_VERSION,
}


def _requirements(*extras: str) -> list[Requirement]:
    """The base dependencies and those of ``extras`` (extras they name of this project included),
    without those whose markers rule out the lock platform."""
    project = lock.tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    found, todo, seen = [Requirement(r) for r in project["dependencies"]], list(extras), set()
    while todo:
        extra = todo.pop()
        if extra in seen:
            continue
        seen.add(extra)
        for requirement in map(Requirement, project["optional-dependencies"][extra]):
            if requirement.name == project["name"]:
                todo += requirement.extras
            else:
                found.append(requirement)
    return [r for r in found if r.marker is None or r.marker.evaluate(LOCK_PLATFORM)]


def _normalized(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def test_every_extra_is_pinned_in_the_full_lock():
    """An extra missing from LOCKS would install whatever is newest on the day, with -c or not."""
    project = lock.tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    pins = lock.read_pins(REQUIREMENTS / lock.FULL)
    unpinned = {}
    for extra in project["optional-dependencies"]:
        names = sorted({_normalized(r.name) for r in _requirements(extra)} - pins.keys())
        if names:
            unpinned[extra] = names
    assert not unpinned, (
        f"{lock.FULL} does not pin {unpinned}: add the extras to LOCKS and run `{lock.REGENERATE}`"
    )


def test_the_base_and_service_installs_hold_no_ros_package():
    """The ROS 2 wheels stay in their own extra: `pip install .` and the service's install never
    bring them (nor what only they need)."""
    named = [_normalized(r.name) for r in _requirements("service", "sim")]
    assert not [name for name in named if name.startswith("ros-")]
    # What the full lock has only for the ROS wheels: the wheels and what only they pull in.
    via = dict(
        re.findall(r"^([A-Za-z0-9._-]+)==\S+\s+# via (.*)$", (REQUIREMENTS / lock.FULL).read_text(), re.M)
    )
    ros = {
        _normalized(name)
        for name, by in via.items()
        if name.startswith("ros-") or all(b.strip().startswith("ros-") for b in by.split(","))
    }
    assert {"ros-rclpy", "lark-parser"} <= ros, "the check knows the ROS wheels by their names"
    assert not ros & set(lock.read_pins(REQUIREMENTS / "main.txt"))


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
