"""The app in-process over given weights, for tests that need a model other than the fixtures'."""

from __future__ import annotations

from pathlib import Path

from fastapi.testclient import TestClient

from service.core import PlanningService
from service.http_app import create_app
from service.settings import Settings


def serve(weights: Path) -> TestClient:
    """A client of the app serving ``weights`` without an API key (use as a context manager)."""
    return TestClient(create_app(core=PlanningService.from_settings(Settings(model=weights, api_key=None))))
