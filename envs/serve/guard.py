"""What keeps an HTTP server of the env answering under hostile clients and load.

Two layers, both needed because neither sees everything:

* `GuardedH11Protocol` (uvicorn's h11 protocol with a deadline): a connection must deliver its first
  request's headers within `request_timeout_s`, or it is answered 408 and closed. uvicorn times out
  idle keep-alive connections but not a first request that never finishes arriving, so without this
  a half-sent request holds its connection (and a file descriptor) for ever. It also sets
  TCP_NODELAY, which uvicorn's sockets lack (each kept-alive request waited ~40 ms for a delayed ACK).
* `HTTPGuard` (ASGI middleware): a request target over 8 KiB is a 414, headers over 16 KiB a 431;
  at most `max_requests` requests in flight (one more waits up to `busy_wait_s` for a slot, then is
  answered 503 busy with Retry-After, its body not kept); a request body must arrive within
  `request_timeout_s` of its slot (else 408) and stay within `max_body_bytes` (else 413, declared or
  chunked); a client that disconnects mid-request ends quietly; an exception no handler caught is a
  500 with a short message (logged) instead of a dropped connection. A refused request's body is read and dropped (bounded) before the answer, because
  closing a socket with unread data resets it and the client would never read the refusal.

Every refusal is a JSON-RPC error object (id null), so an MCP client reads it as one.
"""

from __future__ import annotations

import asyncio
import json
import logging
import socket
from typing import Any

import anyio
from starlette.requests import ClientDisconnect
from uvicorn.protocols.http.h11_impl import H11Protocol

log = logging.getLogger("hcgym.serve")

# A request's headers, at most. h11 refuses a head this large only while it arrives in pieces (its
# limit is on an incomplete event), so the guard checks the parsed head too.
H11_MAX_HEAD = 16 * 1024
MAX_TARGET = 8 * 1024  # a request line's target (path and query), at most
BUSY_WAIT_S = 2.0  # how long a request waits for one of the in-flight slots before it is answered busy
# JSON-RPC error codes (JSON-RPC 2.0 section 5.1)
INVALID_REQUEST = -32600
INTERNAL_ERROR = -32603


def error_body(code: int, message: str) -> bytes:
    return json.dumps({"jsonrpc": "2.0", "id": None, "error": {"code": code, "message": message}}).encode()


def raw_response(status: int, reason: str, body: bytes, extra: str = "") -> bytes:
    """A whole HTTP/1.1 response as bytes, for a connection that has no request to answer through."""
    return (f"HTTP/1.1 {status} {reason}\r\ncontent-type: application/json\r\ncontent-length: {len(body)}\r\n"
            f"connection: close\r\n{extra}\r\n").encode() + body


def guarded_protocol(request_timeout_s: float) -> type[H11Protocol]:
    """uvicorn's h11 protocol whose connections must send a first request within `request_timeout_s`."""
    late = raw_response(408, "Request Timeout", error_body(
        INVALID_REQUEST, f"request timeout: the request did not arrive within {request_timeout_s:g} s"))
    bad_head = raw_response(400, "Bad Request", error_body(INVALID_REQUEST, (
        f"bad HTTP request: a malformed request line or header (e.g. a control character), or a request line "
        f"and headers over {H11_MAX_HEAD // 1024} KiB (a tool name travels in the Mcp-Name header)")))

    class GuardedH11Protocol(H11Protocol):
        def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
            # asyncio sets TCP_NODELAY only on sockets made with proto IPPROTO_TCP, and uvicorn's listening
            # socket (hence every accepted one) has proto 0: a kept-alive connection then holds each
            # response's body behind its headers until the client's delayed ACK, about 40 ms a request.
            sock = transport.get_extra_info("socket")
            if sock is not None and sock.family in (socket.AF_INET, socket.AF_INET6):
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            super().connection_made(transport)
            self._first_request_timer = self.loop.call_later(request_timeout_s, self._first_request_late)

        def _first_request_late(self) -> None:
            # `cycle` is set once a request's headers are parsed; later requests on a kept-alive
            # connection are bounded by uvicorn's keep-alive timeout.
            if self.cycle is None and not self.transport.is_closing():
                self.transport.write(late)
                self.transport.close()

        def handle_websocket_upgrade(self, event: Any) -> None:
            # The connection becomes a WebSocket with no `cycle`: without this the deadline would close it
            # (writing an HTTP 408 into the socket) request_timeout_s after it opened.
            self._first_request_timer.cancel()
            super().handle_websocket_upgrade(event)

        def connection_lost(self, exc: Exception | None) -> None:
            self._first_request_timer.cancel()
            super().connection_lost(exc)

        def send_400_response(self, msg: str) -> None:
            # h11 refused the request's head; uvicorn's own answer is plain text a client cannot parse
            if not self.transport.is_closing():
                self.transport.write(bad_head)
                self.transport.close()

    return GuardedH11Protocol


def _only(exc: BaseException, kind: type[BaseException]) -> bool:
    """Whether `exc` is `kind`, or a group (anyio task groups raise them) of nothing else."""
    if isinstance(exc, BaseExceptionGroup):
        return all(_only(e, kind) for e in exc.exceptions)
    return isinstance(exc, kind)


class HTTPGuard:
    """ASGI middleware: the in-flight bound, the head and body limits, the body deadline, and no request
    left unanswered."""

    def __init__(self, app: Any, *, max_requests: int, request_timeout_s: float, max_body_bytes: int,
                 busy_wait_s: float = BUSY_WAIT_S) -> None:
        self.app = app
        self.max_requests = max_requests
        self.request_timeout_s = request_timeout_s
        self.max_body_bytes = max_body_bytes
        self.busy_wait_s = busy_wait_s
        self._slots: anyio.Semaphore | None = None  # made in the server's event loop, on first use

    @property
    def in_flight(self) -> int:
        return 0 if self._slots is None else self.max_requests - self._slots.value

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        acquired = False
        refused = self._refusal(scope)
        if refused is not None:
            await self._drain(receive, anyio.current_time() + self.request_timeout_s)
            await self._answer(send, *refused)
            return
        # A GET is a session's long-lived event stream (bounded by the session limit), not work.
        counted = scope.get("method") != "GET"
        if counted:
            if self._slots is None:
                self._slots = anyio.Semaphore(self.max_requests)
            # A burst waits its turn for a while (its body still in the socket, not in memory)
            with anyio.move_on_after(self.busy_wait_s):
                await self._slots.acquire()
                acquired = True
            if not acquired:
                await self._drain(receive, anyio.current_time() + self.request_timeout_s)
                await self._answer(send, 503, error_body(INTERNAL_ERROR, (
                    f"busy: {self.max_requests} requests are being served (the server's --max-requests) and "
                    f"none finished within {self.busy_wait_s:g} s; retry shortly")), [(b"retry-after", b"1")])
                return
        # the body's deadline runs from here: the wait for a slot is not the client's doing
        deadline = anyio.current_time() + self.request_timeout_s
        try:
            # The whole body is read here, before the app runs (the SDK buffers it anyway), so a slow or
            # oversized body is answered by this guard and never becomes an exception inside the app.
            body = await self._read_body(receive, deadline, send)
            if body is None:
                return
            await self._run(scope, body, receive, send)
        finally:
            if counted:
                self._slots.release()

    def _refusal(self, scope: Any) -> tuple[int, bytes] | None:
        """A request refused on its head alone: an over-long target, over-large headers, a declared
        body over the limit."""
        target = len(scope.get("raw_path") or b"") + len(scope.get("query_string") or b"")
        if target > MAX_TARGET:
            return 414, error_body(INVALID_REQUEST, f"request target of {target} bytes, over {MAX_TARGET}")
        headers = scope.get("headers") or []
        size = sum(len(k) + len(v) + 4 for k, v in headers)
        if size > H11_MAX_HEAD:
            return 431, error_body(INVALID_REQUEST, (
                f"request headers of {size} bytes, over {H11_MAX_HEAD // 1024} KiB (a tool name travels in the "
                "Mcp-Name header: at most 128 characters)"))
        declared = dict(headers).get(b"content-length", b"")
        if declared.isdigit() and int(declared) > self.max_body_bytes:
            return 413, self._too_large()
        return None

    async def _read_body(self, receive: Any, deadline: float, send: Any) -> bytes | None:
        """The request body, or None once the request is answered (408, 413) or its client gone."""
        chunks, size = [], 0
        with anyio.move_on_after(max(0.0, deadline - anyio.current_time())) as waited:
            while True:
                message = await receive()
                if message["type"] != "http.request":
                    return None  # disconnected: nobody is left to answer
                chunk = message.get("body", b"")
                size += len(chunk)
                if size > self.max_body_bytes:  # a chunked body declares no length
                    if message.get("more_body", False):
                        await self._drain(receive, deadline)
                    await self._answer(send, 413, self._too_large())
                    return None
                chunks.append(chunk)
                if not message.get("more_body", False):
                    return b"".join(chunks)
        if waited.cancelled_caught:
            await self._answer(send, 408, error_body(INVALID_REQUEST, (
                f"request timeout: the request body did not arrive within {self.request_timeout_s:g} s")))
        return None

    async def _run(self, scope: Any, body: bytes, receive: Any, send: Any) -> None:
        started = False
        replayed = False

        async def replay() -> Any:
            nonlocal replayed
            if not replayed:
                replayed = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()  # after the body: the disconnect, when it comes

        async def watched_send(message: Any) -> None:
            nonlocal started
            if message["type"] == "http.response.start":
                started = True
            await send(message)

        try:
            await self.app(scope, replay, watched_send)
        except Exception as exc:
            if _only(exc, ClientDisconnect):
                return
            log.exception("unhandled error serving %s %s", scope.get("method"), scope.get("path"))
            if not started:
                await self._answer(send, 500, error_body(INTERNAL_ERROR, f"internal error: {type(exc).__name__}"))

    def _too_large(self) -> bytes:
        return error_body(INVALID_REQUEST, f"request body over the server's limit of {self.max_body_bytes} bytes")

    async def _drain(self, receive: Any, deadline: float) -> None:
        """Read and drop what is left of a refused request's body (at most twice the body limit, until the
        deadline), so the refusal is read by the client: closing a socket with unread data resets it."""
        left = 2 * self.max_body_bytes
        with anyio.move_on_after(max(0.0, deadline - anyio.current_time())):
            while left > 0:
                message = await receive()
                if message["type"] != "http.request" or not message.get("more_body", False):
                    return
                left -= len(message.get("body", b""))

    @staticmethod
    async def _answer(send: Any, status: int, body: bytes, extra: list[tuple[bytes, bytes]] | None = None) -> None:
        headers = [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode()),
                   (b"connection", b"close"), *(extra or [])]
        await send({"type": "http.response.start", "status": status, "headers": headers})
        await send({"type": "http.response.body", "body": body, "more_body": False})
