"""Who sent a request, as the TUI, ``/api/job`` and the web page show it."""

from __future__ import annotations

from starlette.requests import Request


def client_name(request: Request) -> str:
    """Who sent it, as the TUI and /api/job show it: the client's address and program."""
    host = request.client.host if request.client else "?"
    agent = "".join(c for c in request.headers.get("user-agent", "") if c.isprintable())[:60]
    return f"{host} ({agent})" if agent else host
