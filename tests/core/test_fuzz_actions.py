"""Property-based fuzzing of `env.step`: over every domain's toolkit and every
action format the parser accepts (Hermes blocks, fenced JSON, a bare JSON object, a JSON list,
OpenAI tool-call objects, a `tool_calls` message, function syntax, free text, and mixes of text
and calls), with ordinary and hostile argument values, on ordinary and terminal turns.

Properties checked on every step:
  * `step` returns (never raises) and the observation is a non-empty str;
  * the episode ends exactly when it should: terminated iff a `submit_answer` call ran
    successfully in this action, truncated iff not terminated and the turn limit is reached;
  * an ended episode is scored (the five reward components and a finite total in [0, 1]; no
    grader error), and its trajectory stays JSON-serialisable.

Three calls in four start from the gold calls of the domain's tasks (so tool bodies run on valid ids)
with at most one argument replaced. The examples are derandomized (the same ones on every run, so CI is reproducible) and bounded in
number; `deadline=None` because a terminal step may load a grader model on first use.
"""

from __future__ import annotations

import json
import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from envs import registry
from envs.env import MAX_CALLS_PER_ACTION, HealthcareGymEnv

DOMAINS = registry.list_domains()
MAX_TURNS = 2  # every second step of an episode is terminal (truncated) unless it submitted earlier
FUZZ_SETTINGS = settings(max_examples=25, deadline=None, derandomize=True, database=None,
                         suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


# -- values -------------------------------------------------------------------------------------
SURROGATES = st.sampled_from(["\ud800", "\udfff", "a\ud83dz", "\udc80\udc80"])
STRINGS = st.one_of(st.text(max_size=40), SURROGATES, st.sampled_from(
    ["A", "B", "warfarin", "aspirin", "P001", "ESI 2", "", " ", "null", "{}", "[", "'); DROP TABLE", "x" * 2000]))
NUMBERS = st.one_of(st.integers(min_value=-10**6, max_value=10**6), st.integers(min_value=-10**120, max_value=10**120),
                    st.floats(allow_nan=True, allow_infinity=True))
SCALARS = st.one_of(st.none(), st.booleans(), NUMBERS, STRINGS)
JSON_VALUES = st.recursive(SCALARS, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=8), inner, max_size=4)), max_leaves=12)


def _deep(levels: int) -> str:
    return "[" * levels + "]" * levels


# Raw JSON text that no Python value serialises to: the hostile classes of tests/core/test_hostile_actions.py.
HOSTILE_JSON_TEXT = st.sampled_from([
    _deep(65), _deep(1000), "9" * 101, "9" * 400, "-" + "9" * 5000, "1e999999", "-1e400", "NaN", "Infinity",
    '"\\ud800"', '{"a": ' * 80 + "1" + "}" * 80,
])


def value_for(schema: dict) -> st.SearchStrategy:
    """A value that fits the schema of one argument most of the time, anything JSON otherwise."""
    kind = schema.get("type")
    if "enum" in schema:
        typed = st.sampled_from(schema["enum"])
    elif kind == "string":
        typed = STRINGS
    elif kind == "integer":
        typed = st.integers(min_value=-5, max_value=400)
    elif kind == "number":
        typed = st.one_of(st.floats(min_value=-5, max_value=500, allow_nan=False), st.integers(0, 300))
    elif kind == "boolean":
        typed = st.booleans()
    elif kind == "array":
        typed = st.lists(value_for(schema.get("items") or {}), max_size=4)
    elif kind == "object":
        typed = st.dictionaries(st.text(max_size=8), SCALARS, max_size=3)
    else:
        typed = JSON_VALUES
    return st.one_of(typed, typed, typed, JSON_VALUES)


@st.composite
def arguments_for(draw, tool: dict | None) -> dict:
    """Arguments for a tool: each declared argument present or not, sometimes an unknown one."""
    properties = ((tool or {}).get("function", {}).get("parameters", {}) or {}).get("properties", {})
    args = {}
    for name, schema in properties.items():
        if draw(st.integers(0, 4)):  # present 4 times in 5
            args[name] = draw(value_for(schema))
    if draw(st.integers(0, 5)) == 0:
        args[draw(st.sampled_from(["extra", "answer", "patient_id", "__class__", ""]))] = draw(JSON_VALUES)
    return args


# -- calls and actions --------------------------------------------------------------------------
@st.composite
def call(draw, tools: list[dict], gold: list[tuple[str, dict]]) -> tuple[str, dict, str | None]:
    """(tool name, arguments, raw hostile JSON added as one more argument, or None). Three calls in
    four start from a gold call of the domain's tasks (valid ids and values, so the tool body runs) with
    at most one argument replaced; the others are built from the tool's schema."""
    names = [t["function"]["name"] for t in tools]
    by_name = {t["function"]["name"]: t for t in tools}
    # (hypothesis starts from the simplest draws, 0 here: the gold branch, unchanged arguments)
    if gold and draw(st.integers(0, 3)) != 3:
        name, args = draw(st.sampled_from(gold))
        args = dict(args)
        if args and draw(st.integers(0, 2)) == 2:
            args[draw(st.sampled_from(sorted(args)))] = draw(JSON_VALUES)
    else:
        name = draw(st.one_of(st.sampled_from(names), st.just("submit_answer"), st.sampled_from(
            ["no_such_tool", "submit", "Submit_Answer", "lookup", names[-1] + "x"])))
        args = draw(arguments_for(by_name.get(name)))
    hostile = draw(st.one_of(st.none(), st.none(), st.none(), HOSTILE_JSON_TEXT))
    return name, args, hostile


def _arguments_json(args: dict, hostile: str | None) -> str:
    text = json.dumps(args, ensure_ascii=False)
    if hostile is None:
        return text
    return text[:-1] + (", " if args else "") + f'"hostile": {hostile}' + "}"


def _function_syntax(name: str, args: dict, hostile: str | None) -> str:
    # JSON literals are function-syntax literals too (true/false/null are read as JSON's)
    parts = [f"{key}={json.dumps(value, ensure_ascii=False)}" for key, value in args.items()
             if key.isidentifier() and key != "__class__"]
    if hostile is not None:
        parts.append(f"hostile={hostile}")
    return f"{name}({', '.join(parts)})"


def render(fmt: str, calls: list[tuple[str, dict, str | None]]) -> str:
    objects = [f'{{"name": {json.dumps(n)}, "arguments": {_arguments_json(a, h)}}}' for n, a, h in calls]
    if fmt == "hermes":
        return "\n".join(f"<tool_call>{o}</tool_call>" for o in objects)
    if fmt == "fenced":
        return "```json\n" + ("[" + ", ".join(objects) + "]" if len(objects) > 1 else objects[0]) + "\n```"
    if fmt == "json_object":
        return objects[0]
    if fmt == "json_list":
        return "[" + ", ".join(objects) + "]"
    if fmt == "openai":
        return json.dumps([{"type": "function", "function": {"name": n, "arguments": _arguments_json(a, h)}}
                           for n, a, h in calls])
    if fmt == "tool_calls":
        return json.dumps({"role": "assistant", "content": "calling", "tool_calls": [
            {"id": f"c{i}", "type": "function", "function": {"name": n, "arguments": _arguments_json(a, h)}}
            for i, (n, a, h) in enumerate(calls)]})
    if fmt == "function":
        return "\n".join(_function_syntax(n, a, h) for n, a, h in calls)
    raise ValueError(fmt)


CALL_FORMATS = ["hermes", "fenced", "json_object", "json_list", "openai", "tool_calls", "function"]


def gold_calls(env: HealthcareGymEnv) -> list[tuple[str, dict]]:
    """The calls of the domain's gold solutions, as seeds for valid calls: each task's expected calls and
    the submission of its gold answer (without these, a successful submit depends on the schema branch
    drawing valid `submit_answer` arguments, which derandomized draws over a changed task set can miss)."""
    calls = [(a.name, dict(a.arguments)) for task in env.tasks for a in task.evaluation_criteria.actions]
    calls += [("submit_answer", {"answer": str(task.correct_answer)}) for task in env.tasks
              if task.correct_answer not in (None, "")]
    return calls


@st.composite
def action(draw, tools: list[dict], gold: list[tuple[str, dict]] = ()) -> str:
    """One agent action in any accepted format, or free text, or text mixed with calls."""
    kind = draw(st.sampled_from(CALL_FORMATS + ["free_text", "mixed", "truncated"]))
    if kind == "free_text":
        return draw(st.one_of(st.text(max_size=200), st.sampled_from(
            ["", "   ", "The answer is B.", "submit_answer", "<tool_call>", "```", "(" * 300, "{" * 300, _deep(2000)])))
    calls = draw(st.lists(call(tools, list(gold)), min_size=1, max_size=3))
    if kind == "mixed":  # prose around calls, in a format that allows it
        fmt = draw(st.sampled_from(["hermes", "fenced", "function"]))
        before, after = draw(st.text(max_size=60)), draw(st.text(max_size=60))
        return f"{before}\n{render(fmt, calls)}\n{after}"
    text = render(kind if kind != "truncated" else "hermes", calls)
    if kind == "truncated":  # cut mid-call, as a generation that hit its token limit
        return text[:draw(st.integers(0, max(len(text) - 1, 0)))]
    return text


# -- the property -------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def domain_envs():
    out = {}
    for domain in DOMAINS:
        env = HealthcareGymEnv(domain=domain, max_turns=MAX_TURNS)
        _, info = env.reset(seed=0)
        out[domain] = (env, info["tools"], gold_calls(env))
    return out


def check_step(env: HealthcareGymEnv, act: str) -> bool:
    """Step once and check every property; returns whether the episode ended."""
    turns_before = len(env.trajectory().turns)
    observation, reward, terminated, truncated, info = env.step(act)
    assert isinstance(observation, str) and observation
    turn = env.trajectory().turns[-1]
    assert turn.index == turns_before and len(turn.tool_calls) <= MAX_CALLS_PER_ACTION
    submitted = any(record.submit and record.ok for record in turn.tool_calls)
    assert terminated == submitted, (terminated, [(r.name, r.error) for r in turn.tool_calls])
    assert truncated == (not submitted and turns_before + 1 >= MAX_TURNS)
    if not (terminated or truncated):
        assert reward == 0.0
        return False
    assert "grader_error" not in info, info.get("grader_error")
    components = info["reward_components"]
    assert {"accuracy", "process", "safety", "format", "coherence"} <= set(components)
    assert math.isfinite(reward) and 0.0 <= reward <= 1.0 and reward == pytest.approx(components["total"])
    record = env.trajectory()
    assert record.reward == reward and record.terminated == terminated and record.truncated == truncated
    json.dumps(record.model_dump(mode="json"))
    assert env.step("after the end")[4] == {"error": "episode_over"}
    return True


@pytest.mark.parametrize("domain", DOMAINS)
def test_fuzzed_actions_never_raise_and_end_scored(domain_envs, domain):
    env, _, gold = domain_envs[domain]
    steps_checked: list[int] = []

    @FUZZ_SETTINGS
    @given(data=st.data())
    def episode(data):
        # the toolkit of the episode's task (cross_domain builds one per pathway)
        _, info = env.reset(seed=data.draw(st.integers(0, 10_000), label="seed"))
        steps = 0
        for act in data.draw(st.lists(action(info["tools"], gold), min_size=1, max_size=MAX_TURNS), label="actions"):
            steps += 1  # check_step asserts the step's contract (no raise, str observation, scored end)
            if check_step(env, act):
                break
        steps_checked.append(steps)

    episode()
    assert steps_checked and min(steps_checked) >= 1, f"{domain}: no fuzzed step was checked"


def test_fuzz_strategies_cover_every_format_and_terminal_steps(domain_envs):
    """The strategies reach what the property is about: every parser format, successful submits
    and turn-limit ends (a strategy that never produced them would make the fuzz test vacuous)."""
    env, tools, gold = domain_envs["drug_interaction"]
    seen_formats: set[str] = set()
    ends = {"terminated": 0, "truncated": 0}
    calls = {"ok": 0, "failed": 0}

    @settings(max_examples=150, deadline=None, derandomize=True, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
    @given(actions=st.lists(action(tools, gold), min_size=1, max_size=MAX_TURNS))
    def episode(actions):
        env.reset(seed=0)
        for act in actions:
            _, _, terminated, truncated, info = env.step(act)
            seen_formats.add(info["action_format"])
            for record in env.trajectory().turns[-1].tool_calls:
                calls["ok" if record.ok else "failed"] += 1
            if terminated or truncated:
                ends["terminated" if terminated else "truncated"] += 1
                break

    episode()
    assert {"hermes", "fenced", "json", "openai", "function", "text"} <= seen_formats, seen_formats
    assert ends["terminated"] >= 5 and ends["truncated"] >= 5, ends
    assert calls["ok"] >= 30 and calls["failed"] >= 30, calls  # tool bodies run, and errors are exercised
