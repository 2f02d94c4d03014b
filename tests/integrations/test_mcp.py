"""`hcgym serve --mcp` driven by the official MCP SDK client (`mcp.Client`) against a real uvicorn on
127.0.0.1: the tool listing is the env's schemas verbatim plus the episode tools, a gold episode
scores over MCP exactly as in process (on the 2026-07-28 protocol, episode named in `_meta`, and on
the legacy protocol, episode found by the session header), concurrent episodes are isolated, a
malformed call gets a tool error naming the argument and the server keeps serving, the episode bound
answers "busy", idle episodes are dropped, and a token is required when one is set."""

from __future__ import annotations

import asyncio
import json
import socket
import threading
import time

import httpx2
import pytest
import uvicorn
from mcp import Client
from mcp.client.streamable_http import streamable_http_client

from envs.env import HealthcareGymEnv
from envs.serve.mcp_server import EPISODE_META_KEY, EPISODE_TOOLS, ServeSettings, build_app
from envs.validate import gold_answer_text


@pytest.fixture(autouse=True)
def _no_embeddings(monkeypatch):
    monkeypatch.setenv("HCGYM_EMBEDDINGS", "0")


class Running:
    def __init__(self, settings: ServeSettings) -> None:
        self.app, self.store = build_app(settings)
        sock = socket.socket()
        sock.bind(("127.0.0.1", 0))
        self.url = f"http://127.0.0.1:{sock.getsockname()[1]}/mcp"
        self.server = uvicorn.Server(uvicorn.Config(self.app, log_level="warning"))
        self.thread = threading.Thread(target=self.server.run, kwargs={"sockets": [sock]}, daemon=True)
        self.thread.start()
        deadline = time.monotonic() + 20
        while not self.server.started:
            assert time.monotonic() < deadline and self.thread.is_alive(), "the MCP server did not start"
            time.sleep(0.02)

    def stop(self) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=10)


def serving(**kw):
    running = Running(ServeSettings(**kw))
    try:
        yield running
    finally:
        running.stop()


@pytest.fixture(scope="module")
def srv():
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("HCGYM_EMBEDDINGS", "0")
        yield from serving(domains=["drug_interaction", "ehr_management"], max_episodes=8)


def run(coro):
    return asyncio.run(coro)


def gold_calls(task) -> list[tuple[str, dict]]:
    submit = {"answer": gold_answer_text(task) or "",
              "reasoning": str(task.metadata.get("gold_reasoning") or "gold replay")}
    return [(a.name, dict(a.arguments)) for a in task.evaluation_criteria.actions] + [("submit_answer", submit)]


def test_tools_are_the_env_schemas_verbatim_plus_the_episode_tools(srv):
    async def go():
        async with Client(srv.url) as c:
            default = (await c.list_tools()).tools
            started = await c.call_tool("start_episode", {"domain": "ehr_management"})
            eid = started.structured_content["episode_id"]
            ehr = (await c.list_tools(meta={EPISODE_META_KEY: eid})).tools
            await c.call_tool("finish_episode", {"episode_id": eid, "reason": "token_limit"})
            return default, ehr, started
    default, ehr, started = run(go())
    for tools, domain in ((default, "drug_interaction"), (ehr, "ehr_management")):
        schemas = HealthcareGymEnv(domain=domain).tool_schemas
        assert [t.name for t in tools] == [*EPISODE_TOOLS, *(s["function"]["name"] for s in schemas)]
        listed = {t.name: t for t in tools}
        for s in schemas:
            assert listed[s["function"]["name"]].input_schema == s["function"]["parameters"]
            assert listed[s["function"]["name"]].description == s["function"]["description"]
    prompt = started.structured_content["prompt"]
    assert prompt["ticket"] and prompt["system"] and prompt["tools"] == HealthcareGymEnv(domain="ehr_management").tool_schemas


@pytest.mark.parametrize("mode", ["auto", "legacy"])
def test_a_gold_episode_over_mcp_scores_as_in_process(srv, mode):
    env = HealthcareGymEnv(domain="drug_interaction", split="test", max_turns=40)
    task = next(t for t in env.tasks if t.evaluation_criteria.actions)
    calls = gold_calls(task)
    env.reset(seed=0, options={"task_id": task.id})
    for name, args in calls:
        if env.call_tool(name, args, message="").done:
            break
    local = env.end
    assert local is not None and local.reason == "answer"

    async def go():
        async with Client(srv.url, mode=mode) as c:
            started = await c.call_tool("start_episode", {"task_id": task.id, "seed": 0})
            eid = started.structured_content["episode_id"]
            # 2026-07-28 requests carry no session: the episode is named in _meta; the legacy protocol's
            # session header finds the episode that session started
            meta = {EPISODE_META_KEY: eid} if mode == "auto" else None
            results = [await c.call_tool(name, args, meta=meta) for name, args in calls]
            again = await c.call_tool("finish_episode", {"episode_id": eid})
            return c.protocol_version, started, results, again
    version, started, results, again = run(go())
    assert (version == "2026-07-28") == (mode == "auto")
    assert started.structured_content["task_id"] == task.id
    assert all(not r.is_error for r in results), [r.content[0].text for r in results if r.is_error]
    last = results[-1].structured_content
    assert last["done"] and all(not r.structured_content["done"] for r in results[:-1])
    score = last["score"]
    assert score["reason"] == "answer" and score["reward"] == local.reward
    assert score["reward_components"] == local.reward_components
    assert set(score["reward_components"]) >= {"accuracy", "process", "safety", "format", "coherence", "total"}
    assert again.structured_content["score"] == score  # finish is idempotent: the same score


def test_concurrent_episodes_are_isolated(srv):
    def meds(result) -> dict[str, str]:
        return {o["order_id"]: o["status"] for o in json.loads(result.content[0].text)["medication_orders"]}

    async def episode(c, write: bool):
        started = await c.call_tool("start_episode", {"domain": "ehr_management", "seed": 1})
        meta = {EPISODE_META_KEY: started.structured_content["episode_id"]}
        if write:
            stop = await c.call_tool("discontinue_order", {"patient_id": "EHR-001", "order_id": "EHR-001-MED-1",
                                                           "reason": "isolation check"}, meta=meta)
            assert not stop.is_error, stop.content[0].text
        else:
            await asyncio.sleep(0.3)  # read after the other episode wrote
        seen = await c.call_tool("get_medication_orders", {"patient_id": "EHR-001"}, meta=meta)
        await c.call_tool("finish_episode", {"reason": "token_limit"}, meta=meta)
        return meds(seen)

    async def go():
        async with Client(srv.url) as a, Client(srv.url, mode="legacy") as b:
            return await asyncio.gather(episode(a, True), episode(b, False))
    wrote, other = run(go())
    assert wrote["EHR-001-MED-1"] == "discontinued"
    assert other["EHR-001-MED-1"] == "active"


def test_malformed_calls_get_a_clear_error_and_the_server_keeps_serving(srv):
    async def go():
        async with Client(srv.url) as c:
            out = {
                "domain": await c.call_tool("start_episode", {"domain": 3}),
                "task": await c.call_tool("start_episode", {"task_id": "no-such-task"}),
                "extra": await c.call_tool("start_episode", {"bogus": 1}),
                "no_episode": await c.call_tool("lookup_drug", {"name": "warfarin"}),
                "unknown_episode": await c.call_tool("lookup_drug", {"name": "x", "episode_id": "nope"}),
                "reason": await c.call_tool("finish_episode", {"episode_id": "nope", "reason": 5}),
            }
            eid = (await c.call_tool("start_episode", {})).structured_content["episode_id"]
            meta = {EPISODE_META_KEY: eid}
            out["unknown_tool"] = await c.call_tool("no_such_tool", {}, meta=meta)
            out["bad_args"] = await c.call_tool("think", {"nonsense": [1]}, meta=meta)
            out["huge"] = await c.call_tool("think", {"thought": "x" * 200_000}, meta=meta)
            out["meta_type"] = await c.call_tool("think", {"thought": "t"}, meta={EPISODE_META_KEY: 7})
            out["still_ok"] = await c.call_tool("think", {"thought": "still here"}, meta=meta)
            await c.call_tool("finish_episode", {"reason": "token_limit"}, meta=meta)
            return out
    out = run(go())
    text = {k: r.content[0].text for k, r in out.items()}
    assert all(out[k].is_error for k in out if k != "still_ok"), text
    assert "argument 'domain'" in text["domain"]
    assert "argument 'task_id'" in text["task"] and "no-such-task" in text["task"]
    assert "argument 'bogus'" in text["extra"]
    assert "start_episode" in text["no_episode"] and EPISODE_META_KEY in text["no_episode"]
    assert "argument 'episode_id'" in text["unknown_episode"] and "nope" in text["unknown_episode"]
    assert "argument 'reason'" in text["reason"]
    assert "no_such_tool" in text["unknown_tool"]
    assert "nonsense" in text["bad_args"]
    assert "over the server's limit" in text["huge"]
    assert EPISODE_META_KEY in text["meta_type"]
    assert not out["still_ok"].is_error
    # a body that is not JSON at all: a JSON-RPC parse error, and the server still answers
    raw = httpx2.post(srv.url, content=b"{not json", headers={
        "content-type": "application/json", "accept": "application/json, text/event-stream",
        "mcp-protocol-version": "2026-07-28"})
    assert raw.status_code in (200, 400) and "Parse error" in raw.text

    async def still():
        async with Client(srv.url) as c:
            return await c.list_tools()
    assert run(still()).tools


def test_the_episode_bound_answers_busy_and_idle_episodes_are_dropped(monkeypatch):
    monkeypatch.setenv("HCGYM_EMBEDDINGS", "0")
    for srv in serving(domains=["drug_interaction"], max_episodes=2, idle_timeout_s=1.0):
        async def go():
            async with Client(srv.url) as c:
                first = (await c.call_tool("start_episode", {})).structured_content["episode_id"]
                second = (await c.call_tool("start_episode", {})).structured_content["episode_id"]
                busy = await c.call_tool("start_episode", {})
                await c.call_tool("finish_episode", {"episode_id": second, "reason": "token_limit"})
                freed = await c.call_tool("start_episode", {})  # an ended episode frees its slot
                await asyncio.sleep(1.2)
                expired = await c.call_tool("think", {"thought": "t"}, meta={EPISODE_META_KEY: first})
                after = await c.call_tool("start_episode", {})
                return busy, freed, expired, after
        busy, freed, expired, after = run(go())
        assert busy.is_error and busy.content[0].text.startswith("busy:") and "2 episodes" in busy.content[0].text
        assert not freed.is_error
        assert expired.is_error and "expired" in expired.content[0].text
        assert not after.is_error and srv.store.running() == 1


def test_a_token_is_required_off_loopback_and_enforced_when_set(monkeypatch):
    monkeypatch.setenv("HCGYM_EMBEDDINGS", "0")
    with pytest.raises(ValueError, match="token"):
        ServeSettings(host="0.0.0.0")
    assert ServeSettings(host="0.0.0.0", token="s3cret").token == "s3cret"
    for srv in serving(domains=["drug_interaction"], token="s3cret"):
        denied = httpx2.post(srv.url, json={"jsonrpc": "2.0", "id": 1, "method": "tools/list"},
                             headers={"accept": "application/json, text/event-stream"})
        assert denied.status_code == 401

        async def go():
            http = httpx2.AsyncClient(headers={"Authorization": "Bearer s3cret"})
            async with http, Client(streamable_http_client(srv.url, http_client=http)) as c:
                return await c.list_tools()
        assert run(go()).tools
