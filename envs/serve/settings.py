"""What every `hcgym serve` server shares: its settings and limits, and the access rule (loopback by
default; a bearer token required once bound elsewhere).

Kept free of any protocol package, so the MCP server (mcp 2.x, in the main venv) and the OpenEnv
server (openenv 0.10, whose fastmcp needs mcp < 2, in its own venv) both import it.
"""

from __future__ import annotations

import hmac
import ipaddress
import json
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, field_validator

from envs.env import MAX_TOOL_RESULT_CHARS

LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "::1")
TOKEN_ENV = "HCGYM_SERVE_TOKEN"


class ServeSettings(BaseModel):
    """What `hcgym serve` serves and its limits."""

    model_config = ConfigDict(extra="forbid")

    host: str = "127.0.0.1"
    port: int = Field(8765, ge=0, le=65535)
    domains: list[str] = Field(default_factory=lambda: ["drug_interaction"], min_length=1)
    split: str | None = "test"
    max_episodes: int = Field(64, ge=1, description="episodes (sessions) running at once; one more is refused as busy")
    idle_timeout_s: float = Field(600.0, gt=0, description="an episode idle this long is dropped")
    max_turns: int = Field(40, ge=1)
    max_tool_calls: int | None = Field(None, ge=1)
    max_tool_result_chars: int | None = Field(MAX_TOOL_RESULT_CHARS, ge=1)
    max_argument_chars: int = Field(100_000, ge=1, description="a call's arguments as JSON, at most")
    max_request_bytes: int = Field(1_000_000, ge=1024, description="an HTTP request body (or WebSocket message), at most")
    token: str | None = Field(None, description="bearer token the server requires (required off loopback)")
    max_requests: int = Field(128, ge=1, description="HTTP requests served at once; one more waits busy_wait_s "
                              "for a slot, then is answered 503 busy")
    busy_wait_s: float = Field(2.0, ge=0, description="how long a request waits for a slot before it is answered busy")
    max_connections: int = Field(1024, ge=1, description="open connections; a request on one more is answered 503")
    request_timeout_s: float = Field(10.0, gt=0, description="a request's headers, then its body, must arrive "
                                     "within this; a slower client is answered 408 and closed")
    max_sessions: int = Field(256, ge=1, description="MCP legacy-protocol (Mcp-Session-Id) sessions open at once")
    max_finished: int = Field(1024, ge=0, description="ended episodes whose score episode_result still answers")

    @field_validator("domains")
    @classmethod
    def _known_domains(cls, value: list[str]) -> list[str]:
        from envs.registry import list_domains

        unknown = [d for d in value if d not in list_domains()]
        if unknown:
            raise ValueError(f"unknown domain(s) {unknown}; registered: {', '.join(list_domains())}")
        return list(dict.fromkeys(value))

    def model_post_init(self, _context: Any) -> None:
        if not is_loopback(self.host) and not self.token:
            raise ValueError(f"host {self.host!r} is not a loopback address: a --token (or {TOKEN_ENV}) "
                             "is required to serve beyond this machine")


def is_loopback(host: str) -> bool:
    if host in LOOPBACK_HOSTS:
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


async def _refuse(scope: Any, receive: Any, send: Any, status: int, message: str) -> None:
    """Answer an HTTP request, or refuse a WebSocket handshake, with `status` and a JSON error."""
    body = json.dumps({"error": message}).encode()
    headers = [(b"content-type", b"application/json")]
    if status == 401:
        headers.append((b"www-authenticate", b"Bearer"))
    if scope["type"] == "websocket":
        await receive()  # the websocket.connect event comes before any answer
        if "websocket.http.response" in (scope.get("extensions") or {}):
            await send({"type": "websocket.http.response.start", "status": status, "headers": headers})
            await send({"type": "websocket.http.response.body", "body": body})
        else:  # the server answers the handshake with 403
            await send({"type": "websocket.close", "code": 1008, "reason": message[:120]})
        return
    await send({"type": "http.response.start", "status": status, "headers": headers})
    await send({"type": "http.response.body", "body": body})


class BearerToken:
    """ASGI wrapper: every request and WebSocket handshake must carry `Authorization: Bearer <token>`."""

    def __init__(self, app: Any, token: str) -> None:
        self.app, self.token = app, token.encode()

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        if scope["type"] in ("http", "websocket"):
            header = dict(scope.get("headers") or []).get(b"authorization", b"")
            if not hmac.compare_digest(header, b"Bearer " + self.token):
                await _refuse(scope, receive, send, 401, "unauthorized: send Authorization: Bearer <token>")
                return
        await self.app(scope, receive, send)


class LoopbackOnly:
    """ASGI wrapper for a server without a token: a connection that reached it over an address that is
    not loopback (the server was bound elsewhere by its launcher, e.g. `uvicorn --host 0.0.0.0`) is
    refused, so the token rule holds however the app is started."""

    def __init__(self, app: Any) -> None:
        self.app = app

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        if scope["type"] in ("http", "websocket"):
            local = scope.get("server")
            # a Unix socket (no port) is local to the machine
            if local and local[1] is not None and not is_loopback(str(local[0])):
                await _refuse(scope, receive, send, 403, f"this server has no token and was reached at "
                              f"{local[0]}, not a loopback address: start it with a token ({TOKEN_ENV}) "
                              "to serve beyond this machine")
                return
        await self.app(scope, receive, send)


def access_guard(app: Any, token: str | None) -> Any:
    """`app` behind the access rule: a token when one is set, otherwise loopback connections only."""
    return BearerToken(app, token) if token else LoopbackOnly(app)
