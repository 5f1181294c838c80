"""Moved to ``vgn_contract.grpc_api`` (the wire contract); its modules here re-export theirs for one release."""
