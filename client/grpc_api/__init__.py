"""Moved to ``vgn_contract.grpc_api``; its modules are re-exported here for one release."""
