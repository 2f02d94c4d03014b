"""Drives a running `hcgym serve --openenv` with OpenEnv's own clients; run in .venv-openenv by
tests/integrations/test_openenv.py, which reads the JSON report this prints and asserts on it.

Input (a JSON file named by the first argument): url, token, idle_wait_s, and the gold episode (task_id, calls). Every scenario
records what the server answered; nothing here decides pass or fail.
"""

from __future__ import annotations

import asyncio
import json
import sys
import time
from typing import Any

import httpx
import websockets
from openenv.core.env_server.mcp_types import CallToolAction
from openenv.core.generic_client import GenericEnvClient
from openenv.core.mcp_client import MCPToolClient

from envs.integrations.openenv.client import HealthcareGymClient

SPEC = json.loads(open(sys.argv[1]).read())
URL, TOKEN = SPEC["url"], SPEC["token"]
AUTH = {"Authorization": f"Bearer {TOKEN}"}
WS_URL = URL.replace("http://", "ws://") + "/ws"


def score(result: Any) -> dict[str, Any]:
    meta = result.observation.metadata if hasattr(result.observation, "metadata") else result.metadata
    return {"done": result.done, "reward": result.reward, "components": (meta or {}).get("reward_components"),
            "reason": ((meta or {}).get("score") or {}).get("reason")}


async def ws_gold_episode() -> dict[str, Any]:
    """A gold episode on a typed WebSocket session."""
    async with HealthcareGymClient(base_url=URL, headers=AUTH) as env:
        first = await env.reset(task_id=SPEC["task_id"], seed=0)
        results = [await env.call_tool(name, args) for name, args in SPEC["calls"]]
        state = await env.state()
        after = await env.call_tool("think", {"thought": "one more"})
        again = await env.finish(final_text="a second answer")
        return {"task_id": first.observation.task_id, "episode_id": state.episode_id,
                "not_done_before_last": [r.done for r in results[:-1]], "end": score(results[-1]),
                "state_reward": state.reward, "ticket": first.observation.prompt.get("ticket"),
                "after_end": [after.done, after.reward, after.observation.error.message if after.observation.error else None],
                "finish_again": score(again)}


async def mcp_gold_episode() -> dict[str, Any]:
    """The same gold episode through OpenEnv's MCP tool client: reset over its WebSocket, tools over /mcp."""
    async with MCPToolClient(base_url=URL, headers=AUTH) as env:
        await env.reset(task_id=SPEC["task_id"], seed=0)
        tools = await env.list_tools()
        outs = [await env.call_tool(name, **args) for name, args in SPEC["calls"]]
        last = outs[-1]
        return {"tools": [{"name": t.name, "description": t.description, "input_schema": t.input_schema}
                          for t in tools],
                "errors": [o.get("error") for o in outs], "done": [o.get("done") for o in outs],
                "reward": last.get("reward"), "components": (last.get("metadata") or {}).get("reward_components")}


async def mcp_only() -> dict[str, Any]:
    """A client that speaks only JSON-RPC to /mcp: a session, start_episode, a cut, the score."""
    async with httpx.AsyncClient(headers=AUTH, timeout=30) as http:
        async def rpc(method: str, params: dict[str, Any]) -> dict[str, Any]:
            body = {"jsonrpc": "2.0", "id": 1, "method": method, "params": params}
            return (await http.post(URL + "/mcp", json=body)).json()

        session = (await rpc("openenv/session/create", {}))["result"]["session_id"]
        call = {"session_id": session}
        started = await rpc("tools/call", {**call, "name": "start_episode", "arguments": {"task_id": SPEC["task_id"]}})
        finished = await rpc("tools/call", {**call, "name": "finish_episode", "arguments": {"reason": "token_limit"}})
        result = await rpc("tools/call", {**call, "name": "episode_result", "arguments": {}})
        closed = await rpc("openenv/session/close", {"session_id": session})
        stateless = await rpc("tools/list", {})
    return {"started": started["result"], "finished": finished["result"], "result": result["result"],
            "closed": closed["result"], "stateless_tools": [t["name"] for t in stateless["result"]["tools"]]}


async def isolation() -> dict[str, Any]:
    """A write in one session (a discontinued order over WebSocket) read from another session (over /mcp)
    and from a third (plain GenericEnvClient, raw dicts)."""
    def orders(text: str) -> dict[str, str]:
        return {o["order_id"]: o["status"] for o in json.loads(text)["medication_orders"]}

    async with HealthcareGymClient(base_url=URL, headers=AUTH) as writer, \
            MCPToolClient(base_url=URL, headers=AUTH) as reader, GenericEnvClient(base_url=URL, headers=AUTH) as raw:
        await writer.reset(domain="ehr_management", seed=1)
        await reader.reset(domain="ehr_management", seed=1)
        await raw.reset(domain="ehr_management", seed=1)
        stop = await writer.call_tool("discontinue_order", {"patient_id": "EHR-001", "order_id": "EHR-001-MED-1",
                                                            "reason": "isolation check"})
        mine = await writer.call_tool("get_medication_orders", {"patient_id": "EHR-001"})
        theirs = await reader.call_tool("get_medication_orders", patient_id="EHR-001")
        third = await raw.step({"type": "call_tool", "tool_name": "get_medication_orders",
                                "arguments": {"patient_id": "EHR-001"}})
        return {"stop_ok": stop.observation.metadata.get("ok"), "stop_result": stop.observation.result,
                "writer": orders(mine.observation.result), "mcp_reader": orders(theirs["result"]),
                "generic_reader": orders(third.observation["result"])}


async def busy() -> dict[str, Any]:
    """Open sessions until the server refuses one; then close one and open again."""
    opened: list[HealthcareGymClient] = []
    refusal = mcp_refusal = None
    try:
        for _ in range(SPEC["max_sessions"] + 1):
            env = HealthcareGymClient(base_url=URL, headers=AUTH)
            try:
                await env.reset(domain="drug_interaction", seed=0)
            except Exception as exc:  # the refusal under test
                refusal = f"{type(exc).__name__}: {exc}"
                await env.close()
                break
            opened.append(env)
        held = len(opened)
        try:
            async with MCPToolClient(base_url=URL, headers=AUTH) as env:
                await env.reset()
        except Exception as exc:
            mcp_refusal = f"{type(exc).__name__}: {exc}"
        await opened.pop().close()
        await asyncio.sleep(0.2)  # the server frees the slot when it sees the close
        async with HealthcareGymClient(base_url=URL, headers=AUTH) as env:
            again = (await env.reset(domain="drug_interaction", seed=0)).observation.task_id
    finally:
        for env in opened:
            await env.close()
    return {"opened": held, "refusal": refusal, "mcp_refusal": mcp_refusal, "again": again}


async def malformed() -> dict[str, Any]:
    """Broken messages on one raw WebSocket; then the same socket still plays; oversized payloads."""
    out: dict[str, Any] = {}
    async with websockets.connect(WS_URL, additional_headers=AUTH, max_size=None) as ws:
        async def ask(message: Any) -> dict[str, Any]:
            await ws.send(message if isinstance(message, str) else json.dumps(message))
            return json.loads(await ws.recv())

        out["not_json"] = await ask("{not json")
        out["unknown_type"] = await ask({"type": "dance"})
        out["step_missing_tool_name"] = await ask({"type": "step", "data": {"type": "call_tool"}})
        out["reset_unknown_argument"] = await ask({"type": "reset", "data": {"bogus": 1}})
        out["reset_unknown_task"] = await ask({"type": "reset", "data": {"task_id": "no-such-task"}})
        out["reset_bad_index"] = await ask({"type": "reset", "data": {"split": "test", "index": 10 ** 9}})
        out["reset_negative_seed"] = await ask({"type": "reset", "data": {"seed": -1}})
        out["reset_long_task_id"] = await ask({"type": "reset", "data": {"task_id": "t" * 50_000}})
        out["step_before_reset"] = await ask({"type": "step", "data": {"type": "call_tool", "tool_name": "think",
                                                                         "arguments": {"thought": "x"}}})
        out["reset_ok"] = await ask({"type": "reset", "data": {"domain": "drug_interaction", "seed": 0}})
        step = {"type": "step", "data": {"type": "call_tool", "tool_name": "no_such_tool", "arguments": {}}}
        out["unknown_tool"] = await ask(step)
        step["data"].update(tool_name="x" * 5_000)
        out["long_tool_name"] = await ask(step)
        step["data"].update(tool_name="think", arguments={"nonsense": [1]})
        out["bad_arguments"] = await ask(step)
        step["data"].update(arguments={"thought": "x" * 200_000})
        out["huge_arguments"] = await ask(step)
        step["data"].update(arguments={"thought": "t"}, metadata={"hcgym/message": 7})
        out["bad_message_meta"] = await ask(step)
        step["data"].update(arguments={"thought": "still here"}, metadata={})
        out["still_ok"] = await ask(step)
        out["finish_bad_reason"] = await ask({"type": "step", "data": {
            "type": "call_tool", "tool_name": "finish_episode", "arguments": {"reason": "because"}}})
    # one frame over the server's message limit: the socket is closed with 1009, the server goes on
    try:
        async with websockets.connect(WS_URL, additional_headers=AUTH, max_size=None) as ws:
            await ws.send(json.dumps({"type": "reset", "data": {"pad": "x" * SPEC["max_request_bytes"]}}))
            await ws.recv()
            out["oversized_frame"] = "answered"
    except websockets.ConnectionClosed as exc:
        out["oversized_frame"] = exc.rcvd.code if exc.rcvd else None
    async with httpx.AsyncClient(headers=AUTH, timeout=30) as http:
        out["mcp_not_json"] = (await http.post(URL + "/mcp", content=b"{not json",
                                               headers={"content-type": "application/json"})).json()
        big = await http.post(URL + "/mcp", content=b"x" * (SPEC["max_request_bytes"] + 1),
                              headers={"content-type": "application/json"})
        out["mcp_oversized"] = [big.status_code, big.text]
        out["health_after"] = (await http.get(URL + "/health")).json()
    return out


async def access() -> dict[str, Any]:
    """No token, or a wrong one: refused over HTTP, /mcp, the WebSocket handshake and the client."""
    out: dict[str, Any] = {}
    async with httpx.AsyncClient(timeout=30) as http:
        none = await http.get(URL + "/schema")
        wrong = await http.get(URL + "/schema", headers={"Authorization": "Bearer wrong"})
        mcp = await http.post(URL + "/mcp", json={"jsonrpc": "2.0", "id": 1, "method": "openenv/session/create"})
        out["http_none"], out["http_wrong"] = [none.status_code, none.text], [wrong.status_code, wrong.text]
        out["mcp_none"] = mcp.status_code
        out["health_none"] = (await http.get(URL + "/health")).status_code  # liveness needs no token
    try:
        async with websockets.connect(WS_URL) as ws:
            await ws.send(json.dumps({"type": "reset", "data": {}}))
            out["ws_none"] = await ws.recv()
    except Exception as exc:
        out["ws_none"] = f"{type(exc).__name__}: {exc}"
    try:
        async with HealthcareGymClient(base_url=URL, headers={"Authorization": "Bearer wrong"}) as env:
            await env.reset()
        out["client_wrong"] = "served"
    except Exception as exc:
        out["client_wrong"] = f"{type(exc).__name__}: {exc}"
    return out


async def task_api() -> dict[str, Any]:
    async with httpx.AsyncClient(headers=AUTH, timeout=30) as http:
        splits = (await http.get(URL + "/healthcare_gym/splits")).json()
        count = (await http.post(URL + "/healthcare_gym/num_tasks", json={"split": "test"})).json()
        task = (await http.post(URL + "/healthcare_gym/task", json={"split": "test", "index": 3})).json()
        out_of_range = await http.post(URL + "/healthcare_gym/task", json={"split": "test", "index": 10 ** 6})
    async with HealthcareGymClient(base_url=URL, headers=AUTH) as env:
        started = await env.reset(split="test", index=3)
    return {"splits": splits, "num_tasks": count, "task": task, "out_of_range": out_of_range.status_code,
            "reset_by_index": [started.observation.domain, started.observation.task_id]}


async def idle() -> dict[str, Any]:
    """A session left idle past the server's idle timeout is closed; its next message says so."""
    async with HealthcareGymClient(base_url=URL, headers=AUTH) as env:
        await env.reset(domain="drug_interaction", seed=0)
        await asyncio.sleep(SPEC["idle_wait_s"])
        try:
            result = await env.step(CallToolAction(tool_name="think", arguments={"thought": "back"}))
            return {"after_idle": f"served: {result.observation}"}
        except Exception as exc:
            return {"after_idle": f"{type(exc).__name__}: {exc}"}


async def wait_until_serving(timeout_s: float = 120.0) -> float:
    """The server is started beside this script (both pay their imports at once): wait for /health."""
    started = time.perf_counter()
    async with httpx.AsyncClient(headers=AUTH, timeout=2) as http:
        while True:
            try:
                if (await http.get(URL + "/health")).status_code == 200:
                    return time.perf_counter() - started
            except httpx.TransportError:
                pass
            if time.perf_counter() - started > timeout_s:
                raise TimeoutError(f"{URL}/health did not answer within {timeout_s:g} s")
            await asyncio.sleep(0.2)


async def main() -> None:
    waited = await wait_until_serving()
    started = time.perf_counter()
    # the idle session waits while everything else runs (the reaper checks every few seconds)
    idle_task = asyncio.create_task(idle())
    report: dict[str, Any] = {}
    report["ws_gold"] = await asyncio.gather(*(ws_gold_episode() for _ in range(4)))
    report["mcp_gold"] = await asyncio.gather(*(mcp_gold_episode() for _ in range(2)))
    report["mcp_only"] = await mcp_only()
    report["isolation"] = await isolation()
    report["busy"] = await busy()
    report["malformed"] = await malformed()
    report["access"] = await access()
    report["task_api"] = await task_api()
    report.update(await idle_task)
    report["waited_for_server_s"], report["scenarios_s"] = round(waited, 2), round(time.perf_counter() - started, 2)
    print(json.dumps(report))


asyncio.run(main())
