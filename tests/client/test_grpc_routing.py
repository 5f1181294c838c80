"""The gRPC client names every call's session in the ``x-session-id`` metadata, the key the fleet's
HAProxy hashes on (``service.launch.haproxy``): checked on a real gRPC server on loopback that records what
each call carried, where the end-to-end fleet test needs HAProxy."""

from __future__ import annotations

from collections.abc import Iterator
from concurrent import futures

import grpc
import pytest

from client.grpc_client import GRPCClient
from service.core import PlanningService
from service.grpc.handlers import add_servicer
from service.grpc.servicer import GraspPlanning
from service.settings import Settings

#: The literal key, as HAProxy's ``balance hdr(...)`` names it (tests/fleet/test_haproxy_config.py):
#: a misspelt constant fails here.
ROUTING_KEY = "x-session-id"


class MetadataRecorder(grpc.ServerInterceptor):
    """Keeps (method, metadata) of every call the server receives."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, dict[str, str]]] = []

    def intercept_service(self, continuation, handler_call_details):
        self.calls.append((handler_call_details.method, dict(handler_call_details.invocation_metadata)))
        return continuation(handler_call_details)


@pytest.fixture
def recorded() -> Iterator[tuple[MetadataRecorder, str]]:
    recorder = MetadataRecorder()
    core = PlanningService.from_settings(Settings(model="none", api_key=None))
    server = grpc.server(futures.ThreadPoolExecutor(max_workers=4), interceptors=[recorder])
    add_servicer(GraspPlanning(core, None), server)
    port = server.add_insecure_port("127.0.0.1:0")
    server.start()
    try:
        yield recorder, f"grpc://127.0.0.1:{port}"
    finally:
        server.stop(None)
        core.close()


def test_calls_on_a_session_carry_its_id_under_the_key_the_proxy_hashes(recorded):
    recorder, url = recorded
    with GRPCClient(url) as client:
        client.create_session(session_id="routed-1")
        client.session("routed-1")
        client.delete_session("routed-1")
    named = [(method, metadata) for method, metadata in recorder.calls if method.endswith("Session")]
    assert len(named) == 3
    for method, metadata in named:
        assert metadata.get(ROUTING_KEY) == "routed-1", method
