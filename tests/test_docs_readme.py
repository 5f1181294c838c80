"""The README is the front door: short, free of lab-notebook residue, and its links resolve.

The rules are the issue's: at most 250 lines, no dates, commit ids or home-directory paths, the two
commands first; every relative link names a file in the repository (and, for a documentation page,
a heading that exists there).
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
FIRST_LINES = [
    "# vgn-service",
    "",
    "    bash install.sh && vgn-client clear-scene --sim   # install, then clear a simulated table with the packaged model",
    "    bash install.sh --dev && python3 -m pytest        # run the tests (short set; `-m slow` for the long ones)",
]


def slugify(heading: str) -> str:
    """The anchor Python-Markdown's toc extension gives a heading (its default slugify)."""
    text = re.sub(r"[^\w\s-]", "", heading.replace("`", "")).strip().lower()
    return re.sub(r"[-\s]+", "-", text)


def anchors(page: Path) -> set[str]:
    """Anchors of a Markdown page's headings (fenced code left out)."""
    text = re.sub(r"^```.*?^```", "", page.read_text(), flags=re.S | re.M)
    return {slugify(m.group(1)) for m in re.finditer(r"^#{1,6}\s+(.+?)\s*$", text, flags=re.M)}


def relative_links(text: str) -> list[str]:
    """Link targets of ``text`` that are not URLs or in-page anchors."""
    targets = re.findall(r"\]\(([^)\s]+)\)", text)
    return [t for t in targets if not re.match(r"[a-z]+://|mailto:|#", t)]


def test_readme_starts_with_the_two_commands():
    assert README.read_text().splitlines()[: len(FIRST_LINES)] == FIRST_LINES


def test_readme_is_short():
    assert len(README.read_text().splitlines()) <= 250


@pytest.mark.parametrize(
    ("what", "pattern"),
    [
        ("a date", r"20[0-9]{2}-[0-9]{2}"),
        ("a home-directory path", r"~/"),
        ("a commit id", r"\b[0-9a-f]{7,40}\b"),
    ],
)
def test_readme_has_no_lab_notebook_residue(what: str, pattern: str):
    found = [
        (n, line) for n, line in enumerate(README.read_text().splitlines(), 1) if re.search(pattern, line)
    ]
    assert not found, f"README.md holds {what}: {found}"


def test_readme_links_resolve():
    broken = []
    for target in relative_links(README.read_text()):
        path, _, anchor = target.partition("#")
        file = ROOT / path
        if not file.exists() or (anchor and file.suffix == ".md" and anchor not in anchors(file)):
            broken.append(target)
    assert not broken, f"README.md links to what does not exist: {broken}"


def test_readme_links_into_the_documentation():
    pages = {t.partition("#")[0] for t in relative_links(README.read_text()) if t.startswith("docs/")}
    assert {"docs/getting-started.md", "docs/http-api.md", "docs/grpc-api.md", "docs/client.md",
            "docs/benchmark.md", "docs/data-and-training.md", "docs/performance.md"} <= pages  # fmt: skip


def test_readme_says_what_the_first_command_runs():
    """One round with clear-scene's defaults, not the benchmark of the results table."""
    from client.cli import build_parser

    commands = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    defaults = commands.choices["clear-scene"].parse_args([])
    said = " ".join(README.read_text().split("The first command", 1)[1].split("\n\n", 1)[0].split())
    assert (defaults.rounds, defaults.object_count, defaults.scene, defaults.selection) == (
        1,
        5,
        "blocks",
        "best",
    )
    assert "runs one round" in said and "5 blocks, the best grasp each time" in said, said
