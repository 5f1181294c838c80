"""Prometheus metrics of one app instance (its own registry, so several apps can coexist)."""

from __future__ import annotations

import time

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram, generate_latest
from starlette.requests import Request
from starlette.types import ASGIApp, Message, Receive, Scope, Send

LATENCY_BUCKETS = (0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0)


class ServiceMetrics:
    """The app's counters, histograms and gauges, in a registry of its own."""

    def __init__(self) -> None:
        self.registry = CollectorRegistry()
        self.requests = Counter(
            "vgn_requests_total",
            "HTTP requests by route and status",
            ["method", "route", "status"],
            registry=self.registry,
        )
        self.latency = Histogram(
            "vgn_request_duration_seconds",
            "HTTP request latency",
            ["method", "route"],
            buckets=LATENCY_BUCKETS,
            registry=self.registry,
        )
        self.integration = Histogram(
            "vgn_integration_seconds",
            "TSDF integration time per frame",
            buckets=LATENCY_BUCKETS,
            registry=self.registry,
        )
        self.planning = Histogram(
            "vgn_planning_seconds",
            "grid read-out + network + detection time",
            buckets=LATENCY_BUCKETS,
            registry=self.registry,
        )
        self.grasps = Counter("vgn_grasps_returned_total", "grasps returned", registry=self.registry)
        self.sessions = Gauge("vgn_sessions", "live sessions", registry=self.registry)
        self.model_loaded = Gauge("vgn_model_loaded", "1 when a model is loaded", registry=self.registry)

    def render(self) -> bytes:
        """The registry in the Prometheus text format, for ``GET /metrics``."""
        return generate_latest(self.registry)


class RequestMetrics:
    """ASGI middleware counting requests and their latency by route template (not raw path,
    so session ids do not explode the label set)."""

    def __init__(self, app: ASGIApp, metrics: ServiceMetrics) -> None:
        self.app = app
        self.metrics = metrics

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Time the request and count it under its route and status, a failed one as 500."""
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started = time.perf_counter()
        status = 500

        async def recording_send(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = message["status"]
            await send(message)

        try:
            await self.app(scope, receive, recording_send)
        finally:
            route = scope.get("route")
            template = getattr(route, "path", "unmatched")
            method = Request(scope).method
            self.metrics.requests.labels(method, template, str(status)).inc()
            self.metrics.latency.labels(method, template).observe(time.perf_counter() - started)
