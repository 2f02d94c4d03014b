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
"""

from __future__ import annotations

import json
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
            return HTTPStatus.NOT_FOUND, {"error": f"no such API route {path!r}"}
        try:
            return HTTPStatus.OK, _json_safe(route(params))
        except ViewerError as exc:
            return HTTPStatus.BAD_REQUEST, {"error": str(exc)}
        except (OSError, ValueError, KeyError) as exc:  # a damaged or half-written file: say which
            return HTTPStatus.INTERNAL_SERVER_ERROR, {"error": f"{type(exc).__name__}: {exc}"}


def make_handler(app: ViewerApp) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        server_version = "hcgym-view"

        def log_message(self, format: str, *args: Any) -> None:
            pass

        def _send(self, status: int, body: bytes, content_type: str) -> None:
            self.send_response(status)
            self.send_header("Content-Type", content_type)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.send_header("X-Content-Type-Options", "nosniff")
            self.send_header("Content-Security-Policy", "default-src 'self'; img-src 'self' data:; "
                                                        "style-src 'self' 'unsafe-inline'")
            self.end_headers()
            self.wfile.write(body)

        def do_GET(self) -> None:
            url = urlsplit(self.path)
            if url.path.startswith("/api/"):
                params = dict(parse_qsl(url.query, keep_blank_values=True))
                status, payload = app.handle(url.path, params)
                body = json.dumps(payload, ensure_ascii=False, allow_nan=False).encode("utf-8")
                self._send(status, body, "application/json; charset=utf-8")
                return
            name = "index.html" if url.path in ("/", "/index.html") else url.path.removeprefix("/static/")
            target = (STATIC / name).resolve()
            if STATIC.resolve() not in target.parents or not target.is_file():
                self._send(HTTPStatus.NOT_FOUND, b"not found", "text/plain; charset=utf-8")
                return
            kind = mimetypes.guess_type(target.name)[0] or "application/octet-stream"
            self._send(HTTPStatus.OK, target.read_bytes(),
                       f"{kind}; charset=utf-8" if kind.startswith("text/") or kind.endswith("javascript") else kind)

    return Handler


class ViewerServer:
    """A running viewer on 127.0.0.1 (port 0 picks a free one); `url` says where."""

    def __init__(self, sources: list[Source], port: int = 0) -> None:
        self.app = ViewerApp(sources)
        self.httpd = ThreadingHTTPServer((LOOPBACK, port), make_handler(self.app))
        self.httpd.daemon_threads = True
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
