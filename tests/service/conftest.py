"""Fixtures shared by the service's tests."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from client.grpc_client import GRPCClient
from client.http import VGNClient
from service.launch.embedded import EmbeddedService


@pytest.fixture
def clients(service: EmbeddedService) -> Iterator[tuple[VGNClient, GRPCClient]]:
    """An HTTP and a gRPC client of the module's ``service`` (each module starts its own)."""
    with VGNClient(service.url) as http, GRPCClient(service.grpc_url) as rpc:
        yield http, rpc
