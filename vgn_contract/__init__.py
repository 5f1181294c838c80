"""The wire contract: what the service and its clients must agree on, said once for both sides.

The request and answer schemas (``schemas``, which the HTTP API and ``openapi.json`` are built
from), the geometry both sides compute with (``geometry``), the gripper descriptions and the
built-in hands (``gripper_description``, ``grippers/``), the session snapshot format
(``snapshot``), grasp identities across re-plans (``tracking``), and the gRPC contract: the
``.proto`` (``proto/``), its generated stubs and the conversions to the schemas (``grpc_api``).

It imports nothing else of this repository, and needs only the base install (pydantic, numpy,
scipy; the gRPC stubs also need the ``grpc`` extra), so the light client carries it.
"""
