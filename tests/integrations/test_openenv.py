"""`hcgym serve --openenv` driven by OpenEnv's own clients (openenv 0.10, in .venv-openenv: it cannot
share this venv, whose mcp 2.x its fastmcp refuses). One server for the module, started through the
CLI with a token; tests/integrations/openenv_client.py runs every scenario against it with
`HealthcareGymClient` (OpenEnv's `EnvClient`), `MCPToolClient` (/mcp) and `GenericEnvClient`, and
this module checks the report: concurrent WebSocket episodes score as in process, the MCP tool
client lists the env's schemas verbatim and plays the same episode to the same score, sessions are
isolated, the session bound answers "busy", malformed messages get clear errors and the server
keeps serving, the token is required, the task API matches the registry, idle sessions are closed."""

from __future__ import annotations

import json
import os
import secrets
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from envs.env import HealthcareGymEnv
from envs.registry import get_splits, get_tasks
from envs.serve import openenv_launch
from envs.serve.settings import LoopbackOnly
from envs.validate import gold_answer_text

ROOT = Path(__file__).resolve().parents[2]
OPENENV_PYTHON = ROOT / ".venv-openenv" / "bin" / "python"
CLIENT = Path(__file__).with_name("openenv_client.py")
DOMAINS = ("drug_interaction", "ehr_management")
MAX_SESSIONS = 6
IDLE_TIMEOUT_S = 8.0
# OpenEnv's reaper looks every max(timeout / 4, 5) s, so an idle session is closed within timeout + 5 s.
IDLE_WAIT_S = IDLE_TIMEOUT_S + 6.0
MAX_REQUEST_BYTES = 1_000_000
EPISODE_TOOLS = ("start_episode", "finish_episode", "episode_result")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _gold(task) -> list[list]:
    submit = {"answer": gold_answer_text(task) or "",
              "reasoning": str(task.metadata.get("gold_reasoning") or "gold replay")}
    return [[a.name, dict(a.arguments)] for a in task.evaluation_criteria.actions] + [["submit_answer", submit]]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """Start the server, play the in-process reference while it starts, run the client script once."""
    if not OPENENV_PYTHON.is_file():
        pytest.fail(f"{OPENENV_PYTHON} is missing: run `make openenv` (OpenEnv needs its own venv)")
    token, port = secrets.token_hex(16), _free_port()
    url = f"http://127.0.0.1:{port}"
    env = {**os.environ, "HCGYM_SERVE_TOKEN": token, "HCGYM_EMBEDDINGS": "0"}
    env.pop(openenv_launch.PYTHON_ENV, None)
    log_path = tmp_path_factory.mktemp("openenv") / "server.log"
    log = open(log_path, "w")
    server = subprocess.Popen(
        [sys.executable, "-m", "envs.cli", "serve", "--openenv", "--port", str(port), "--max-episodes",
         str(MAX_SESSIONS), "--idle-timeout", str(IDLE_TIMEOUT_S), "--no-warmup",
         *(a for d in DOMAINS for a in ("--domain", d))],
        cwd=ROOT, env=env, stdout=log, stderr=subprocess.STDOUT)
    spec = {"url": url, "token": token, "max_sessions": MAX_SESSIONS, "idle_wait_s": IDLE_WAIT_S,
            "max_request_bytes": MAX_REQUEST_BYTES}
    client = None
    try:
        with pytest.MonkeyPatch.context() as mp:
            mp.setenv("HCGYM_EMBEDDINGS", "0")
            local = HealthcareGymEnv(domain="drug_interaction", split="test", max_turns=40)
            task = next(t for t in local.tasks if t.evaluation_criteria.actions)
            spec.update(task_id=task.id, calls=_gold(task))
            # the client starts beside the server (it waits for /health), so their imports overlap
            spec_path = log_path.with_name("spec.json")
            spec_path.write_text(json.dumps(spec))
            client = subprocess.Popen([str(OPENENV_PYTHON), str(CLIENT), str(spec_path)], stdout=subprocess.PIPE,
                                      stderr=subprocess.PIPE, text=True, cwd=ROOT, env=env)
            local.reset(seed=0, options={"task_id": task.id})
            for name, args in spec["calls"]:
                if local.call_tool(name, args, message="").done:
                    break
        try:
            out, err = client.communicate(timeout=300)
        except subprocess.TimeoutExpired:
            client.kill()
            out, err = client.communicate()
        assert server.poll() is None, f"the OpenEnv server exited:\n{log_path.read_text()}"
        assert client.returncode == 0, f"the client script failed:\n{err[-4000:]}\nserver:\n{log_path.read_text()[-2000:]}"
        report = json.loads(out.strip().splitlines()[-1])
        print(f"openenv: server answered after {report['waited_for_server_s']} s, scenarios took {report['scenarios_s']} s")
        yield {"report": report, "local": local.end, "task": task}
    finally:
        if client is not None and client.poll() is None:
            client.kill()
            client.wait()
        server.terminate()
        try:
            server.wait(timeout=15)
        except subprocess.TimeoutExpired:
            server.kill()
            server.wait()
        log.close()


def test_concurrent_websocket_episodes_score_as_in_process(run):
    local, sessions = run["local"], run["report"]["ws_gold"]
    assert local is not None and local.reason == "answer"
    assert len(sessions) == 4 and len({s["episode_id"] for s in sessions}) == 4
    for s in sessions:
        assert s["task_id"] == run["task"].id and not any(s["not_done_before_last"])
        assert s["end"] == {"done": True, "reward": local.reward, "components": local.reward_components,
                            "reason": "answer"}
        assert s["state_reward"] == local.reward
        # nothing runs after the end, and finishing again answers the same score
        assert s["after_end"][:2] == [True, local.reward] and "the episode is over (answer)" in s["after_end"][2]
        assert s["finish_again"] == s["end"]
    assert set(local.reward_components) >= {"accuracy", "process", "safety", "format", "coherence", "total"}


def test_mcp_tool_client_lists_the_env_schemas_and_plays_to_the_same_score(run):
    local = run["local"]
    schemas = HealthcareGymEnv(domain="drug_interaction").tool_schemas
    for episode in run["report"]["mcp_gold"]:
        tools = episode["tools"]
        assert [t["name"] for t in tools] == [*EPISODE_TOOLS, *(s["function"]["name"] for s in schemas)]
        listed = {t["name"]: t for t in tools}
        for s in schemas:
            assert listed[s["function"]["name"]]["input_schema"] == s["function"]["parameters"]
            assert listed[s["function"]["name"]]["description"] == s["function"]["description"]
        assert episode["errors"] == [None] * len(episode["errors"])
        assert episode["done"] == [False] * (len(episode["done"]) - 1) + [True]
        assert episode["reward"] == local.reward and episode["components"] == local.reward_components


def test_a_client_speaking_only_mcp_json_rpc_plays_an_episode(run):
    only = run["report"]["mcp_only"]
    assert only["started"]["result"]["task_id"] == run["task"].id and only["started"]["result"]["prompt"]["ticket"]
    finished = only["finished"]
    assert finished["done"] is True and finished["metadata"]["score"]["reason"] == "token_limit"
    assert isinstance(finished["reward"], float) and finished["metadata"]["reward_components"]["total"] == finished["reward"]
    assert only["result"]["done"] is True and only["result"]["result"]["score"] == finished["metadata"]["score"]
    assert only["closed"]["closed"] is True
    assert only["stateless_tools"][:3] == list(EPISODE_TOOLS) and "lookup_drug" in only["stateless_tools"]


def test_a_write_in_one_session_is_never_seen_in_another(run):
    iso = run["report"]["isolation"]
    assert iso["stop_ok"] is True, iso["stop_result"]
    assert iso["writer"]["EHR-001-MED-1"] == "discontinued"
    assert iso["mcp_reader"]["EHR-001-MED-1"] == "active"
    assert iso["generic_reader"]["EHR-001-MED-1"] == "active"


def test_the_session_bound_answers_busy(run):
    busy = run["report"]["busy"]
    # the idle-timeout scenario holds one session the whole time
    assert busy["opened"] == MAX_SESSIONS - 1
    assert f"busy: {MAX_SESSIONS} sessions are open" in busy["refusal"] and "CAPACITY_REACHED" in busy["refusal"]
    assert "busy:" in busy["mcp_refusal"]
    assert busy["again"]  # a closed session frees its slot


def test_malformed_messages_get_clear_errors_and_the_server_keeps_serving(run):
    bad = run["report"]["malformed"]
    assert bad["not_json"]["data"]["code"] == "INVALID_JSON"
    assert bad["unknown_type"]["data"]["code"] == "UNKNOWN_TYPE"
    assert bad["step_missing_tool_name"]["data"]["code"] == "VALIDATION_ERROR"
    assert "argument 'bogus'" in bad["reset_unknown_argument"]["data"]["message"]
    assert "no-such-task" in bad["reset_unknown_task"]["data"]["message"]
    assert "argument 'index'" in bad["reset_bad_index"]["data"]["message"]
    assert "argument 'seed'" in bad["reset_negative_seed"]["data"]["message"]
    long_id = bad["reset_long_task_id"]["data"]["message"]
    assert "argument 'task_id'" in long_id and len(long_id) < 500  # refused by size, not echoed
    observation = {k: bad[k]["data"]["observation"] for k in (
        "step_before_reset", "unknown_tool", "long_tool_name", "bad_arguments", "huge_arguments", "bad_message_meta",
        "finish_bad_reason", "still_ok")}
    assert "reset first" in observation["step_before_reset"]["error"]["message"]
    assert observation["unknown_tool"]["error"]["error_type"] == "tool_not_found"
    assert "no_such_tool" in observation["unknown_tool"]["error"]["message"]
    assert "over 128" in observation["long_tool_name"]["error"]["message"]
    assert len(observation["long_tool_name"]["tool_name"]) < 100
    assert observation["bad_arguments"]["error"]["error_type"] == "invalid_args"
    assert "nonsense" in observation["bad_arguments"]["error"]["message"]
    assert "over the server's limit" in observation["huge_arguments"]["error"]["message"]
    assert "hcgym/message" in observation["bad_message_meta"]["error"]["message"]
    assert "argument 'reason'" in observation["finish_bad_reason"]["error"]["message"]
    assert observation["still_ok"]["error"] is None and observation["still_ok"]["result"] == "Thought recorded."
    assert bad["reset_ok"]["type"] == "observation"
    assert bad["oversized_frame"] == 1009
    assert bad["mcp_not_json"]["error"]["code"] == -32700
    assert bad["mcp_oversized"][0] == 413 and "limit" in bad["mcp_oversized"][1]
    assert bad["health_after"] == {"status": "healthy"}


def test_a_token_is_required(run):
    access = run["report"]["access"]
    assert access["http_none"][0] == 401 and "Bearer" in access["http_none"][1]
    assert access["http_wrong"][0] == 401 and access["mcp_none"] == 401
    assert access["health_none"] == 200  # liveness only
    assert "401" in access["ws_none"]
    assert "401" in access["client_wrong"]


def test_the_task_api_is_the_registry(run):
    api = run["report"]["task_api"]
    expected = [(d, t.id) for d in DOMAINS for t in get_tasks(d, "test")]
    assert [s["name"] for s in api["splits"]] == list(dict.fromkeys(s for d in DOMAINS for s in get_splits(d)))
    assert api["num_tasks"] == {"num_tasks": len(expected)}
    assert (api["task"]["task"]["domain"], api["task"]["task"]["id"]) == expected[3]
    assert api["task"]["task"]["ticket"]
    assert api["out_of_range"] == 400
    assert tuple(api["reset_by_index"]) == expected[3]


def test_an_idle_session_is_closed(run):
    after = run["report"]["after_idle"]
    assert "session is closed" in after and "idle" in after, after


def test_serve_openenv_says_how_to_get_openenv(monkeypatch, tmp_path):
    monkeypatch.delenv(openenv_launch.PYTHON_ENV, raising=False)
    monkeypatch.setattr(openenv_launch, "PROJECT_ROOT", tmp_path)
    with pytest.raises(RuntimeError, match="make openenv"):
        openenv_launch.openenv_python()
    monkeypatch.setenv(openenv_launch.PYTHON_ENV, str(tmp_path / "nope"))
    with pytest.raises(RuntimeError, match=openenv_launch.PYTHON_ENV):
        openenv_launch.openenv_python()


def test_serving_beyond_loopback_needs_a_token(monkeypatch):
    import argparse

    from envs.serve.cli import register

    monkeypatch.delenv("HCGYM_SERVE_TOKEN", raising=False)
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    args = parser.parse_args(["serve", "--openenv", "--host", "0.0.0.0"])
    with pytest.raises(ValueError, match="not a loopback address: a --token"):
        args.func(args)


def test_without_a_token_only_loopback_connections_are_served():
    import asyncio

    async def app(scope, receive, send):
        await send({"type": "http.response.start", "status": 200, "headers": []})
        await send({"type": "http.response.body", "body": b"ok"})

    async def hit(local_address):
        sent = []

        async def receive():
            return {"type": "http.request", "body": b"", "more_body": False}

        async def send(message):
            sent.append(message)
        await LoopbackOnly(app)({"type": "http", "server": local_address, "headers": []}, receive, send)
        return sent[0]["status"], b"".join(m.get("body", b"") for m in sent[1:])

    assert asyncio.run(hit(("127.0.0.1", 8000))) == (200, b"ok")
    status, body = asyncio.run(hit(("10.1.2.3", 8000)))
    assert status == 403 and b"HCGYM_SERVE_TOKEN" in body


def test_the_servers_requirements_are_the_declared_bounds():
    """make openenv and the image install server/requirements.txt: each line is the bound pyproject.toml
    declares for that package (a dependency, or the openenv extra), so the venvs cannot drift apart."""
    import re
    import tomllib

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    declared = {}
    for requirement in [*project["dependencies"], *project["optional-dependencies"]["openenv"]]:
        name = re.match(r"[A-Za-z0-9_.\-]+", requirement).group(0).lower()
        declared[name] = requirement.replace(" ", "")
    lines = [line.split("#")[0].strip() for line in
             (ROOT / "envs/integrations/openenv/server/requirements.txt").read_text().splitlines()]
    wanted = [line.replace(" ", "") for line in lines if line]
    assert wanted and "openenv==0.10.0" in wanted
    for requirement in wanted:
        name = re.match(r"[A-Za-z0-9_.\-]+", requirement).group(0).lower()
        assert declared.get(name) == requirement, (requirement, declared.get(name))
