"""Moved to ``vgn_contract.grpc_api``; its modules are re-exported here for one release."""

from client.moved import warn_moved

warn_moved("client.grpc_api", "vgn_contract.grpc_api")
