"""`hcgym view RUN_DIR [RUN_DIR ...]`: serve the viewer on 127.0.0.1 until interrupted."""

from __future__ import annotations

import argparse


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "view", help="a local web page over training runs and evaluation folders",
        description="Serve a read-only page on 127.0.0.1 over the named folders: training runs (hcgym train's "
                    "output_dir) and evaluation results (hcgym eval's --output), or folders that hold them.")
    parser.add_argument("folders", nargs="+", help="run or evaluation folders (or folders containing them)")
    parser.add_argument("--port", type=int, default=8765, help="port on 127.0.0.1 (0: any free port; default 8765)")
    parser.set_defaults(func=run_command)


def run_command(args: argparse.Namespace) -> int:
    from viewer.data import discover
    from viewer.server import ViewerServer

    if not 0 <= args.port <= 65535:
        raise ValueError(f"--port {args.port}: expected 0-65535")
    sources = discover(args.folders)
    server = ViewerServer(sources, port=args.port)
    kinds = ", ".join(f"{s.path.name} ({s.kind})" for s in sources)
    print(f"hcgym view: serving {kinds}\nhcgym view: open {server.url}  (Ctrl-C to stop)", flush=True)
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        server.httpd.server_close()
    return 0
