"""Moved to ``vgn_contract.grpc_api.grasp_planning_pb2_grpc``; re-exported here for one release."""

from client.moved import warn_moved
from vgn_contract.grpc_api.grasp_planning_pb2_grpc import (
    GRPC_GENERATED_VERSION,
    GRPC_VERSION,
    GraspPlanning,
    GraspPlanningServicer,
    GraspPlanningStub,
    add_GraspPlanningServicer_to_server,
)

warn_moved("client.grpc_api.grasp_planning_pb2_grpc", "vgn_contract.grpc_api.grasp_planning_pb2_grpc")

__all__ = [
    "GRPC_GENERATED_VERSION",
    "GRPC_VERSION",
    "GraspPlanning",
    "GraspPlanningServicer",
    "GraspPlanningStub",
    "add_GraspPlanningServicer_to_server",
]
