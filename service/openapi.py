"""Write the app's OpenAPI document to ``openapi.json``: ``python -m service.openapi``."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from service.http_app import create_app
from service.settings import Settings

DEFAULT_PATH = Path(__file__).resolve().parent.parent / "openapi.json"


def render() -> str:
    """The OpenAPI document, independent of the environment's settings."""
    document = create_app(Settings(model=None, api_key=None)).openapi()
    return json.dumps(document, indent=2, sort_keys=True) + "\n"


def main(argv: list[str] | None = None) -> None:
    """Write the document to the path given, or to the repository's ``openapi.json``."""
    parser = argparse.ArgumentParser(prog="python -m service.openapi", description=__doc__)
    parser.add_argument("path", nargs="?", type=Path, default=DEFAULT_PATH, help="where to write it")
    path = parser.parse_args(argv).path
    path.write_text(render())
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
