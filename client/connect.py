"""One entry point for every place that takes a service URL: the scheme picks the transport.

``http://`` / ``https://`` give a ``VGNClient``; ``grpc://`` / ``grpcs://`` a ``GRPCClient``
(imported only then, so the base install needs no grpcio).
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from client.extras import missing_extra
from client.http import VGNClient
from client.recovery import DEFAULT_REPLAY, Replay

if TYPE_CHECKING:
    from client.grpc_client import GRPCClient

log = logging.getLogger("vgn.client")

GRPC_SCHEMES = ("grpc://", "grpcs://")


def is_grpc_url(url: str) -> bool:
    """Whether ``url`` names the gRPC front end (``grpc://`` or ``grpcs://``, any case)."""
    return url.lower().startswith(GRPC_SCHEMES)


def connect(
    url: str, api_key: str | None = None, timeout: float = 30.0, replay: Replay | None = DEFAULT_REPLAY
) -> VGNClient | GRPCClient:
    """A client for ``url``; both kinds have the same methods and return types (``replay``:
    what each keeps to rebuild a session lost with its replica, ``client.recovery``)."""
    log.debug("connecting to %s over %s", url, "gRPC" if is_grpc_url(url) else "HTTP")
    if not is_grpc_url(url):
        return VGNClient(url, api_key=api_key, timeout=timeout, replay=replay)
    try:
        from client.grpc_client import GRPCClient
    except ImportError as error:
        raise ImportError(missing_extra("a grpc:// URL", "grpc", error)) from None
    return GRPCClient(url, api_key=api_key, timeout=timeout, replay=replay)
