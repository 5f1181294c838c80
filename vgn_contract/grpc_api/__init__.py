"""Python stubs of ``vgn_contract/proto/vgn/v1/grasp_planning.proto`` (generated, checked in) and the
conversions between them and the wire schemas of ``vgn_contract.schemas``.

Importing the stubs needs the ``grpc`` extra (grpcio, protobuf); the HTTP client does not.
Regenerate after editing the ``.proto``: ``python -m vgn_contract.grpc_api.generate``.
"""
