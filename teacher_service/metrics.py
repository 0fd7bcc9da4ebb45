"""The service's measurements: its Prometheus metrics, each curriculum's share of them, the
results-per-second rate the API reports, and the ASGI middleware that times requests.

Each app gets its own registry so several apps (tests) can live in one process.
"""

from __future__ import annotations

import time
from collections import deque

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram, generate_latest
from starlette.types import ASGIApp, Message, Receive, Scope, Send

_LATENCY_BUCKETS = (0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5)
_FIT_BUCKETS = (0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0, 60.0)


class ServiceMetrics:
    def __init__(self) -> None:
        self.registry = CollectorRegistry()
        self.requests = Counter(
            "kc_http_requests", "HTTP requests served.", ["method", "route", "status"], registry=self.registry
        )
        self.request_seconds = Histogram(
            "kc_http_request_duration_seconds",
            "Time to answer a request.",
            ["method", "route"],
            buckets=_LATENCY_BUCKETS,
            registry=self.registry,
        )
        self.tasks_issued = Counter("kc_tasks_issued", "Tasks handed out.", ["curriculum"], registry=self.registry)
        self.tasks_expired = Counter(
            "kc_tasks_expired", "Tasks that expired with no result.", ["curriculum"], registry=self.registry
        )
        self.results = Counter(
            "kc_results",
            "Results received, by outcome (accepted, duplicate, or expired: its task had expired).",
            ["curriculum", "outcome"],
            registry=self.registry,
        )
        self.fits = Counter("kc_fits", "Teacher model fits installed.", ["curriculum"], registry=self.registry)
        self.fit_errors = Counter(
            "kc_fit_errors",
            "Teacher model fits not installed: they raised, ran too long, were superseded or could not run.",
            ["curriculum"],
            registry=self.registry,
        )
        self.fit_timeouts = Counter(
            "kc_fit_timeouts",
            "Teacher model fits abandoned at the time limit (KC_FIT_TIMEOUT_S), their process killed.",
            ["curriculum"],
            registry=self.registry,
        )
        self.fits_superseded = Counter(
            "kc_fits_superseded",
            "Teacher model fits replaced, before they started, by the curriculum's next fit.",
            ["curriculum"],
            registry=self.registry,
        )
        self.fit_process_deaths = Counter(
            "kc_fit_process_deaths", "Fit processes that died without being told to.", registry=self.registry
        )
        self.fits_stopped = Gauge(
            "kc_fits_stopped",
            "1 once fit processes kept dying and no fits run until the service restarts, else 0.",
            registry=self.registry,
        )
        self.fit_seconds = Histogram(
            "kc_fit_duration_seconds",
            "Time one teacher model fit took.",
            ["curriculum"],
            buckets=_FIT_BUCKETS,
            registry=self.registry,
        )
        self.fits_pending = Gauge("kc_fits_pending", "Fits queued or running.", ["curriculum"], registry=self.registry)

    def render(self) -> bytes:
        return generate_latest(self.registry)

    def for_curriculum(self, name: str) -> CurriculumMetrics:
        return CurriculumMetrics(self, name)


class CurriculumMetrics:
    """One curriculum's labelled series, looked up once rather than on every request."""

    def __init__(self, metrics: ServiceMetrics, name: str) -> None:
        self.tasks_issued = metrics.tasks_issued.labels(name)
        self.tasks_expired = metrics.tasks_expired.labels(name)
        self.results_expired = metrics.results.labels(name, "expired")
        self.results_accepted = metrics.results.labels(name, "accepted")
        self.results_duplicate = metrics.results.labels(name, "duplicate")
        self.fits = metrics.fits.labels(name)
        self.fit_errors = metrics.fit_errors.labels(name)
        self.fit_seconds = metrics.fit_seconds.labels(name)
        self.fits_pending = metrics.fits_pending.labels(name)


class RateCounter:
    """Events per second over the last ``window_s`` seconds (or since counting began, if sooner)."""

    def __init__(self, window_s: float, since: float) -> None:
        self._window = window_s
        self._counting_since = since
        self._arrivals: deque[tuple[float, int]] = deque()

    def count(self, now: float, events: int) -> None:
        self._arrivals.append((now, events))
        while self._arrivals and self._arrivals[0][0] < now - self._window:
            self._arrivals.popleft()

    def per_second(self, now: float) -> float:
        recent = sum(events for at, events in self._arrivals if at >= now - self._window)
        return recent / max(min(self._window, now - self._counting_since), 1e-3)


class MetricsMiddleware:
    """Counts and times every HTTP request by its route template (not its raw path)."""

    def __init__(self, app: ASGIApp, metrics: ServiceMetrics) -> None:
        self.app = app
        self.metrics = metrics

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started = time.perf_counter()
        status = 500

        async def send_and_watch(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = message["status"]
            await send(message)

        try:
            await self.app(scope, receive, send_and_watch)
        finally:
            route = getattr(scope.get("route"), "path", "unmatched")
            method = scope["method"]
            self.metrics.requests.labels(method, route, str(status)).inc()
            self.metrics.request_seconds.labels(method, route).observe(time.perf_counter() - started)
