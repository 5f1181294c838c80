"""Docstrings of the shipped packages explain; they are not lab notes.

A docstring says what a thing does and why, in a few lines. A measured figure (a latency, a
speed-up, a share of runs) or the machine it was measured on belongs on a documentation page
beside where and how it was measured (docs/performance.md, docs/design.md), where it can be
updated without touching code and is said once. Values of settings and physical constants
("5 cm", "10 Hz", "95 % interval") are not measurements and are allowed. The same holds for the
field descriptions of the API's schemas and the service's settings, which users read in the
HTTP reference, openapi.json, the configuration page and ``--help``.
"""

from __future__ import annotations

import ast
import importlib
import re
from collections.abc import Iterator
from pathlib import Path

import pytest
from pydantic import BaseModel

ROOT = Path(__file__).resolve().parents[1]
MAX_LINES = 12

#: What reads as a measurement or a machine, each with a name for the failure message.
LAB_NOTES: dict[str, re.Pattern[str]] = {
    # "22.1 ms", "~4 ms", "10 s", "3 minutes": a duration with its unit (not "HTTP 500s").
    "duration": re.compile(
        r"(?<![\w.])\d+(?:[.,]\d+)?(?:\s?[-–]\s?\d+(?:\.\d+)?)?"
        r"(?:\s?(?:ms|µs|us|ns|secs?|seconds?|mins?|minutes?|hours?)|\s[sh])\b"
    ),
    # "81.3 %", "40 %": a share, unless it names a confidence interval ("95 % Wilson interval").
    "percentage": re.compile(r"(?<![\w.])\d+(?:\.\d+)?\s?%(?!\s*(?:Wilson|confidence|interval))"),
    # "8x faster", "1.6x as long", "15-25x the coarse one": a measured speed-up or slow-down.
    "ratio": re.compile(
        r"(?<![\w.])\d+(?:\.\d+)?(?:\s?[-–]\s?\d+(?:\.\d+)?)?\s?[x×]\s(?:faster|slower|as\b|the\b|more\b|less\b)"
    ),
    # Latency percentiles quoted as figures ("p50").
    "percentile": re.compile(r"\bp(?:50|90|95|99)\b"),
    # The machine: accelerator models and core counts ("H200", "2-core VM", "on 2 cores").
    "accelerator": re.compile(r"\b(?:[AHLV]100|H200|A10G?|L4|L40S?|T4|RTX\s?\d{4}|Xeon|EPYC|Ryzen)\b"),
    "cores": re.compile(r"(?<![\w.])\d+[-\s](?:CPU\s)?(?:cores?|vCPUs?)\b"),
    # When a run happened: an ISO date.
    "date": re.compile(r"\b20\d\d-\d\d-\d\d\b"),
}


def shipped_packages() -> list[str]:
    """The packages pyproject.toml installs (``tool.setuptools.packages.find.include``)."""
    text = (ROOT / "pyproject.toml").read_text()  # no tomllib: the project supports Python 3.10
    section = text.split("[tool.setuptools.packages.find]", 1)[1]
    include = re.search(r"^include\s*=\s*\[([^\]]*)\]", section, re.MULTILINE)
    assert include, "pyproject.toml names no packages to install"
    return sorted({pattern.rstrip("*") for pattern in re.findall(r'"([^"]+)"', include.group(1))})


def docstrings(path: Path) -> Iterator[tuple[str, int, str]]:
    """``(qualified name, line, docstring)`` of the module and every class and function in it."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))

    def walk(node: ast.AST, prefix: str) -> Iterator[tuple[str, int, str]]:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
                name = f"{prefix}{child.name}"
                text = ast.get_docstring(child, clean=True)
                if text:
                    yield name, child.lineno, text
                yield from walk(child, f"{name}.")
            else:
                yield from walk(child, prefix)

    text = ast.get_docstring(tree, clean=True)
    if text:
        yield "<module>", 1, text
    yield from walk(tree, "")


def source_files() -> list[Path]:
    files = []
    for package in shipped_packages():
        files += [
            path
            for path in sorted((ROOT / package).rglob("*.py"))
            if not path.name.endswith(("_pb2.py", "_pb2_grpc.py"))  # generated gRPC stubs
        ]
    return files


def lab_notes(text: str) -> list[str]:
    """Each measured figure or machine in ``text``, as ``kind: 'match'``."""
    return [
        f"{kind}: {match.group(0)!r}"
        for kind, pattern in LAB_NOTES.items()
        for match in pattern.finditer(text)
    ]


def problems(path: Path) -> list[str]:
    found = []
    where = path.relative_to(ROOT)
    for name, line, text in docstrings(path):
        lines = len(text.splitlines())
        if lines > MAX_LINES:
            found.append(f"{where}:{line} {name}: {lines} lines (at most {MAX_LINES})")
        found += [f"{where}:{line} {name}: {note}" for note in lab_notes(text)]
    return found


def test_the_shipped_packages_are_found() -> None:
    assert shipped_packages() == [
        "client",
        "ros_bridge",
        "service",
        "sim_worker",
        "training",
        "vgn_contract",
        "vgn_data",
    ]
    assert len(source_files()) > 50


def test_docstrings_are_short_and_quote_no_measurements() -> None:
    found = [problem for path in source_files() for problem in problems(path)]
    assert not found, (
        "Docstrings explain what and why in at most 12 lines; measured figures and machines go to "
        "docs/performance.md or docs/design.md:\n" + "\n".join(found)
    )


#: Modules whose pydantic models' field descriptions are published: the wire schemas and the settings.
DESCRIBED_MODULES = ("vgn_contract.schemas", "service.settings")


def field_descriptions(module_name: str) -> Iterator[tuple[str, str]]:
    """``(Model.field, description)`` of every pydantic model the module defines."""
    module = importlib.import_module(module_name)
    for name, value in vars(module).items():
        if isinstance(value, type) and issubclass(value, BaseModel) and value.__module__ == module_name:
            for field_name, field in value.model_fields.items():
                if field.description:
                    yield f"{name}.{field_name}", field.description


def test_field_descriptions_quote_no_measurements() -> None:
    described = {
        f"{module}:{name}": text for module in DESCRIBED_MODULES for name, text in field_descriptions(module)
    }
    assert {"vgn_contract.schemas:GraspQuery.clearance", "service.settings:Settings.turn_average"} <= set(
        described
    ), "the scan found no field descriptions"
    found = [f"{where}: {note}" for where, text in described.items() for note in lab_notes(text)]
    assert not found, (
        "Field descriptions say what and why; measured figures and machines go to docs/performance.md "
        "or docs/design.md:\n" + "\n".join(found)
    )


@pytest.mark.parametrize(
    "text",
    [
        "Planning took 22.1 ms p50.",
        "Took from 17.8 to 22.1 ms.",
        "Costs ~4 ms for 640×480.",
        "Takes about 10 minutes.",
        "Whole heads made it 1.0-1.4 ms faster.",
        "On an H200 it is quick.",
        "Measured on a 2-core VM.",
        "With 2 cores, one lane each.",
        "It holds 81.3 % of grasps.",
        "It was 8x faster on a 40³ grid.",
        "A request takes about 1.6x as long.",
        "Run on 2026-11-27.",
        "Applies before max_grasps; about 3 ms.",
        "Four grids in one batch, about 2x the time of a plain request on 2 CPU cores.",
        "At about twice the planning time on a 2-core CPU.",
    ],
)
def test_measured_figures_are_caught(text: str) -> None:
    assert lab_notes(text)


@pytest.mark.parametrize(
    "text",
    [
        "Fingers 5 cm apart, moved in 2 mm steps at 10 cm/s.",
        "The cameras look at 10 Hz.",
        "A 95 % Wilson interval of a proportion.",
        "With 95 % confidence intervals.",
        "A 4×4 matrix, 640×480 pixels, 120³ voxels, a ×2 upsampling.",
        "Stops the server instead of serving 500s.",
        "Rotates by k × 90° about +z; uses the settings in ``rest_timeout`` seconds.",
        "A grid of 40 voxels with 16 channels at float16 (0.6 MB).",
    ],
)
def test_settings_and_constants_pass(text: str) -> None:
    assert not lab_notes(text)


def test_a_long_docstring_is_caught(tmp_path: Path) -> None:
    module = tmp_path / "module.py"
    body = "\n".join(f"    line {i}" for i in range(MAX_LINES))
    module.write_text(f'def f() -> None:\n    """Summary.\n\n{body}\n    """\n')
    assert [name for name, _, text in docstrings(module) if len(text.splitlines()) > MAX_LINES] == ["f"]
