"""Environment step overhead: env.step on a READ tool call vs calling the same tool directly.

For every registered domain: reset latency (median), steps/s for a READ tool call, and the
environment's overhead per step (parse + validate + record) = median step time - median direct
call time of the same tool function with the same arguments. Target: <= 100 microseconds.
"The tool's own work" is calling the function and serialising its result to the observation text.
Also reports the slowest tool of each domain over the gold actions of its tasks, median of three
warm calls (target <= 5 ms except knowledge search; one-off index loads on first use excluded).

Hostile actions: per domain, a seeded campaign of generated hostile actions (every
action format, hostile values: deep nesting, huge integers, non-JSON literals, surrogates, unknown
tools, truncated calls) plus the worst case per tool (an action of 3,300 calls of that tool with
distinct unknown names, or 2,000-character strings, in every string argument: cut to the call cap,
and each unknown name asks for suggestions), each on an ordinary turn and as the episode's last
turn (so scoring is included). Prints actions tried, exceptions out of `step` (must be 0), the
slowest step with its action, and its ratio to the typical step (the median READ step above).

Run: python bench/env_step.py [--domains a b] [--steps 3000] [--hostile-actions 400] [--no-hostile]
"""

from __future__ import annotations

import argparse
import json
import random
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import envs  # noqa: E402,F401
from envs import registry  # noqa: E402
from envs.env import HealthcareGymEnv  # noqa: E402
from envs.core.tools import ToolType  # noqa: E402

KNOWLEDGE_TOOLS = {"search", "search_pubmed", "retrieve_evidence", "search_medical_wiki", "browse_article",
                   "search_guidelines"}


def _median_us(samples: list[float]) -> float:
    return statistics.median(samples) * 1e6


def pick_read_action(domain: str):
    """The first READ expected action of any task (tools are looked up after reset, since some
    domains, e.g. cross-domain pathways, build their toolkit per task)."""
    env = HealthcareGymEnv(domain=domain, max_turns=10**9)
    for task in registry.get_tasks(domain):
        env.reset(seed=0, options={"task_id": task.id})
        for action in task.evaluation_criteria.actions[:1]:
            definition = env.domain_env.toolkit.definitions.get(action.name)
            if definition and definition.tool_type is ToolType.READ and action.name not in KNOWLEDGE_TOOLS:
                return task, action
    raise SystemExit(f"{domain}: no task with a READ expected action to benchmark")


def slowest_tool(domain: str, max_tasks: int = 150) -> tuple[str, float]:
    """Median of three warm calls of every gold action of up to `max_tasks` tasks."""
    slowest = ("-", 0.0)
    env = HealthcareGymEnv(domain=domain, max_turns=10**9)
    for task in registry.get_tasks(domain)[:max_tasks]:
        env.reset(seed=0, options={"task_id": task.id})
        toolkit = env.domain_env.toolkit
        for action in task.evaluation_criteria.actions:
            if action.name in KNOWLEDGE_TOOLS or action.name not in toolkit.definitions:
                continue
            toolkit.call(action.name, action.arguments)  # warm: one-off index loads are not per-call cost
            runs = []
            for _ in range(3):
                start = time.perf_counter()
                toolkit.call(action.name, action.arguments)
                runs.append(time.perf_counter() - start)
            elapsed = statistics.median(runs)
            if elapsed > slowest[1]:
                slowest = (action.name, elapsed)
    return slowest


def bench_domain(domain: str, steps: int) -> dict:
    task, action = pick_read_action(domain)
    env = HealthcareGymEnv(domain=domain, task_id=task.id, max_turns=10**9)
    resets = []
    for seed in range(200):
        start = time.perf_counter()
        env.reset(seed=seed)
        resets.append(time.perf_counter() - start)
    env.reset(seed=0)
    text = "<tool_call>" + json.dumps({"name": action.name, "arguments": action.arguments}) + "</tool_call>"
    definition, method = env.domain_env.toolkit.bound(action.name)
    kwargs = definition.validate(action.arguments)
    direct, stepped = [], []
    for _ in range(steps):
        # The tool's own work: compute the result and serialise it to the observation text the
        # agent must receive. Everything else in env.step (parse, validate, record) is overhead.
        start = time.perf_counter()
        json.dumps(method(**kwargs), ensure_ascii=False, default=str)
        direct.append(time.perf_counter() - start)
        start = time.perf_counter()
        env.step(text)
        stepped.append(time.perf_counter() - start)
        if len(env._record.turns) > 200:  # keep the transcript from growing without bound
            env.reset(seed=0)
    slowest = slowest_tool(domain)
    step_us, direct_us = _median_us(stepped), _median_us(direct)
    return {
        "domain": domain, "tool": action.name, "reset_ms_p50": _median_us(resets) / 1000,
        "step_us_p50": step_us, "direct_us_p50": direct_us, "overhead_us": step_us - direct_us,
        "steps_per_s": 1e6 / step_us, "step_over_direct_ratio": step_us / max(direct_us, 1e-3),
        "slowest_tool": slowest[0], "slowest_tool_ms": slowest[1] * 1000,
    }


# -- hostile actions ------------------------------------------------------------------------------
def _deep(levels: int) -> str:
    return "[" * levels + "]" * levels


def _hermes(name: str, arguments_json: str) -> str:
    return '<tool_call>{"name": "%s", "arguments": %s}</tool_call>' % (name, arguments_json)


# Hostile argument values, one per class that has raised out of `step` (values written into an argument).
HOSTILE_VALUES = [
    _deep(1000), _deep(65), "9" * 5000, "9" * 400, "-" + "9" * 101, "1e999999", "-1e400", "NaN", "Infinity",
    '"\\ud800 x \\udfff"', '{"a": [null, true, 1.5, "s"]}', '"' + "x" * 20_000 + '"',
]
FUNCTION_ONLY_VALUES = ["0x" + "f" * 5000, "1j", "b'x'", "{1, 2}", "...", "__import__('os')", _deep(900)]


def random_hostile_action(rng: random.Random, tools: list[str]) -> tuple[str, str]:
    """(label, action): a random tool (or submit, or an unknown one), format and hostile value."""
    name = rng.choice(tools + ["submit_answer", "submit_answer", "no_such_tool"])
    value = rng.choice(HOSTILE_VALUES)
    calls = rng.choice([1, 1, 2, 40])
    fmt = rng.randrange(7)
    if fmt == 0:
        text = "\n".join(_hermes(name, '{"answer": %s, "patient_id": %s}' % (value, value)) for _ in range(calls))
    elif fmt == 1:
        text = "```json\n[" + ", ".join('{"name": "%s", "arguments": {"answer": %s}}' % (name, value)
                                        for _ in range(calls)) + "]\n```"
    elif fmt == 2:
        text = json.dumps([{"type": "function", "function": {"name": name, "arguments": '{"answer": %s}' % value}}
                           for _ in range(calls)])
    elif fmt == 3:
        literal = rng.choice(FUNCTION_ONLY_VALUES + HOSTILE_VALUES)
        text = "\n".join(f"{name}(answer={literal})" for _ in range(calls))
    elif fmt == 4:
        text = "Let me check.\n" + _hermes(name, '{"answer": %s}' % value) + "\nThen I answer."
    elif fmt == 5:
        full = _hermes(name, '{"answer": %s}' % value)
        text = full[:rng.randrange(len(full))]
    else:
        text = rng.choice(["", "   ", value, "<tool_call>" + value, "```" + value, "(" * 500, _deep(3000),
                           "x" * 100_001])
    return f"random fmt{fmt} {name} x{calls}", text


def worst_case_actions(tool_schemas: list[dict], gold: dict[str, dict]) -> list[tuple[str, str]]:
    """Per tool, 3,300 calls with distinct unknown names (or 2,000-character strings) in every
    string argument, the other arguments from a gold call of that tool (cut to the call cap)."""
    out = []
    for schema in tool_schemas:
        name = schema["function"]["name"]
        if name == "submit_answer":
            continue
        properties = schema["function"]["parameters"].get("properties", {})
        strings = [p for p, s in properties.items() if s.get("type") == "string" and "enum" not in s]
        for kind in ("unknown", "long"):
            calls = []
            for i in range(3300):
                args = dict(gold.get(name, {}))
                for prop in strings:
                    args[prop] = f"zq{i:04d}xkv" if kind == "unknown" else ("x" * 1990 + f"{i:010d}")
                calls.append(_hermes(name, json.dumps(args)))
            text = "\n".join(calls)
            if len(text) > 100_000:  # keep it an action the env accepts: as many calls as fit
                text = text[:100_000].rsplit("\n", 1)[0]
            out.append((f"{name} x{text.count('<tool_call>')} {kind} strings", text))
    return out


def hostile_domain(domain: str, random_actions: int, typical_us: float) -> dict:
    env = HealthcareGymEnv(domain=domain, max_turns=10**9)
    _, info = env.reset(seed=0)
    tools = [t["function"]["name"] for t in info["tools"]]
    gold: dict[str, dict] = {}
    for task in env.tasks[:200]:
        for action in task.evaluation_criteria.actions:
            gold.setdefault(action.name, dict(action.arguments))
    for name in tools:  # warm: first-use index loads (KB, ontologies) are not a step's cost
        if name != "submit_answer":
            env.domain_env.toolkit.call(name, gold.get(name, {}))
    from envs.rewards.similarity import get_embedder

    embed = get_embedder()  # the free-text grader's model loads once per process (~15 s), not per step
    if embed is not None:
        embed(["warm-up"])  # its first encode initialises torch (~4 s once)
    rng = random.Random(f"hostile-bench-{domain}")
    actions = [random_hostile_action(rng, tools) for _ in range(random_actions)]
    actions += worst_case_actions(info["tools"], gold)
    tried = exceptions = 0
    timings: list[tuple[float, str]] = []
    first_error = ""
    ordinary = HealthcareGymEnv(domain=domain, max_turns=10**9)
    last_turn = HealthcareGymEnv(domain=domain, max_turns=1)  # every step ends (and scores) the episode
    for seed, (label, text) in enumerate(actions):
        for env, where in ((ordinary, "ordinary"), (last_turn, "last turn")):
            if env._record is None or env._done or len(env._record.turns) > 50:
                env.reset(seed=seed)
            tried += 1
            start = time.perf_counter()
            try:
                env.step(text)
            except Exception as exc:  # what the guarantee forbids: counted, and the run goes on
                exceptions += 1
                first_error = first_error or f"{label}: {type(exc).__name__}: {exc}"[:200]
                env.reset(seed=seed)
                continue
            timings.append((time.perf_counter() - start, f"{label} ({where})"))
    timings.sort(reverse=True)
    first_use_s = timings[0][0]
    # The first pass includes one-off loads on first use (a grader's vocabulary, an ontology) and
    # stalls from other load on the machine: the ten slowest steps are timed again, warm, on fresh
    # episodes (median of three); per-step cost is the warm time.
    by_label = {f"{label} ({where})": (text, where) for label, text in actions for where in ("ordinary", "last turn")}
    warm: list[tuple[float, str]] = list(timings[10:11])
    for _, label in timings[:10]:
        text, where = by_label[label]
        env = ordinary if where == "ordinary" else last_turn
        runs = []
        for _ in range(3):
            env.reset(seed=0)
            start = time.perf_counter()
            env.step(text)
            runs.append(time.perf_counter() - start)
        warm.append((statistics.median(runs), label))
    slowest_s, slowest_label = max(warm)
    return {"domain": domain, "tried": tried, "exceptions": exceptions, "first_error": first_error,
            "median_ms": statistics.median(t for t, _ in timings) * 1000, "slowest_ms": slowest_s * 1000,
            "first_use_ms": first_use_s * 1000, "slowest": slowest_label,
            "slowest_over_typical": slowest_s * 1e6 / max(typical_us, 1e-3)}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--domains", nargs="*")
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--hostile-actions", type=int, default=400, help="random hostile actions per domain")
    parser.add_argument("--no-hostile", action="store_true", help="skip the hostile-action campaign")
    args = parser.parse_args()
    rows = [bench_domain(d, args.steps) for d in (args.domains or registry.list_domains())]
    header = f"{'domain':18s} {'tool':28s} {'reset ms':>9s} {'step us':>9s} {'direct us':>9s} {'overhead us':>11s} {'steps/s':>9s} {'step/direct':>11s} {'slowest tool (ms)':>28s}"
    print(header)
    for r in rows:
        print(f"{r['domain']:18s} {r['tool']:28s} {r['reset_ms_p50']:9.3f} {r['step_us_p50']:9.1f} {r['direct_us_p50']:9.1f} "
              f"{r['overhead_us']:11.1f} {r['steps_per_s']:9.0f} {r['step_over_direct_ratio']:11.1f} "
              f"{r['slowest_tool'] + ' ' + format(r['slowest_tool_ms'], '.3f'):>28s}")
    worst = max(r["overhead_us"] for r in rows)
    print(f"\nworst env overhead per step: {worst:.1f} us (target <= 100 us): {'PASS' if worst <= 100 else 'FAIL'}")
    if args.no_hostile:
        return
    print("\nHostile actions: each action on an ordinary turn and on the last turn (scored); "
          "ratio = slowest step / the typical READ step above")
    print(f"{'domain':18s} {'tried':>6s} {'exceptions':>10s} {'median ms':>9s} {'slowest ms':>10s} {'ratio':>7s} "
          f"{'first use ms':>12s}  slowest action (warm)")
    hostile = []
    for r in rows:
        h = hostile_domain(r["domain"], args.hostile_actions, r["step_us_p50"])
        hostile.append(h)
        print(f"{h['domain']:18s} {h['tried']:6d} {h['exceptions']:10d} {h['median_ms']:9.3f} {h['slowest_ms']:10.1f} "
              f"{h['slowest_over_typical']:7.0f} {h['first_use_ms']:12.1f}  {h['slowest']}", flush=True)
        if h["first_error"]:
            print(f"  first exception: {h['first_error']}")
    total = sum(h["tried"] for h in hostile)
    errors = sum(h["exceptions"] for h in hostile)
    slowest = max(hostile, key=lambda h: h["slowest_ms"])
    print(f"\n{total} hostile actions, {errors} exceptions out of step ({'PASS' if errors == 0 else 'FAIL'}); "
          f"slowest step {slowest['slowest_ms']:.1f} ms ({slowest['domain']}: {slowest['slowest']})")


if __name__ == "__main__":
    main()
