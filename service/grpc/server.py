"""Build and start the gRPC server: ``vgn.v1.GraspPlanning``, the standard health service
(``grpc.health.v1``) and server reflection, so ``grpcurl`` and load balancers work."""

from __future__ import annotations

from concurrent import futures

import grpc
from grpc_health.v1 import health, health_pb2, health_pb2_grpc
from grpc_reflection.v1alpha import reflection

from service.api.metrics import ServiceMetrics
from service.core import PlanningService
from service.grpc.errors import SERVICE_NAME
from service.grpc.handlers import add_servicer
from service.grpc.servicer import GraspPlanning

#: Room beside the depth bytes in one frame message (pose, intrinsics, field tags).
MESSAGE_OVERHEAD = 64 * 1024
WORKERS = 8


class GRPCPortError(RuntimeError):
    """The gRPC port cannot be bound (taken by another process, or not ours to use)."""


def build_server(
    core: PlanningService, host: str, port: int, metrics: ServiceMetrics | None = None
) -> tuple[grpc.Server, int]:
    """A started server on ``host:port`` and the port it bound (``port`` 0: any free one)."""
    options = [
        # Without this, Linux lets a second server bind the same port and share its traffic.
        ("grpc.so_reuseport", 0),
        ("grpc.max_receive_message_length", core.settings.max_frame_bytes + MESSAGE_OVERHEAD),
        ("grpc.max_send_message_length", -1),
    ]
    server = grpc.server(futures.ThreadPoolExecutor(max_workers=WORKERS, thread_name_prefix="vgn-grpc"),
                         options=options)  # fmt: skip
    add_servicer(GraspPlanning(core, metrics), server)
    health_servicer = health.HealthServicer()
    health_pb2_grpc.add_HealthServicer_to_server(health_servicer, server)
    reflection.enable_server_reflection((SERVICE_NAME, health.SERVICE_NAME, reflection.SERVICE_NAME), server)
    address = f"{host}:{port}"
    try:
        bound = server.add_insecure_port(address)
    except RuntimeError as error:
        raise GRPCPortError(_port_message(address, error)) from None
    if bound == 0:
        raise GRPCPortError(_port_message(address, "bind failed"))
    status = (
        health_pb2.HealthCheckResponse.SERVING
        if core.planner.ready
        else health_pb2.HealthCheckResponse.NOT_SERVING
    )
    for name in ("", SERVICE_NAME):  # "" is the whole server, as load balancers ask
        health_servicer.set(name, status)
    server.start()
    return server, bound


def _port_message(address: str, error: object) -> str:
    return (
        f"cannot serve gRPC on {address} ({error}): the port is probably in use; set VGN_GRPC_PORT "
        "to a free port, or VGN_GRPC_PORT=0 to turn gRPC off"
    )
