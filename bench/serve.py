"""The env server under load: concurrent episodes through `hcgym serve --mcp` vs the same calls in process.

The first server is `hcgym serve --mcp` in its own process (`--port 0`, graders warmed, `--max-episodes`
the session count). `--sessions` clients (default 64 and, for the unloaded latency, 1), each the
official MCP SDK client (`mcp.Client`, protocol 2026-07-28, the episode named in the request
`_meta`), run at once in one event loop; each replays `--episodes` gold episodes (a session alone:
`--episodes-alone`): `start_episode` with a task id, the task's gold tool calls, then `submit_answer`
with the gold answer (the call that ends and scores the episode). Tasks: the domain's split, those
with gold tool calls, in order, cycled.

The peer is the same episodes in process: `HealthcareGymEnv.call_tool` on as many envs as there are
sessions, round-robin one call each (one thread), so as many episodes are open at once.

A step is one task-tool call (the gold calls and the submit); `start_episode` is timed apart.
Printed per arm: steps/s, p50/p99 of a step (client-side, including queueing behind the other
sessions), episodes/s, CPU seconds of the server process and of this process (and per step, starts
included: unlike steps/s it does not depend on what else the machine runs), and the ratios in
process / server. Every episode's score over MCP must equal its score in process (exit 1 if not).
Rounds (`--rounds`) alternate the arms.

The second server is `hcgym serve --openenv` (OpenEnv 0.10, `envs/integrations/openenv/`), driven by
OpenEnv's own client (`HealthcareGymClient`, an `EnvClient`: one WebSocket session per client,
`reset(task_id=...)` then the calls) in a process of the OpenEnv venv (`make openenv`; this script
re-run there with `--drive-openenv`); without that venv the arm is skipped, said so. Another server
plugs in as another entry of `SERVERS`: a function that starts it and returns its URL and process,
and one that drives the sessions through it and returns their timings.

    python bench/serve.py [--domain drug_interaction] [--sessions 1 64] [--episodes 4] [--episodes-alone 32]
                          [--rounds 2] [--servers mcp openenv]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from envs.env import HealthcareGymEnv  # noqa: E402
from envs.validate import gold_answer_text  # noqa: E402

MAX_TURNS = 40


@dataclass
class Arm:
    """One arm's timings over a round."""

    steps: list[float] = field(default_factory=list)   # seconds per step
    starts: list[float] = field(default_factory=list)  # seconds per start_episode / reset
    rewards: dict[tuple[int, str], float] = field(default_factory=dict)  # (episode index, task id) -> reward
    episodes: int = 0  # episodes run (the rounds replay the same ones)
    wall_s: float = 0.0
    server_cpu_s: float = 0.0
    client_cpu_s: float = 0.0


def gold_plan(domain: str, split: str) -> list[tuple[str, list[tuple[str, dict]]]]:
    """(task id, gold calls ending with submit_answer) for every task with gold tool calls."""
    env = HealthcareGymEnv(domain=domain, split=split, max_turns=MAX_TURNS)
    plan = []
    for task in env.tasks:
        if not task.evaluation_criteria.actions:
            continue
        submit = {"answer": gold_answer_text(task) or "",
                  "reasoning": str(task.metadata.get("gold_reasoning") or "gold replay")}
        plan.append((task.id, [(a.name, dict(a.arguments)) for a in task.evaluation_criteria.actions]
                     + [("submit_answer", submit)]))
    if not plan:
        raise SystemExit(f"{domain}/{split}: no task with gold tool calls")
    return plan


def episodes_for(plan, sessions: int, per_session: int) -> list[list[tuple[int, str, list]]]:
    """Session s's episodes: (episode index, task id, calls), tasks cycled over all episodes."""
    out = []
    for s in range(sessions):
        out.append([(k, *plan[k % len(plan)]) for k in range(s * per_session, (s + 1) * per_session)])
    return out


def cpu_s_of(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def self_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return 0.0


def in_process(domain: str, split: str, sessions: list[list[tuple[int, str, list]]]) -> Arm:
    """The same episodes on `len(sessions)` envs, one call each in turn."""
    arm = Arm()
    cpu0, t0 = self_cpu_s(), time.perf_counter()
    envs = [HealthcareGymEnv(domain=domain, split=split, max_turns=MAX_TURNS) for _ in sessions]
    queues = [list(episodes) for episodes in sessions]
    current: list[tuple[int, str, list] | None] = [None] * len(sessions)
    cursor = [0] * len(sessions)
    while any(queues) or any(c is not None for c in current):
        for i, env in enumerate(envs):
            if current[i] is None:
                if not queues[i]:
                    continue
                current[i], cursor[i] = queues[i].pop(0), 0
                s0 = time.perf_counter()
                env.reset(seed=0, options={"task_id": current[i][1]})
                arm.starts.append(time.perf_counter() - s0)
                continue
            index, task_id, calls = current[i]
            name, arguments = calls[cursor[i]]
            s0 = time.perf_counter()
            result = env.call_tool(name, arguments, message="")
            arm.steps.append(time.perf_counter() - s0)
            cursor[i] += 1
            if result.done or cursor[i] == len(calls):
                arm.rewards[(index, task_id)] = env.reward if env.reward is not None else float("nan")
                arm.episodes += 1
                current[i] = None
    arm.wall_s = time.perf_counter() - t0
    arm.client_cpu_s = self_cpu_s() - cpu0
    return arm


def start_mcp(domain: str, split: str, sessions: int) -> tuple[str, subprocess.Popen]:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-m", "envs.cli", "serve", "--mcp", "--port", "0", "--domain", domain,
                             "--split", split, "--max-episodes", str(max(sessions, 1)), "--max-turns", str(MAX_TURNS)],
                            cwd=ROOT, env=env, stdout=subprocess.PIPE, text=True)
    line = proc.stdout.readline()
    found = re.search(r"http://\S+/mcp", line)
    if not found:
        proc.kill()
        raise SystemExit(f"the MCP server did not start (exit {proc.poll()}): {line!r}")
    return found.group(0), proc


async def mcp_session(url: str, episodes: list[tuple[int, str, list]], arm: Arm) -> None:
    from mcp import Client

    from envs.serve.mcp_server import EPISODE_META_KEY

    async with Client(url) as client:
        for index, task_id, calls in episodes:
            s0 = time.perf_counter()
            started = await client.call_tool("start_episode", {"task_id": task_id, "seed": 0})
            arm.starts.append(time.perf_counter() - s0)
            if started.is_error:
                raise RuntimeError(f"start_episode {task_id}: {started.content[0].text}")
            meta = {EPISODE_META_KEY: started.structured_content["episode_id"]}
            for name, arguments in calls:
                s0 = time.perf_counter()
                result = await client.call_tool(name, arguments, meta=meta)
                arm.steps.append(time.perf_counter() - s0)
                done = result.structured_content or {}
                if done.get("done"):
                    arm.rewards[(index, task_id)] = done["score"]["reward"]
                    arm.episodes += 1
                    break


def over_mcp(url: str, proc: subprocess.Popen, sessions: list[list[tuple[int, str, list]]]) -> Arm:
    arm = Arm()

    async def run_all() -> None:
        await asyncio.gather(*(mcp_session(url, episodes, arm) for episodes in sessions))

    server0, cpu0, t0 = cpu_s_of(proc.pid), self_cpu_s(), time.perf_counter()
    asyncio.run(run_all())
    arm.wall_s = time.perf_counter() - t0
    arm.client_cpu_s = self_cpu_s() - cpu0
    arm.server_cpu_s = cpu_s_of(proc.pid) - server0
    return arm


def start_openenv(domain: str, split: str, sessions: int) -> tuple[str, subprocess.Popen]:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-m", "envs.cli", "serve", "--openenv", "--port", "0", "--domain", domain,
                             "--split", split, "--max-episodes", str(max(sessions, 1)), "--max-turns", str(MAX_TURNS)],
                            cwd=ROOT, env=env, stdout=subprocess.PIPE, text=True)
    line = proc.stdout.readline()
    found = re.search(r"http://[^\s]+:\d+", line)
    if not found:
        proc.kill()
        raise SystemExit(f"the OpenEnv server did not start (exit {proc.poll()}): {line!r}")
    return found.group(0), proc


def over_openenv(url: str, proc: subprocess.Popen, sessions: list[list[tuple[int, str, list]]]) -> Arm:
    """The sessions on OpenEnv's own WebSocket client, in the OpenEnv venv (`drive_openenv`)."""
    from envs.serve.openenv_launch import openenv_python

    with tempfile.TemporaryDirectory() as tmp:
        spec = Path(tmp) / "spec.json"
        spec.write_text(json.dumps({"url": url, "sessions": sessions}))
        server0 = cpu_s_of(proc.pid)
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
        done = subprocess.run([openenv_python(), __file__, "--drive-openenv", str(spec)], cwd=ROOT, env=env,
                              capture_output=True, text=True)
        server_cpu = cpu_s_of(proc.pid) - server0  # the driver's imports cost the server nothing
    if done.returncode != 0:
        raise SystemExit(f"the OpenEnv driver failed: {done.stderr[-2000:]}")
    report = json.loads(done.stdout.splitlines()[-1])
    return Arm(steps=report["steps"], starts=report["starts"], episodes=report["episodes"],
               rewards={(i, task): reward for i, task, reward in report["rewards"]}, wall_s=report["wall_s"],
               server_cpu_s=server_cpu, client_cpu_s=report["cpu_s"])


def drive_openenv(spec_path: str) -> int:
    """Run in the OpenEnv venv: the sessions through `HealthcareGymClient` (OpenEnv's `EnvClient`, one
    WebSocket session each), `reset(task_id=...)` then the calls; prints one JSON line of timings."""
    from envs.integrations.openenv.client import HealthcareGymClient

    spec = json.loads(Path(spec_path).read_text())
    report: dict = {"steps": [], "starts": [], "rewards": [], "episodes": 0}

    async def session(episodes: list) -> None:
        async with HealthcareGymClient(base_url=spec["url"]) as env:
            for index, task_id, calls in episodes:
                s0 = time.perf_counter()
                await env.reset(task_id=task_id, seed=0)
                report["starts"].append(time.perf_counter() - s0)
                for name, arguments in calls:
                    s0 = time.perf_counter()
                    result = await env.call_tool(name, arguments)
                    report["steps"].append(time.perf_counter() - s0)
                    if result.done:
                        report["rewards"].append([index, task_id, result.reward])
                        report["episodes"] += 1
                        break

    async def run_all() -> None:
        await asyncio.gather(*(session(episodes) for episodes in spec["sessions"]))

    async def timed() -> tuple[float, float]:
        # one untimed episode first: this process's first calls pay one-off imports and model builds
        await session(spec["sessions"][0][:1])
        for key in ("steps", "starts", "rewards"):
            report[key].clear()
        report["episodes"] = 0
        cpu0, t0 = self_cpu_s(), time.perf_counter()
        await run_all()
        return time.perf_counter() - t0, self_cpu_s() - cpu0

    report["wall_s"], report["cpu_s"] = asyncio.run(timed())
    print(json.dumps(report))
    return 0


# name -> (start the server: (domain, split, sessions) -> (url, process), drive it: (url, process, sessions) -> Arm)
SERVERS = {"mcp": (start_mcp, over_mcp), "openenv": (start_openenv, over_openenv)}


def pct(samples: list[float], q: float) -> float:
    ordered = sorted(samples)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))] if ordered else float("nan")


def summary(arm: Arm) -> dict[str, float]:
    return {"steps": len(arm.steps), "steps_per_s": len(arm.steps) / arm.wall_s,
            "episodes_per_s": arm.episodes / arm.wall_s, "p50_ms": statistics.median(arm.steps) * 1e3,
            "p99_ms": pct(arm.steps, 0.99) * 1e3, "start_p50_ms": statistics.median(arm.starts) * 1e3,
            "wall_s": arm.wall_s, "server_cpu_s": arm.server_cpu_s, "client_cpu_s": arm.client_cpu_s,
            "cpu_ms_per_step": (arm.server_cpu_s + arm.client_cpu_s) / len(arm.steps) * 1e3}


def merge(arms: list[Arm]) -> Arm:
    out = Arm()
    for arm in arms:
        out.steps += arm.steps
        out.starts += arm.starts
        out.rewards.update(arm.rewards)
        out.episodes += arm.episodes
        out.wall_s += arm.wall_s
        out.server_cpu_s += arm.server_cpu_s
        out.client_cpu_s += arm.client_cpu_s
    return out


def main(argv: list[str] | None = None) -> int:
    if argv is None and sys.argv[1:2] == ["--drive-openenv"]:
        return drive_openenv(sys.argv[2])
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--domain", default="drug_interaction")
    parser.add_argument("--split", default="test")
    parser.add_argument("--sessions", type=int, nargs="+", default=[1, 64], help="concurrent sessions (one run each)")
    parser.add_argument("--episodes", type=int, default=4, help="episodes per session")
    parser.add_argument("--episodes-alone", type=int, default=32, help="episodes of a session running alone")
    parser.add_argument("--rounds", type=int, default=2, help="rounds, the arms alternating")
    parser.add_argument("--servers", nargs="+", choices=sorted(SERVERS), default=["mcp", "openenv"],
                        help="openenv needs its venv (make openenv); without it that arm is skipped, said so")
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    os.environ.setdefault("HCGYM_EMBEDDINGS", "0")

    servers = list(args.servers)
    if "openenv" in servers:
        from envs.serve.openenv_launch import openenv_python

        try:
            openenv_python()
        except (RuntimeError, ValueError, OSError) as exc:
            print(f"skipping the OpenEnv server: {exc}", file=sys.stderr)
            servers.remove("openenv")
    plan = gold_plan(args.domain, args.split)
    HealthcareGymEnv(domain=args.domain, split=args.split).warmup()  # the in-process arm's graders, as the server's
    results: dict[str, dict] = {}
    failed = False
    for n in args.sessions:
        sessions = episodes_for(plan, n, args.episodes_alone if n == 1 else args.episodes)
        running = {}
        try:
            for name in servers:
                running[name] = SERVERS[name][0](args.domain, args.split, n)
            for name in servers:  # untimed: the first calls of a client and a server pay one-off setup
                SERVERS[name][1](*running[name], [sessions[0][:1]])
            local: list[Arm] = []
            served: dict[str, list[Arm]] = {name: [] for name in servers}
            for _ in range(args.rounds):
                local.append(in_process(args.domain, args.split, sessions))
                for name in servers:
                    served[name].append(SERVERS[name][1](*running[name], sessions))
            server_rss = {name: rss_mb(proc.pid) for name, (_, proc) in running.items()}
        finally:
            for _, proc in running.values():
                proc.terminate()
                proc.wait(timeout=30)
        here = merge(local)
        a = summary(here)
        row: dict = {"in_process": a, "episodes": len(here.rewards)}
        print(f"{n} concurrent session(s) x {len(sessions[0])} episodes x {args.rounds} rounds "
              f"({args.domain}/{args.split}, {len(here.rewards)} distinct gold episodes, {here.episodes} run and "
              f"{a['steps']} steps per arm)")
        print(line("in process", a))
        for name in servers:
            there = merge(served[name])
            b = summary(there)
            differ = sorted(k for k in here.rewards if there.rewards.get(k) != here.rewards[k])
            row[name] = {**b, "ratio_steps_per_s": a["steps_per_s"] / b["steps_per_s"], "scores_differ": len(differ),
                         "server_rss_mb": server_rss[name]}
            print(line(f"{name} server", b))
            print(f"    in process is {row[name]['ratio_steps_per_s']:.1f}x its steps/s and "
                  f"{b['cpu_ms_per_step'] / a['cpu_ms_per_step']:.1f}x less CPU a step; scores differing: "
                  f"{len(differ)}; server RSS {server_rss[name]:.0f} MB")
            if differ:
                failed = True
                print(f"FAIL: {name}: scores differ for {differ[:5]}", file=sys.stderr)
        results[str(n)] = row
    results["cpus"] = os.cpu_count()
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))
    return 1 if failed else 0


def line(label: str, s: dict[str, float]) -> str:
    return (f"  {label:<15} {s['steps_per_s']:8.1f} steps/s  p50 {s['p50_ms']:8.2f} ms  p99 {s['p99_ms']:8.2f} ms"
            f"  start p50 {s['start_p50_ms']:7.2f} ms  {s['episodes_per_s']:6.1f} episodes/s  CPU s: server "
            f"{s['server_cpu_s']:.1f}, client {s['client_cpu_s']:.1f} ({s['cpu_ms_per_step']:.1f} ms a step, "
            "starts included)")


if __name__ == "__main__":
    sys.exit(main())
