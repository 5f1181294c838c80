#!/usr/bin/env python3
"""Regenerate the lock files in this folder from pyproject.toml with `uv pip compile`.

Why: pyproject.toml gives ranges, so a plain `pip install -e ".[...]"` takes whatever is newest on
the day and a fresh machine can test other versions than CI did. The locks pin every package
(for one platform, below); install.sh installs with them as pip constraints, and tests/test_lock.py
fails when pyproject.toml's dependency lists changed after the locks were made.

Usage, from anywhere:  python3 requirements/lock.py [--upgrade] [--find-links DIR]
It keeps the versions already pinned where they still fit (uv reads the old file as preferences);
--upgrade takes the newest allowed versions instead. Needs `uv` (pip install uv) and a folder
with the CPU wheel of torch (see README.md here).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10: pytest brings tomli
    import tomli as tomllib

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

# The platform every lock is resolved for. manylinux_2_35: open3d-cpu 0.20.0 ships wheels for
# glibc >= 2.35 only (Debian 12 has 2.36, Ubuntu 22.04 2.35).
PYTHON_VERSION = "3.11"
PYTHON_PLATFORM = "x86_64-manylinux_2_35"
PLATFORM_TEXT = "Linux x86-64 (manylinux_2_35: glibc >= 2.35), CPython 3.11"

# Lock file -> the extras it covers. Order matters: the test set is resolved first and constrains
# the others, so the packages they share have the same versions.
LOCKS: dict[str, tuple[str, ...]] = {
    "full.txt": ("all", "dev", "docs", "ray", "runtimes", "ros", "realsense"),
    "main.txt": ("service", "sim"),
}
FULL = "full.txt"
HASH_KEY = "pyproject-deps-sha256"
REGENERATE = "python3 requirements/lock.py"


def pyproject_deps_hash(pyproject: Path = ROOT / "pyproject.toml") -> str:
    """Hash [project] dependencies and optional-dependencies: what the locks were resolved from."""
    project = tomllib.loads(pyproject.read_text())["project"]
    deps = {
        "dependencies": project.get("dependencies", []),
        "optional-dependencies": project.get("optional-dependencies", {}),
    }
    return hashlib.sha256(json.dumps(deps, sort_keys=True).encode()).hexdigest()


def read_header_hash(lock: Path) -> str | None:
    """The pyproject hash a lock file was made from, or None where its header has none."""
    for line in lock.read_text().splitlines():
        if not line.startswith("#"):
            break
        m = re.match(rf"#\s*{HASH_KEY}:\s*([0-9a-f]{{64}})\s*$", line)
        if m:
            return m.group(1)
    return None


def read_pins(lock: Path) -> dict[str, str]:
    """Normalized package name -> pinned version, from a lock's `name==version` lines."""
    return parse_pins(lock.read_text())


def parse_pins(text: str) -> dict[str, str]:
    """Normalized package name -> pinned version, from lock text."""
    return {
        re.sub(r"[-_.]+", "-", m.group(1)).lower(): m.group(2)
        for m in re.finditer(r"^([A-Za-z0-9][A-Za-z0-9._-]*)==([^\s;#]+)", text, flags=re.M)
    }


def _uv() -> list[str]:
    """The uv command: on PATH, or the uv package in this Python."""
    if shutil.which("uv"):
        return ["uv"]
    try:
        import uv  # noqa: F401
    except ModuleNotFoundError:
        sys.exit("uv is missing: pip install uv")
    return [sys.executable, "-m", "uv"]


def _default_find_links() -> str | None:
    """The folder with the torch CPU wheel: /opt/wheels on our machines."""
    return "/opt/wheels" if Path("/opt/wheels").is_dir() else None


def torch_cpu_pin() -> str:
    """`torch==X+cpu` for pyproject's `torch==X`: forces the CPU wheel, which uv would otherwise
    pass over for PyPI's CUDA build of the same public version once an old lock pins `torch==X`."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    for req in [r for reqs in project.get("optional-dependencies", {}).values() for r in reqs]:
        m = re.fullmatch(r"torch\s*==\s*([0-9][0-9.]*)", req.strip())
        if m:
            return f"torch=={m.group(1)}+cpu"
    sys.exit("pyproject.toml pins no `torch==X`; update requirements/lock.py")


def compile_lock(name: str, extras: tuple[str, ...], find_links: str, upgrade: bool) -> None:
    """Resolve one lock with uv and write it with the header tests/test_lock.py reads."""
    out = HERE / name
    args = ["pip", "compile", "pyproject.toml"]
    for extra in extras:
        args += ["--extra", extra]
    args += ["--python-version", PYTHON_VERSION, "--python-platform", PYTHON_PLATFORM]
    if name != FULL:
        args += ["--constraint", f"requirements/{FULL}"]
    args += ["--output-file", f"requirements/{name}", "--no-header", "--quiet", "--annotation-style", "line"]
    with tempfile.TemporaryDirectory() as tmp:
        override = Path(tmp) / "torch-cpu.txt"
        override.write_text(torch_cpu_pin() + "\n")
        cmd = [*_uv(), *args, "--find-links", find_links, "--override", str(override)]
        subprocess.run(cmd + (["--upgrade"] if upgrade else []), cwd=ROOT, check=True)
        # A stable name for the temporary file in the `# via` notes, so a rerun changes nothing.
        body = out.read_text().replace(str(override), "torch-cpu")
    # torch's CPU wheel is 2.13.0+cpu; pin the public version so pip takes the CPU build from
    # wherever it is configured to look (find-links or the PyTorch CPU index).
    body = re.sub(r"^([A-Za-z0-9._-]+==[^\s+;#]+)\+[A-Za-z0-9.]+", r"\1", body, flags=re.M)
    cuda = [p for p in parse_pins(body) if p.startswith(("nvidia-", "triton"))]
    if cuda:
        sys.exit(
            f"{name}: resolved the CUDA build of torch ({', '.join(cuda)}); pass --find-links "
            "with a folder holding the torch CPU wheel (requirements/README.md)"
        )
    version = subprocess.run([*_uv(), "--version"], capture_output=True, text=True, check=True).stdout.strip()
    header = [
        f"# Lock for vgn-service extras [{','.join(extras)}]: exact versions of every package.",
        f"# Resolved for {PLATFORM_TEXT} by {version}.",
        f"# Regenerate (after changing pyproject.toml's dependencies): {REGENERATE}",
        f"#   which runs: uv {' '.join(args)} --find-links <folder with the torch CPU wheel> "
        f"--override <file with {torch_cpu_pin()}>",
        f"# {HASH_KEY}: {pyproject_deps_hash()}",
        "",
    ]
    out.write_text("\n".join(header) + body)


def main() -> None:
    """Regenerate every lock in LOCKS."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--upgrade", action="store_true", help="take the newest allowed versions")
    parser.add_argument(
        "--find-links",
        default=_default_find_links(),
        help="folder with the torch CPU wheel (default /opt/wheels where it exists)",
    )
    opts = parser.parse_args()
    if not opts.find_links:
        sys.exit("no folder with the torch CPU wheel: see requirements/README.md, then pass --find-links")
    for name, extras in LOCKS.items():
        compile_lock(name, extras, opts.find_links, opts.upgrade)
        print(f"wrote requirements/{name}")


if __name__ == "__main__":
    main()
