"""A missing extra is explained one way everywhere: what needs it, what failed, the install that fixes it."""

from __future__ import annotations

from client.extras import missing_extra


def test_the_message_names_the_feature_the_failure_and_the_install():
    error = ModuleNotFoundError("No module named 'grpc'")
    text = missing_extra("gRPC", "grpc", error, ", or set VGN_GRPC_PORT=0")
    assert text == (
        "gRPC needs the grpc extra (No module named 'grpc'): pip install 'vgn-service[grpc]', or set VGN_GRPC_PORT=0"
    )
    assert (
        missing_extra("serving", "service")
        == "serving needs the service extra: pip install 'vgn-service[service]'"
    )
