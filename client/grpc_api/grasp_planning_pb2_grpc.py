"""Moved to ``vgn_contract.grpc_api.grasp_planning_pb2_grpc``; re-exported here for one release."""

from vgn_contract.grpc_api.grasp_planning_pb2_grpc import (
    GRPC_GENERATED_VERSION,
    GRPC_VERSION,
    GraspPlanning,
    GraspPlanningServicer,
    GraspPlanningStub,
    add_GraspPlanningServicer_to_server,
)

__all__ = [
    "GRPC_GENERATED_VERSION",
    "GRPC_VERSION",
    "GraspPlanning",
    "GraspPlanningServicer",
    "GraspPlanningStub",
    "add_GraspPlanningServicer_to_server",
]
