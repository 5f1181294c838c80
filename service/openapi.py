"""Write the app's OpenAPI document to ``openapi.json``: ``python -m service.openapi``."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from service.app import create_app
from service.settings import Settings

DEFAULT_PATH = Path(__file__).resolve().parent.parent / "openapi.json"


def render() -> str:
    """The OpenAPI document, independent of the environment's settings."""
    document = create_app(Settings(model=None, api_key=None)).openapi()
    return json.dumps(document, indent=2, sort_keys=True) + "\n"


def main() -> None:
    """Write the document to the path given, or to the repository's ``openapi.json``."""
    path = Path(sys.argv[1]) if len(sys.argv) > 1 else DEFAULT_PATH
    path.write_text(render())
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
