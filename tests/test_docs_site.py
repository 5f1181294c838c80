"""The documentation site's sources are whole without building it: every page in the nav exists,
every page is in the nav, and every file a page includes (``--8<--``) exists.

CI builds the site with ``mkdocs build --strict`` (.ci/run), which checks links and renders the
docstrings; these checks run without the docs extra.
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
MKDOCS = ROOT / "mkdocs.yml"


def nav_pages() -> list[str]:
    """The .md files mkdocs.yml's nav names (read as text: the file uses mkdocs' own YAML tags)."""
    nav = MKDOCS.read_text().split("\nnav:\n", 1)[1].split("\n\n", 1)[0]
    return re.findall(r":\s*([\w./-]+\.md)\s*$", nav, flags=re.M)


def test_every_nav_page_exists():
    missing = [page for page in nav_pages() if not (DOCS / page).is_file()]
    assert not missing, f"mkdocs.yml's nav names pages that do not exist: {missing}"


def test_every_page_is_in_the_nav():
    pages = {p.relative_to(DOCS).as_posix() for p in DOCS.rglob("*.md")}
    pages = {p for p in pages if not p.startswith(("generated/", "results/"))}
    assert pages <= set(nav_pages()), (
        f"pages missing from mkdocs.yml's nav: {sorted(pages - set(nav_pages()))}"
    )


def test_every_included_file_exists():
    missing = []
    for page in DOCS.rglob("*.md"):
        for name in re.findall(r'^--8<-- "([^"]+)"', page.read_text(), flags=re.M):
            path, _, section = name.partition(":")
            file = ROOT / path
            if not file.is_file():
                missing.append(f"{page.name}: {name}")
            elif section and f"--8<-- [start:{section}]" not in file.read_text():
                missing.append(f"{page.name}: {name} (no such section)")
    assert not missing, f"included files or sections that do not exist: {missing}"


def test_the_training_page_keeps_a_place_for_the_data_figures():
    assert "<!-- TRAINING-DATA-FIGURES" in (DOCS / "data-and-training.md").read_text()
