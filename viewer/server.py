"""The viewer's HTTP server: static pages we wrote plus a small read-only JSON API.

Why the standard library's `ThreadingHTTPServer` and hand-written pages (no web framework, no
JavaScript build, no CDN): the install stays as it is, the page loads with no network, and the
API is a dozen GET routes over data that Arrow already filters fast. It binds 127.0.0.1 only:
a run's episodes can hold patient-like text and the page has no login.

API (all GET, JSON):
  /api/sources                               runs and evaluations being served
  /api/run/metrics?source=ID                 metrics.jsonl rows
  /api/run/config?source=ID                  config.yaml text
  /api/episodes?source=ID&<filters>          a page of the episode table (viewer.data.EpisodeQuery)
  /api/run/episode?source=ID&file=N&row=R    one training episode, whole
  /api/eval/summary?source=ID                per-benchmark metrics with 95% CIs (evals.report)
  /api/eval/episode?source=ID&row_id=X       one evaluation episode: its result row and messages
  /api/eval/compare?a=ID&b=ID                paired comparison of two evaluations (evals.compare)

Hostile input gets an answer, never a dropped connection: a bad parameter (a huge number, a NUL
byte, an unknown value) is a 400 naming it, a static name that no file can have is a 400, and any
other exception is a 500 with a short message (the traceback goes to the log). Load is bounded: a
listen backlog of `BACKLOG` (a burst is queued, not reset), at most `max_active` requests worked on
at once (a request that finds no free slot within `busy_wait_s` gets 503 "busy" with Retry-After),
and every connection has a socket timeout (`timeout_s`): a client that sends half a request, or
stops reading the answer, is closed when it runs out.
"""

from __future__ import annotations

import json
import logging
import math
import mimetypes
import threading
from collections.abc import Callable
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any
from urllib.parse import parse_qsl, urlsplit

from viewer.data import EpisodeQuery, EvalSource, RunSource, Source, ViewerError

STATIC = Path(__file__).parent / "static"
LOOPBACK = "127.0.0.1"
#: Listen backlog: connections the kernel queues before accept (Linux caps it at net.core.somaxconn).
BACKLOG = 1024
#: Requests worked on at once; a page asks for a handful, and each holds decoded Arrow data.
MAX_ACTIVE = 8
#: How long a request waits for a free slot before it is answered 503 "busy".
BUSY_WAIT_S = 2.0
#: Socket timeout of a connection: reading the request and writing the answer.
TIMEOUT_S = 15.0
#: Longest static file name served (file systems refuse longer path components).
MAX_NAME = 255
LOG = logging.getLogger("hcgym.viewer")


def _json_safe(value: Any) -> Any:
    """NaN and infinities become null: JSON has no such numbers and browsers refuse them."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    return value


class ViewerApp:
    """Routes requests to the sources; independent of HTTP so it can be called directly."""

    def __init__(self, sources: list[Source]) -> None:
        self.sources = {s.id: s for s in sources}

    def source(self, params: dict[str, str], key: str = "source", kind: type | None = None) -> Source:
        source_id = params.get(key)
        if source_id not in self.sources:
            raise ViewerError(f"unknown {key} {source_id!r}; serving {sorted(self.sources)}")
        source = self.sources[source_id]
        if kind is not None and not isinstance(source, kind):
            raise ViewerError(f"{key} {source_id!r} is a {source.kind}, not a "
                              f"{'run' if kind is RunSource else 'evaluation'}")
        return source

    def routes(self) -> dict[str, Callable[[dict[str, str]], Any]]:
        return {
            "/api/sources": lambda p: [s.describe() for s in self.sources.values()],
            "/api/run/metrics": lambda p: self.source(p, kind=RunSource).metrics(),
            "/api/run/config": lambda p: {"text": self.source(p, kind=RunSource).config_text()},
            "/api/episodes": lambda p: self.source(p).episodes(EpisodeQuery.from_params(p)),
            "/api/run/episode": self._run_episode,
            "/api/eval/summary": lambda p: self.source(p, kind=EvalSource).summary(),
            "/api/eval/episode": lambda p: self.source(p, kind=EvalSource).episode(p.get("row_id", "")),
            "/api/eval/compare": self._compare,
        }

    def _run_episode(self, params: dict[str, str]) -> Any:
        source = self.source(params, kind=RunSource)
        try:
            file, row = int(params.get("file", "")), int(params.get("row", ""))
        except ValueError:
            raise ViewerError(f"file and row must be integers (got file={params.get('file')!r}, "
                              f"row={params.get('row')!r})") from None
        return source.episode(file, row)

    def _compare(self, params: dict[str, str]) -> Any:
        from evals.compare import compare_dirs

        a = self.source(params, "a", EvalSource)
        b = self.source(params, "b", EvalSource)
        comparison, _ = compare_dirs(a.path, b.path, n_resamples=2_000)
        return comparison

    def handle(self, path: str, params: dict[str, str]) -> tuple[int, Any]:
        route = self.routes().get(path)
        if route is None:
            return HTTPStatus.NOT_FOUND, {"error": f"no such API route {path[:80]!r}"}
        for name, value in params.items():
            if "\x00" in name or "\x00" in value:
                return HTTPStatus.BAD_REQUEST, {"error": f"parameter {name[:40]!r} holds a NUL byte"}
        try:
            return HTTPStatus.OK, _json_safe(route(params))
        except ViewerError as exc:
            return HTTPStatus.BAD_REQUEST, {"error": str(exc)}
        except (OSError, ValueError, KeyError) as exc:  # a damaged or half-written file: say which
            return HTTPStatus.INTERNAL_SERVER_ERROR, {"error": f"{type(exc).__name__}: {exc}"}


def make_handler(app: ViewerApp, slots: threading.BoundedSemaphore | None = None, *,
                 timeout_s: float | None = TIMEOUT_S, busy_wait_s: float = BUSY_WAIT_S) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        server_version = "hcgym-view"
        timeout = timeout_s  # StreamRequestHandler sets it on the socket: reads and writes both

        def log_message(self, format: str, *args: Any) -> None:
            pass

        def _send(self, status: int, body: bytes, content_type: str, headers: dict[str, str] | None = None) -> None:
            self.send_response(status)
            for key, value in (headers or {}).items():
                self.send_header(key, value)
            self.send_header("Content-Type", content_type)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.send_header("X-Content-Type-Options", "nosniff")
            self.send_header("Content-Security-Policy", "default-src 'self'; img-src 'self' data:; "
                                                        "style-src 'self' 'unsafe-inline'")
            self.end_headers()
            self.wfile.write(body)

        def _send_json(self, status: int, payload: Any, headers: dict[str, str] | None = None) -> None:
            body = json.dumps(payload, ensure_ascii=False, allow_nan=False).encode("utf-8")
            self._send(status, body, "application/json; charset=utf-8", headers)

        def do_GET(self) -> None:
            if slots is not None and not slots.acquire(timeout=busy_wait_s):
                try:
                    self._send_json(HTTPStatus.SERVICE_UNAVAILABLE,
                                    {"error": "busy: too many requests at once; retry shortly"}, {"Retry-After": "1"})
                except OSError:
                    pass
                self.close_connection = True
                return
            try:
                self._get()
            except (ConnectionError, TimeoutError):
                self.close_connection = True  # the client went away or stopped reading: nobody to answer
            except Exception as exc:  # noqa: BLE001 - any request gets an answer, the log gets the traceback
                LOG.exception("viewer: %s failed", self.path[:200])
                try:
                    self._send_json(HTTPStatus.INTERNAL_SERVER_ERROR,
                                    {"error": f"internal error: {type(exc).__name__}: {str(exc)[:200]}"})
                except OSError:
                    self.close_connection = True
            finally:
                if slots is not None:
                    slots.release()

        def _get(self) -> None:
            if "\x00" in self.path:
                self._send_json(HTTPStatus.BAD_REQUEST, {"error": "the request path holds a NUL byte"})
                return
            url = urlsplit(self.path)
            if url.path.startswith("/api/"):
                params = dict(parse_qsl(url.query, keep_blank_values=True))
                self._send_json(*app.handle(url.path, params))
                return
            name = "index.html" if url.path in ("/", "/index.html") else url.path.removeprefix("/static/")
            if len(name) > MAX_NAME:
                self._send_json(HTTPStatus.BAD_REQUEST, {"error": f"static file name of {len(name)} characters; "
                                                                  f"at most {MAX_NAME}"})
                return
            try:
                target = (STATIC / name).resolve()
                found = STATIC.resolve() in target.parents and target.is_file()
            except OSError:  # a name the file system refuses (too long a component, a loop): no such file
                found = False
            if not found:
                self._send(HTTPStatus.NOT_FOUND, b"not found", "text/plain; charset=utf-8")
                return
            kind = mimetypes.guess_type(target.name)[0] or "application/octet-stream"
            self._send(HTTPStatus.OK, target.read_bytes(),
                       f"{kind}; charset=utf-8" if kind.startswith("text/") or kind.endswith("javascript") else kind)

    return Handler


class _HTTPServer(ThreadingHTTPServer):
    daemon_threads = True
    request_queue_size = BACKLOG  # socketserver's default of 5 resets a burst of connections


class ViewerServer:
    """A running viewer on 127.0.0.1 (port 0 picks a free one); `url` says where.

    `max_active` requests are worked on at once (others wait up to `busy_wait_s`, then get 503);
    `timeout_s` is each connection's socket timeout.
    """

    def __init__(self, sources: list[Source], port: int = 0, *, max_active: int = MAX_ACTIVE,
                 timeout_s: float | None = TIMEOUT_S, busy_wait_s: float = BUSY_WAIT_S) -> None:
        if max_active < 1:
            raise ValueError(f"max_active={max_active}: expected at least 1")
        self.app = ViewerApp(sources)
        self.slots = threading.BoundedSemaphore(max_active)
        self.httpd = _HTTPServer((LOOPBACK, port), make_handler(self.app, self.slots, timeout_s=timeout_s,
                                                                busy_wait_s=busy_wait_s))
        self.thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        host, port = self.httpd.server_address[:2]
        return f"http://{host}:{port}/"

    def start(self) -> ViewerServer:
        self.thread = threading.Thread(target=self.httpd.serve_forever, name="hcgym-view", daemon=True)
        self.thread.start()
        return self

    def serve_forever(self) -> None:
        self.httpd.serve_forever()

    def stop(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()
