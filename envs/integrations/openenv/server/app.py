"""The OpenEnv server of HealthcareGym: OpenEnv's FastAPI app (`/ws` sessions, `/mcp`, the task API,
`/reset` `/step` `/state` `/schema` `/metadata` `/health`) over `HealthcareGymEnvironment`, with the
limits every `hcgym serve` server has (`envs.serve.settings.ServeSettings`).

- sessions: one environment per WebSocket (or `/mcp` session); at most `max_episodes` open at once,
  one more is refused with an error starting "busy:" (code CAPACITY_REACHED);
- a session idle for `idle_timeout_s` is closed by OpenEnv's reaper (checked every
  max(timeout / 4, 5) s); its next message answers that it was closed;
- HTTP requests pass the MCP server's guard (`envs.serve.guard.HTTPGuard`: `max_requests` in flight,
  a body over `max_request_bytes` is a 413, a slow one a 408); a WebSocket message over
  `max_request_bytes` closes the socket (1009); a call's arguments over `max_argument_chars` and
  results over `max_tool_result_chars` are the environment's limits;
- loopback by default; off loopback a token is required (`Authorization: Bearer`), for HTTP and the
  WebSocket handshake alike. Without a token, a connection that reached the server over an address
  that is not loopback is refused, however the app was started (`uvicorn --host 0.0.0.0`, a Docker
  port).

Run: `hcgym serve --openenv` (in the venv `make openenv` builds), `python -m
envs.integrations.openenv.server.app --port 8000`, or `uvicorn envs.integrations.openenv.server.app:app`
(settings from `HCGYM_SERVE_DOMAINS` (comma-separated) and `HCGYM_SERVE_TOKEN`). `/health` answers
without the token (liveness probes); every other route needs it when one is set.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
from typing import Any

from envs.serve.guard import H11_MAX_HEAD, HTTPGuard, guarded_protocol
from envs.serve.settings import TOKEN_ENV, ServeSettings, access_guard

BUSY = "busy: {max} sessions are open (the server's --max-episodes); close one or retry later"


def build_app(settings: ServeSettings) -> Any:
    """The ASGI app: OpenEnv's routes over `HealthcareGymEnvironment`, behind the body limit and the
    access rule."""
    from fastapi import FastAPI
    from openenv.core.env_server.exceptions import SessionCapacityError
    from openenv.core.env_server.http_server import HTTPEnvServer
    from openenv.core.env_server.types import ConcurrencyConfig

    from envs.integrations.openenv.environment import HealthcareGymEnvironment
    from envs.integrations.openenv.models import (ENV_NAME, CallToolAction, CallToolObservation, HealthcareGymObservation,
                                                  HealthcareGymState)

    class Server(HTTPEnvServer):
        # OpenEnv's refusal says "Server at capacity"; ours says busy, as the MCP server does.
        async def _create_session(self):  # type: ignore[override]
            try:
                return await super()._create_session()
            except SessionCapacityError as exc:
                raise SessionCapacityError(exc.active_sessions, exc.max_sessions,
                                           BUSY.format(max=exc.max_sessions)) from None

    app = FastAPI(title="HealthcareGym (OpenEnv)", version="1.0.0",
                  description="HealthcareGym's clinical tasks over OpenEnv: WebSocket sessions at /ws, MCP at /mcp.")
    server = Server(functools.partial(HealthcareGymEnvironment, settings), CallToolAction, CallToolObservation,
                    concurrency_config=ConcurrencyConfig(max_concurrent_envs=settings.max_episodes,
                                                         session_timeout=settings.idle_timeout_s),
                    env_name=ENV_NAME, state_cls=HealthcareGymState, reset_observation_cls=HealthcareGymObservation)
    server.register_routes(app, mode=os.environ.get("OPENENV_MODE", "simulation"))
    guarded = access_guard(app, settings.token)

    async def routed(scope: Any, receive: Any, send: Any) -> None:
        # Liveness answers without the token: container health checks and Spaces probe it bare, and
        # it tells nothing but "healthy".
        if scope["type"] == "http" and scope.get("path") == "/health" and scope.get("method") in ("GET", "HEAD"):
            await app(scope, receive, send)
        else:
            await guarded(scope, receive, send)

    # The MCP server's HTTP guard: requests in flight, head and body limits, body deadline, a 500 for
    # an exception no handler caught (WebSockets pass through it).
    outer = HTTPGuard(routed, max_requests=settings.max_requests, request_timeout_s=settings.request_timeout_s,
                      max_body_bytes=settings.max_request_bytes, busy_wait_s=settings.busy_wait_s)
    outer.openenv_server = server  # type: ignore[attr-defined]
    return outer


DOMAINS_ENV = "HCGYM_SERVE_DOMAINS"


def _environment_fields() -> dict[str, Any]:
    """The token from `HCGYM_SERVE_TOKEN` and the domains from `HCGYM_SERVE_DOMAINS` (comma-separated)."""
    fields: dict[str, Any] = {"token": os.environ.get(TOKEN_ENV) or None}
    if os.environ.get(DOMAINS_ENV):
        fields["domains"] = [d.strip() for d in os.environ[DOMAINS_ENV].split(",") if d.strip()]
    return fields


def settings_from_environment() -> ServeSettings:
    """Settings for a launcher that gives none (`uvicorn ...:app`, `openenv serve`): the defaults and
    what the environment variables say."""
    return ServeSettings(**_environment_fields())


def __getattr__(name: str) -> Any:
    # `app` is built on first access, so importing the module (and `main`) builds nothing.
    if name == "app":
        app = build_app(settings_from_environment())
        globals()["app"] = app
        return app
    raise AttributeError(name)


def serve(settings: ServeSettings, warmup: bool = True) -> None:
    import uvicorn

    from envs.env import HealthcareGymEnv

    if warmup:  # the first score of a process loads graders; pay that before the first client
        for domain in settings.domains:
            HealthcareGymEnv(domain=domain, split=None).warmup()
    app = build_app(settings)
    # uvicorn as the MCP server runs it: a first-request deadline and TCP_NODELAY (guarded_protocol),
    # the connection bound; WebSocket frames up to the body limit.
    server = uvicorn.Server(uvicorn.Config(
        app, host=settings.host, port=settings.port, http=guarded_protocol(settings.request_timeout_s),
        limit_concurrency=settings.max_connections, backlog=2048, timeout_keep_alive=5,
        h11_max_incomplete_event_size=H11_MAX_HEAD, ws_max_size=settings.max_request_bytes, log_level="warning"))
    sock = server.config.bind_socket()  # bound here so --port 0 prints the port it got
    sock.listen(server.config.backlog)
    host = f"[{settings.host}]" if ":" in settings.host else settings.host
    print(f"hcgym serve: OpenEnv at http://{host}:{sock.getsockname()[1]} (WebSocket /ws, MCP /mcp) "
          f"domains={','.join(settings.domains)}", flush=True)
    server.run(sockets=[sock])


def main(argv: list[str] | None = None) -> int:
    """`python -m envs.integrations.openenv.server.app`: `--settings-json` (what `hcgym serve --openenv`
    passes) or `--host`, `--port`, `--domain`; the token from `HCGYM_SERVE_TOKEN`, and the domains from
    `HCGYM_SERVE_DOMAINS` where no `--domain` is given."""
    parser = argparse.ArgumentParser(prog="python -m envs.integrations.openenv.server.app")
    parser.add_argument("--settings-json", help="ServeSettings as JSON (the token comes from $HCGYM_SERVE_TOKEN)")
    parser.add_argument("--host", default=None)
    parser.add_argument("--port", type=int, default=None)
    parser.add_argument("--domain", action="append", dest="domains", metavar="DOMAIN")
    parser.add_argument("--no-warmup", action="store_true")
    args = parser.parse_args(argv)
    from pydantic import ValidationError

    fields: dict[str, Any] = _environment_fields()
    given = json.loads(args.settings_json) if args.settings_json else {}
    if not isinstance(given, dict):
        parser.error("--settings-json must be a JSON object")
    fields.update({k: v for k, v in given.items() if k != "token"})
    for key in ("host", "port", "domains"):
        if getattr(args, key) is not None:
            fields[key] = getattr(args, key)
    try:
        settings = ServeSettings(**fields)
    except ValidationError as exc:
        parser.error("; ".join(f"{'.'.join(map(str, e['loc'])) or 'settings'}: {e['msg']}" for e in exc.errors()))
    serve(settings, warmup=not args.no_warmup)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
