"""The checked-in gRPC stubs are generated from ``vgn_contract/proto/vgn/v1/grasp_planning.proto`` and must not drift."""

from __future__ import annotations

from pathlib import Path

import pytest

from vgn_contract.grpc_api import generate


def test_stubs_match_the_proto(tmp_path: Path):
    pytest.importorskip("grpc_tools", reason="generating stubs needs grpcio-tools (the dev extra)")
    fresh = generate.generate(tmp_path)
    for path in fresh:
        committed = generate.PACKAGE_DIR / path.name
        assert committed.read_text() == path.read_text(), (
            f"{committed.name} differs from what grpcio-tools makes of the .proto: regenerate with "
            "`python -m vgn_contract.grpc_api.generate` (with the pinned grpcio-tools of the dev extra)"
        )


def test_stubs_import_without_the_proto_tree():
    """The service stub imports the message module relatively, so the installed package works."""
    from vgn_contract.grpc_api import grasp_planning_pb2, grasp_planning_pb2_grpc

    assert grasp_planning_pb2_grpc.vgn_dot_v1_dot_grasp__planning__pb2 is grasp_planning_pb2
