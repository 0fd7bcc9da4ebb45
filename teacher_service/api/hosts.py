"""Answer only requests addressed to an allowed host name (``KC_ALLOWED_HOSTS``).

A web page the user opens can make its own domain resolve to 127.0.0.1 (DNS rebinding) and then
read from, or write to, a service on the loopback as if it were that page's origin. Such requests
still carry the page's host name in ``Host``, so refusing unknown names closes that door. Written
here rather than taken from Starlette, whose check splits ``[::1]:8000`` at the first colon.
"""

from __future__ import annotations

from starlette.datastructures import Headers
from starlette.responses import JSONResponse
from starlette.types import ASGIApp, Receive, Scope, Send


def host_name(header: str) -> str:
    """The ``Host`` header without its port, lower-case; IPv6 addresses keep their brackets."""
    header = header.strip().lower()
    if header.startswith("["):
        return header[: header.find("]") + 1]
    return header.partition(":")[0]


class AllowedHosts:
    """The host names answered: exact names, and ``*.example.org`` for the subdomains of one."""

    def __init__(self, allowed: list[str]) -> None:
        self.allowed = allowed
        self.names = frozenset(name for name in allowed if not name.startswith("*."))
        self.suffixes = tuple(name[1:] for name in allowed if name.startswith("*."))

    def allows(self, name: str) -> bool:
        return name in self.names or (bool(name) and name.endswith(self.suffixes))


class AllowedHostsMiddleware:
    def __init__(self, app: ASGIApp, allowed: list[str]) -> None:
        self.app = app
        self.hosts = AllowedHosts(allowed)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        name = host_name(Headers(scope=scope).get("host", ""))
        if self.hosts.allows(name):
            await self.app(scope, receive, send)
            return
        response = JSONResponse(
            {
                "detail": f"this teacher service does not answer for host {name[:100]!r}; it answers for "
                f"{', '.join(self.hosts.allowed)} (KC_ALLOWED_HOSTS; add the name you reach it by there)"
            },
            status_code=400,
        )
        await response(scope, receive, send)
