"""The FastAPI application, served by ``uvicorn service.app:app`` (which prepares the process first).

The model is loaded at start-up (lifespan), so importing this module is cheap and a
misconfigured ``VGN_MODEL`` stops the server with a clear message instead of serving 500s.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator
from typing import TYPE_CHECKING

from fastapi import FastAPI
from starlette.formparsers import MultiPartParser

from client.extras import missing_extra
from service.api.docs import docs_urls, install_docs
from service.api.errors import install_error_handlers
from service.api.limits import MULTIPART_OVERHEAD, BodySizeLimit
from service.api.metrics import RequestMetrics, ServiceMetrics
from service.api.routes import api, health
from service.api.viewer import viewer, viewer_assets
from service.core import PlanningService
from service.settings import Settings

if TYPE_CHECKING:
    import grpc

log = logging.getLogger("vgn.service")
SWEEP_INTERVAL_S = 30.0


def create_app(settings: Settings | None = None, core: PlanningService | None = None) -> FastAPI:
    """An app over ``core`` (built from ``settings`` at start-up when not given)."""
    settings = settings or (core.settings if core else Settings())

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        owned = app.state.core is None  # a core handed in is closed by whoever built it
        if owned:
            app.state.core = await asyncio.to_thread(PlanningService.from_settings, settings)
        service: PlanningService = app.state.core
        info = service.model_info()
        log.info("model: %s", f"{info.model_id} from {info.source}" if info.loaded else info.detail)
        grpc_server = start_grpc(service, settings, app.state.metrics)
        sweeper = asyncio.create_task(_sweep_forever(service))
        try:
            yield
        finally:
            sweeper.cancel()
            if grpc_server is not None:  # let calls in flight finish, briefly
                await asyncio.to_thread(lambda: grpc_server.stop(grace=1.0).wait(2.0))
            if owned:  # a restart of the app builds a fresh one
                await asyncio.to_thread(service.close)
                app.state.core = None

    app = FastAPI(
        title="vgn-service",
        version="0.1.0",
        summary="Real-time 6-DOF grasp planning with the Volumetric Grasping Network",
        lifespan=lifespan,
        **docs_urls(),
    )
    app.state.settings = settings
    app.state.core = core
    app.state.metrics = ServiceMetrics()
    install_error_handlers(app)
    app.include_router(health)
    app.include_router(api)
    app.include_router(viewer)
    app.include_router(viewer_assets)
    install_docs(app)
    app.add_middleware(BodySizeLimit, max_frame_bytes=settings.max_frame_bytes)
    # Starlette spools file parts over 1 MiB to disk; a 640x480 float32 frame is 1.2 MB.
    # Bodies are already capped above, so keep whole frames in memory (halves parsing time).
    MultiPartParser.spool_max_size = max(
        MultiPartParser.spool_max_size, settings.max_frame_bytes + MULTIPART_OVERHEAD
    )
    app.add_middleware(RequestMetrics, metrics=app.state.metrics)
    return app


def start_grpc(service: PlanningService, settings: Settings, metrics: ServiceMetrics) -> grpc.Server | None:
    """The gRPC front end on the same core (``VGN_GRPC_PORT``; 0: none). Imported only when
    wanted, so an HTTP-only install needs no grpcio; a port in use stops the start-up."""
    if settings.grpc_port == 0:
        return None
    try:
        from service.grpc.server import build_server
    except ImportError as error:
        raise RuntimeError(missing_extra("gRPC", "grpc", error, ", or set VGN_GRPC_PORT=0")) from None
    server, port = build_server(service, settings.grpc_host, settings.grpc_port, metrics)
    log.info("gRPC: listening on %s:%d", settings.grpc_host, port)
    return server


async def _sweep_forever(service: PlanningService) -> None:
    """Drop expired sessions even when nobody calls, so their memory is returned."""
    while True:
        await asyncio.sleep(SWEEP_INTERVAL_S)
        dropped = service.sessions.sweep()
        if dropped:
            log.info("expired %d idle session(s)", dropped)


app = create_app()
