"""Prometheus metrics (one registry per app instance) and the request-timing middleware."""

from __future__ import annotations

import time

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram, generate_latest
from starlette.types import ASGIApp, Message, Receive, Scope, Send

CONTENT_TYPE = "text/plain; version=0.0.4; charset=utf-8"


class Metrics:
    def __init__(self) -> None:
        self.registry = CollectorRegistry()
        r = self.registry
        self.requests = Counter(
            "shapes_http_requests", "HTTP requests", ["method", "route", "status"], registry=r
        )
        self.request_seconds = Histogram(
            "shapes_http_request_duration_seconds",
            "HTTP request duration",
            ["method", "route"],
            registry=r,
        )
        self.jobs = Counter("shapes_jobs", "Descriptor jobs by outcome", ["outcome"], registry=r)
        self.job_seconds = Histogram(
            "shapes_job_duration_seconds",
            "Descriptor job time from enqueue to stored result",
            buckets=(0.5, 1, 2, 5, 10, 20, 30, 60, 120, 300, 600, float("inf")),
            registry=r,
        )
        self.describe_seconds = Histogram(
            "shapes_describe_seconds",
            "Descriptor computation time reported by the worker",
            buckets=(0.5, 1, 2, 3, 5, 10, 20, 60, float("inf")),
            registry=r,
        )
        self.search_seconds = Histogram(
            "shapes_search_seconds",
            "Index search time (candidates and exact re-ranking)",
            buckets=(0.0005, 0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.5, float("inf")),
            registry=r,
        )
        self.verify_anchors = Counter(
            "shapes_verify_anchors",
            "A single view's verified candidates by whether their anchors were kept in "
            "memory or made anew",
            ["outcome"],
            registry=r,
        )
        self.index_size = Gauge("shapes_index_size", "Shapes in the index", ["preset"], registry=r)
        self.jobs_unfinished = Gauge(
            "shapes_jobs_unfinished", "Jobs queued or processing", registry=r
        )

    def render(self) -> bytes:
        return generate_latest(self.registry)


class RequestMetricsMiddleware:
    """Counts and times requests by route template (pure ASGI: keeps streaming bodies)."""

    def __init__(self, app: ASGIApp, metrics: Metrics) -> None:
        self.app = app
        self.metrics = metrics

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        start = time.perf_counter()
        status = {"code": 500}

        async def send_wrapper(message: Message) -> None:
            if message["type"] == "http.response.start":
                status["code"] = message["status"]
            await send(message)

        try:
            await self.app(scope, receive, send_wrapper)
        finally:
            route = scope.get("route")
            path = getattr(route, "path", None) or "unmatched"
            method = scope.get("method", "")
            self.metrics.requests.labels(method, path, str(status["code"])).inc()
            self.metrics.request_seconds.labels(method, path).observe(time.perf_counter() - start)
