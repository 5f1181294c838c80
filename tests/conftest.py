"""Shared fixtures: a random-initialised checkpoint, the app in-process, and a real uvicorn.

Shared helper code lives in ``tests/helpers/``. Each folder of tests is a package (it has an
``__init__.py``), so pytest imports ``tests/service/test_x.py`` as ``tests.service.test_x`` and
test files in different folders may share a basename; ``pytest_configure`` refuses a folder
that lacks one.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Iterator
from pathlib import Path

import pytest
import torch

from client.http import VGNClient
from service.core import PlanningService
from service.http_app import create_app
from service.launch.embedded import EmbeddedService
from service.settings import Settings
from service.vgn.checkpoint import save_vgn
from service.vgn.network import VGN

# Apps built in tests start no gRPC server unless a test asks: test processes run side by side
# and would all want the default port. Tests that serve gRPC pick a free port.
os.environ["VGN_GRPC_PORT"] = "0"
warnings.filterwarnings("ignore", message=".*httpx2.*")
from fastapi.testclient import TestClient  # noqa: E402

TESTS = Path(__file__).resolve().parent


def pytest_configure(config: pytest.Config) -> None:
    """Without ``__init__.py`` pytest would import a folder's tests by basename, and two
    ``test_x.py`` in different folders would clash."""
    missing = sorted(
        str(folder.relative_to(TESTS.parent))
        for folder in {parent for test in TESTS.rglob("test_*.py") for parent in test.parents}
        if folder.is_relative_to(TESTS) and not (folder / "__init__.py").is_file()
    )
    if missing:
        raise pytest.UsageError(f"test folders without __init__.py: {', '.join(missing)}")


@pytest.fixture(scope="session")
def random_checkpoint(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Random-initialised VGN weights for plumbing tests (no meaningful grasps). The width
    head is biased to ~4 voxels so detection's width filter lets grasps through."""
    torch.manual_seed(0)
    network = VGN()
    with torch.no_grad():
        network.conv_width.weight.mul_(0.01)
        network.conv_width.bias.fill_(4.0)
    path = tmp_path_factory.mktemp("weights") / "random.safetensors"
    save_vgn(network, path)
    return path


@pytest.fixture
def settings(random_checkpoint: Path) -> Settings:
    return Settings(model=random_checkpoint, max_sessions=8, session_ttl_s=600, api_key=None)


@pytest.fixture
def core(settings: Settings) -> Iterator[PlanningService]:
    service = PlanningService.from_settings(settings)
    yield service
    service.close()


@pytest.fixture
def http(core: PlanningService) -> Iterator[TestClient]:
    """The app in-process, over the core fixture."""
    with TestClient(create_app(core=core)) as client:
        yield client


@pytest.fixture(scope="session")
def server(random_checkpoint: Path) -> Iterator[EmbeddedService]:
    """A real uvicorn process on loopback serving the random checkpoint."""
    env = {"VGN_MAX_FRAME_BYTES": str(4 * 1024 * 1024), "VGN_API_KEY": "", "VGN_TORCH_THREADS": "1"}
    with EmbeddedService(model=random_checkpoint, env=env) as service:
        yield service


@pytest.fixture
def vgn(server: EmbeddedService) -> Iterator[VGNClient]:
    with VGNClient(server.url) as client:
        yield client


#: Ray gives its raylet a fixed 30 s to register at start-up; on the 2-core VM it has missed
#: that now and then (under load, and once on a quiet machine), so the fixture tries again.
START_ATTEMPTS = 3


@pytest.fixture(scope="module")
def ray_address() -> Iterator[str]:
    """A local Ray instance (2 CPUs) for the module; the address commands join it by."""
    ray = pytest.importorskip("ray")
    for attempt in range(1, START_ATTEMPTS + 1):
        try:
            ray.init(address="local", num_cpus=2, include_dashboard=False, logging_level="WARNING")
            break
        except Exception as error:  # Ray raises a bare Exception for a start-up timeout
            ray.shutdown()
            if attempt == START_ATTEMPTS or "timed out during startup" not in str(error):
                raise
    try:
        yield ray.get_runtime_context().gcs_address
    finally:
        ray.shutdown()
