"""`hcgym serve`: the environment as a server other agents and trainers reach."""

from __future__ import annotations

import argparse
import os


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("serve", help="serve the environment (--mcp: MCP over streamable HTTP; --openenv: OpenEnv)")
    p.add_argument("--mcp", action="store_true", help="serve MCP (streamable HTTP at /mcp)")
    p.add_argument("--openenv", action="store_true",
                   help="serve OpenEnv (WebSocket sessions at /ws, MCP tools at /mcp, the task API); runs in the "
                        "venv `make openenv` builds (.venv-openenv) or $HCGYM_OPENENV_PYTHON")
    p.add_argument("--host", default="127.0.0.1", help="bind address (default loopback; others need --token)")
    p.add_argument("--port", type=int, default=8765)
    p.add_argument("--domain", action="append", dest="domains", metavar="DOMAIN",
                   help="a domain to serve (repeat for several; the first is the default)")
    p.add_argument("--split", default="test", help="split start_episode draws from by default")
    p.add_argument("--max-episodes", type=int, default=64, help="episodes running at once (more: busy)")
    p.add_argument("--idle-timeout", type=float, default=600.0, help="seconds before an idle episode is dropped")
    p.add_argument("--max-turns", type=int, default=40)
    p.add_argument("--max-tool-calls", type=int, default=None)
    p.add_argument("--max-tool-result-chars", type=int, default=50_000)
    p.add_argument("--max-argument-chars", type=int, default=100_000)
    p.add_argument("--max-requests", type=int, default=128, help="HTTP requests served at once (more: 503 busy)")
    p.add_argument("--max-connections", type=int, default=1024, help="open connections (a request on more: 503)")
    p.add_argument("--request-timeout", type=float, default=10.0,
                   help="seconds a request's headers, then its body, may take to arrive (slower: 408, closed)")
    p.add_argument("--max-sessions", type=int, default=256, help="MCP legacy-protocol sessions open at once")
    p.add_argument("--max-finished", type=int, default=1024, help="ended episodes whose score is kept")
    p.add_argument("--token", default=None, help="bearer token clients must send (default $HCGYM_SERVE_TOKEN)")
    p.add_argument("--no-warmup", action="store_true", help="skip loading graders before serving")
    p.set_defaults(func=cmd_serve)


def cmd_serve(args: argparse.Namespace) -> int:
    if args.mcp == args.openenv:
        raise ValueError("choose one protocol: --mcp (MCP over streamable HTTP) or --openenv (OpenEnv: WebSocket "
                         "sessions at /ws, MCP tools at /mcp)")
    from pydantic import ValidationError

    from envs.serve.settings import ServeSettings

    fields = dict(host=args.host, port=args.port, split=args.split, max_episodes=args.max_episodes,
                  idle_timeout_s=args.idle_timeout, max_turns=args.max_turns, max_tool_calls=args.max_tool_calls,
                  max_tool_result_chars=args.max_tool_result_chars, max_argument_chars=args.max_argument_chars,
                  max_requests=args.max_requests, max_connections=args.max_connections,
                  request_timeout_s=args.request_timeout, max_sessions=args.max_sessions,
                  max_finished=args.max_finished,
                  token=args.token or os.environ.get("HCGYM_SERVE_TOKEN") or None)
    if args.domains:
        fields["domains"] = args.domains
    try:
        settings = ServeSettings(**fields)
    except ValidationError as exc:
        raise ValueError("; ".join(f"{'.'.join(map(str, e['loc'])) or 'settings'}: {e['msg']}"
                                   for e in exc.errors())) from None
    if args.openenv:
        from envs.serve.openenv_launch import launch

        launch(settings, warmup=not args.no_warmup)  # this process becomes the server
        return 0
    from envs.serve.mcp_server import serve

    serve(settings, warmup=not args.no_warmup)
    return 0
