"""vLLM's OpenAI-compatible server (its CPU build in .venv-vllm) on a tiny model, for the tests that
drive a real endpoint (evaluation's OpenAI policy, verifiers' vf-eval)."""

from __future__ import annotations

import os
import socket
import subprocess
import time
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
VLLM_PYTHON = REPO_ROOT / ".venv-vllm" / "bin" / "python"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextmanager
def openai_server(model_dir: str, served_name: str, max_model_len: int, log_path: Path, *,
                  start_timeout_s: float, extra_args: tuple[str, ...] = (),
                  extra_env: dict[str, str] | None = None) -> Iterator[str]:
    """`http://127.0.0.1:PORT/v1` while the server runs: float32, eager, seeded, Hermes tool calls parsed;
    a server that exits or is not healthy within `start_timeout_s` raises with its log's tail."""
    port = free_port()
    env = dict(os.environ, VLLM_CPU_KVCACHE_SPACE="1", VLLM_CPU_OMP_THREADS_BIND="0", OMP_NUM_THREADS="1",
               VLLM_ENABLE_V1_MULTIPROCESSING="0", VLLM_LOGGING_LEVEL="WARNING", HF_HUB_OFFLINE="1",
               TRANSFORMERS_OFFLINE="1", **(extra_env or {}))
    command = [str(VLLM_PYTHON), "-m", "vllm.entrypoints.openai.api_server", "--model", model_dir,
               "--served-model-name", served_name, "--host", "127.0.0.1", "--port", str(port),
               "--dtype", "float32", "--max-model-len", str(max_model_len), "--enforce-eager",
               "--gpu-memory-utilization", "0.1", "--seed", "0", "--enable-auto-tool-choice",
               "--tool-call-parser", "hermes", "--disable-uvicorn-access-log", *extra_args]
    with open(log_path, "wb") as log:
        process = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT, env=env, cwd=str(REPO_ROOT),
                                   start_new_session=True)
    try:
        deadline = time.monotonic() + start_timeout_s
        while True:
            if process.poll() is not None:
                tail = log_path.read_text(errors="replace")[-4000:]
                raise RuntimeError(f"vLLM server exited with code {process.returncode} while starting:\n{tail}")
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/health", timeout=2) as response:
                    if response.status == 200:
                        break
            except OSError:
                pass
            if time.monotonic() > deadline:
                tail = log_path.read_text(errors="replace")[-4000:]
                raise RuntimeError(f"vLLM server not healthy after {start_timeout_s:g} s:\n{tail}")
            time.sleep(0.5)
        yield f"http://127.0.0.1:{port}/v1"
    finally:
        process.terminate()
        try:
            process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(timeout=30)
