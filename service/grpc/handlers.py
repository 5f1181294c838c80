"""The method handlers of ``vgn.v1.GraspPlanning``, built from the service descriptor with
request parsers that never fail.

grpcio answers a request whose bytes do not parse as the method's message with INTERNAL
("Exception deserializing request!"), which reads as a server bug. Here such bytes become a
``MalformedRequest`` that the servicer refuses with INVALID_ARGUMENT, naming the message type
and what the parser objected to.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import grpc
from google.protobuf.message import DecodeError

from vgn_contract.grpc_api import grasp_planning_pb2 as pb

SERVICE = pb.DESCRIPTOR.services_by_name["GraspPlanning"]


@dataclass(frozen=True)
class MalformedRequest:
    """Request bytes that are not a valid ``message_type``; ``reason`` is the parser's."""

    message_type: str
    reason: str

    def describe(self) -> str:
        """The INVALID_ARGUMENT message: which message type, and what the parser objected to."""
        return f"the request is not a valid {self.message_type} message ({self.reason})"


def tolerant_parser(message_class: Any) -> Callable[[bytes], Any]:
    """``message_class.FromString`` that returns a ``MalformedRequest`` instead of raising."""
    full_name = message_class.DESCRIPTOR.full_name

    def parse(data: bytes) -> Any:
        try:
            return message_class.FromString(data)
        except (DecodeError, ValueError, RuntimeError) as error:
            return MalformedRequest(full_name, str(error) or type(error).__name__)

    return parse


def method_handlers(servicer: Any) -> dict[str, grpc.RpcMethodHandler]:
    """One handler per method of the service, bound to ``servicer``'s method of that name."""
    handlers = {}
    for method in SERVICE.methods:
        request_class = getattr(pb, method.input_type.name)
        response_class = getattr(pb, method.output_type.name)
        make = {
            (False, False): grpc.unary_unary_rpc_method_handler,
            (True, False): grpc.stream_unary_rpc_method_handler,
            (False, True): grpc.unary_stream_rpc_method_handler,
            (True, True): grpc.stream_stream_rpc_method_handler,
        }[(method.client_streaming, method.server_streaming)]
        handlers[method.name] = make(
            getattr(servicer, method.name),
            request_deserializer=tolerant_parser(request_class),
            response_serializer=response_class.SerializeToString,
        )
    return handlers


def add_servicer(servicer: Any, server: grpc.Server) -> None:
    """Register ``servicer`` on ``server`` as ``vgn.v1.GraspPlanning``."""
    handlers = method_handlers(servicer)
    server.add_generic_rpc_handlers((grpc.method_handlers_generic_handler(SERVICE.full_name, handlers),))
    server.add_registered_method_handlers(SERVICE.full_name, handlers)
