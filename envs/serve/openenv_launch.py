"""`hcgym serve --openenv`: start the OpenEnv server in an interpreter that has openenv.

openenv 0.10 cannot share a venv with the MCP server's SDK (its fastmcp needs mcp < 2; the `mcp`
extra is mcp 2.x), so the main venv has no openenv. The settings are checked here, then this
process becomes the server (exec) in the first interpreter that has openenv: $HCGYM_OPENENV_PYTHON,
this one, or the project's `.venv-openenv` (`make openenv`). The server is started by module name,
so this package never imports the OpenEnv integration.
"""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path

from envs.serve.settings import TOKEN_ENV, ServeSettings

PYTHON_ENV = "HCGYM_OPENENV_PYTHON"
SERVER_MODULE = "envs.integrations.openenv.server.app"
PROJECT_ROOT = Path(__file__).resolve().parents[2]


def openenv_python() -> str:
    """The interpreter to run the OpenEnv server in; a RuntimeError saying how to get one if none has it."""
    chosen = os.environ.get(PYTHON_ENV)
    if chosen:
        if not Path(chosen).is_file():
            raise RuntimeError(f"{PYTHON_ENV}={chosen!r} is not a file")
        return chosen
    if importlib.util.find_spec("openenv") is not None:
        return sys.executable
    venv = PROJECT_ROOT / ".venv-openenv" / "bin" / "python"
    if venv.is_file():
        return str(venv)
    raise RuntimeError(
        "openenv is not installed in this interpreter (the main venv cannot have it: openenv 0.10's fastmcp "
        "needs mcp < 2, the mcp extra is mcp 2.x). Run `make openenv` (builds .venv-openenv, which "
        f"`hcgym serve --openenv` then uses), or install healthcare-ai-gym[openenv] in a venv without the "
        f"mcp extra and point {PYTHON_ENV} at its python")


def launch(settings: ServeSettings, warmup: bool = True) -> None:
    """Become the OpenEnv server (never returns)."""
    python = openenv_python()
    argv = [python, "-m", SERVER_MODULE, "--settings-json", settings.model_dump_json(exclude={"token"})]
    if not warmup:
        argv.append("--no-warmup")
    env = dict(os.environ)
    env.pop(TOKEN_ENV, None)
    if settings.token:  # the token travels in the environment, never in argv (ps shows argv)
        env[TOKEN_ENV] = settings.token
    sys.stdout.flush()
    sys.stderr.flush()
    os.execve(python, argv, env)
