"""Hostile actions: `env.step` never raises, whatever the action, in every domain, and
the cost of one action is bounded by the per-action call cap.

Each class of action that has raised out of `step` has a one-line reproducer below; a seeded
random test mixes these classes over the ten domains, on ordinary and on terminal turns.
"""

import json
import random

import pytest

from envs import registry
from envs.core.actions import MAX_INTEGER_DIGITS, MAX_NESTING_DEPTH, parse_action
from envs.env import MAX_CALLS_PER_ACTION, HealthcareGymEnv
from envs.core.tools import safe_repr
from envs.rewards.accuracy import _numbers
from envs.rewards.similarity import _encodable
from envs.rewards.text import as_number, norm_value

DOMAINS = registry.list_domains()


def hermes(name, arguments_json):
    return '<tool_call>{"name": "%s", "arguments": %s}</tool_call>' % (name, arguments_json)


def deep(levels):
    return "[" * levels + "]" * levels


# Each reproducer: the action, and a phrase the parse error (shown to the agent) must contain.
NON_TERMINAL = {
    "json_nested_1000_hermes": (hermes("think", '{"thought": %s}' % deep(1000)), "levels deep exceeds the limit of 64"),
    "json_nested_1000_bare": (deep(1000), "levels deep exceeds the limit of 64"),
    "json_nested_1000_fenced": ("```json\n" + deep(1000) + "\n```", "levels deep exceeds the limit of 64"),
    "json_nested_in_openai_arguments": (
        json.dumps({"type": "function", "function": {"name": "think", "arguments": '{"t": %s}' % deep(1000)}}),
        "levels deep exceeds the limit of 64"),
    "json_int_5000_digits": (hermes("think", '{"thought": %s}' % ("9" * 5000)), "5000 digits"),
    "function_hex_5000_digits": ("think(thought=0x" + "f" * 5000 + ")", "digits"),
    "function_decimal_5000_digits": ("think(thought=" + "9" * 5000 + ")", "could not read call"),
    "function_complex": ("think(thought=1j)", "complex literal"),
    "function_bytes": ("think(thought=b'x')", "bytes literal"),
    "function_set": ("think(thought={1, 2})", "set literal"),
    "function_ellipsis": ("think(thought=...)", "Ellipsis"),
    "function_nested_900": ("think(thought=" + deep(900) + ")", "could not read call"),
    "function_expression": ("think(thought=__import__('os'))", "not a literal"),
}


@pytest.fixture(scope="module")
def envs_by_domain():
    return {domain: HealthcareGymEnv(domain=domain, max_turns=3) for domain in DOMAINS}


@pytest.mark.parametrize("case", sorted(NON_TERMINAL))
def test_each_reproducer_is_a_parse_error_in_every_domain(envs_by_domain, case):
    action, phrase = NON_TERMINAL[case]
    for domain, env in envs_by_domain.items():
        env.reset(seed=0)
        observation, reward, terminated, truncated, info = env.step(action)
        assert not terminated and not truncated and reward == 0.0, (domain, case)
        assert info["parse_errors"], (domain, case)
        assert any(phrase in e for e in info["parse_errors"]), (domain, case, info["parse_errors"])
        assert "could not parse action" in observation and phrase in observation
        turn = env.trajectory().turns[-1]
        assert turn.parse_errors == info["parse_errors"] and not turn.tool_calls
        json.dumps(env.trajectory().model_dump(mode="json"))  # the record stays serialisable


def test_limits_are_generous_for_real_arguments():
    nested = {"a": [[[{"b": [1, 2]}]]]}
    parsed = parse_action(hermes("think", json.dumps({"thought": "x", "n": 10 ** (MAX_INTEGER_DIGITS - 1),
                                                      "nested": nested})), {"think"})
    assert not parsed.errors and parsed.calls[0].arguments["nested"] == nested
    parsed = parse_action("think(thought='[[[x]]] {not json}', n=-0x10, ok=true, items=[1, 'a', None])", {"think"})
    assert not parsed.errors, parsed.errors
    assert parsed.calls[0].arguments == {"thought": "[[[x]]] {not json}", "n": -16, "ok": True, "items": [1, "a", None]}
    # brackets inside JSON strings are not nesting
    parsed = parse_action(hermes("think", json.dumps({"thought": "[" * 500})), {"think"})
    assert not parsed.errors and parsed.calls[0].arguments["thought"] == "[" * 500
    at_limit = hermes("think", '{"thought": %s}' % deep(MAX_NESTING_DEPTH - 2))
    assert not parse_action(at_limit, {"think"}).errors


def submit_env(domain, max_turns=3):
    env = HealthcareGymEnv(domain=domain, max_turns=max_turns)
    env.reset(seed=0)
    return env


def assert_scored(env, out, terminated=True):
    observation, reward, is_terminated, is_truncated, info = out
    assert (is_terminated, is_truncated) == (terminated, not terminated)
    assert "grader_error" not in info, info.get("grader_error")
    assert set(info["reward_components"]) >= {"accuracy", "process", "safety", "format", "coherence"}
    assert reward == pytest.approx(info["reward_components"]["total"])
    assert env.trajectory().reward == reward


@pytest.mark.parametrize("domain", DOMAINS)
def test_terminal_step_with_hostile_arguments_is_still_scored(domain):
    # a 400-digit integer argument on the last turn: OverflowError in the reward's number normalisation
    env = submit_env(domain, max_turns=1)
    assert_scored(env, env.step(hermes("think", '{"thought": "x", "n": %s}' % ("9" * 99))), terminated=False)
    env = submit_env(domain, max_turns=1)
    out = env.step(hermes("think", '{"thought": "x", "n": %s}' % ("9" * 400)))
    assert_scored(env, out, terminated=False)
    assert any("400 digits" in e for e in out[4]["parse_errors"])
    # an argument nested 900 deep on the last turn: RecursionError in the reward
    env = submit_env(domain, max_turns=1)
    out = env.step(hermes("think", '{"thought": "x", "n": %s}' % deep(900)))
    assert_scored(env, out, terminated=False)
    # a lone surrogate in the submitted answer (TypeError in the similarity grader on NL tasks)
    env = submit_env(domain)
    assert_scored(env, env.step(hermes("submit_answer", '{"answer": "\\ud800 the answer \\udfff"}')))


def test_reward_normalisers_take_hostile_values():
    assert as_number(10 ** 400) is None and as_number(-(10 ** 400)) is None and as_number(5) == 5.0
    assert norm_value(json.loads(deep(900))) == norm_value(json.loads(deep(901)))  # bounded, not a crash
    assert norm_value(10 ** 5000)[0] == "o"
    assert _numbers("dose 1e999999999 mg, then 2.5e3 mg") == [(2500.0, "mg", 26)]
    assert _encodable("a\ud800b") == "a?b" and _encodable("plain") == "plain"
    assert safe_repr(10 ** 5000) == "<int too large to show>" and safe_repr("x" * 100, 10) == "'xxxxxxxxx..."


def test_toolkit_error_messages_survive_huge_integers():
    env = submit_env("drug_interaction")
    toolkit = env.domain_env.toolkit
    outcome = toolkit.call("lookup_drug", {"name": 10 ** 5000})
    assert outcome.error_kind == "invalid_arguments" and "too large to show" in outcome.error
    outcome = toolkit.call(10 ** 5000, {})
    assert outcome.error_kind == "unknown_tool" and "too large to show" in outcome.error


HOSTILE_PIECES = [
    lambda r: deep(r.choice([65, 300, 1000, 3000])),
    lambda r: "9" * r.choice([101, 400, 4301, 6000]),
    lambda r: "0x" + "f" * r.choice([400, 5000]),
    lambda r: r.choice(["1j", "b'x'", "{1, 2}", "...", "1e999999", "-1e400", "NaN", "Infinity"]),
    lambda r: json.dumps("\ud800" + "x" * r.randint(0, 5)),
    lambda r: json.dumps({"k": [None, True, 1.5, "s"]}),
]


def hostile_action(rng, tool_names):
    """One action: a random tool (or submit_answer), a random format, hostile argument values."""
    name = rng.choice(tool_names + ["submit_answer", "no_such_tool"])
    value = rng.choice(HOSTILE_PIECES)(rng)
    fmt = rng.randrange(5)
    if fmt == 0:
        return hermes(name, '{"answer": %s, "x": %s}' % (value, value))
    if fmt == 1:
        return "```json\n" + '{"name": "%s", "arguments": {"answer": %s}}' % (name, value) + "\n```"
    if fmt == 2:
        return json.dumps({"type": "function", "function": {"name": name, "arguments": '{"answer": %s}' % value}})
    if fmt == 3:
        return f"{name}(answer={value})"
    return rng.choice(["", "   ", value, "<tool_call>" + value, "```" + value, "(" * 500])


@pytest.mark.parametrize("domain", DOMAINS)
def test_seeded_random_hostile_actions_never_raise(domain):
    rng = random.Random(f"hostile-{domain}")
    env = HealthcareGymEnv(domain=domain, max_turns=2)  # every other step is terminal
    tool_names = [tool["function"]["name"] for tool in env.reset(seed=0)[1]["tools"]]
    ended = 0
    for i in range(40):
        if env._done:
            env.reset(seed=i)
        observation, reward, terminated, truncated, info = env.step(hostile_action(rng, tool_names))
        assert isinstance(observation, str) and observation
        if terminated or truncated:
            ended += 1
            assert "grader_error" not in info, info["grader_error"]
            assert reward == pytest.approx(info["reward_components"]["total"])
            json.dumps(env.trajectory().model_dump(mode="json"))
    assert ended >= 10


def test_calls_per_action_are_capped_and_the_rest_refused():
    # One 99 KB action of 3,300 lookups of unknown drug names: uncapped, every call asks for fuzzy
    # suggestions over the whole name index (its cost: docs/benchmarks.md, "A hostile action's cost").
    env = submit_env("drug_interaction")
    action = "\n".join(f'lookup_drug(name="zq{i:04d}xkv")' for i in range(3300))
    assert 95_000 < len(action) <= 100_000
    observation, reward, terminated, truncated, info = env.step(action)
    assert len(info["tool_calls"]) == MAX_CALLS_PER_ACTION == 32
    refusal = f"{3300 - 32} tool calls after the first 32 were not run: an action may make at most 32 calls"
    assert refusal in info["parse_errors"] and refusal in observation
    assert len(env.trajectory().turns[-1].tool_calls) == 32
    # Its time is bench/hostile_step.py's to measure, not asserted here.


def test_submit_within_the_cap_still_ends_the_episode():
    env = submit_env("drug_interaction")
    action = "\n".join(['think(thought="a")'] * 40 + ['submit_answer(answer="x")'])
    out = env.step(action)
    assert not out[2] and len(out[4]["tool_calls"]) == 32  # submit was call 41: refused, not run
    out = env.step("\n".join(['think(thought="a")'] * 5 + ['submit_answer(answer="x")']))
    assert out[2] and out[4]["tool_calls"][-1] == "submit_answer"


def test_a_failing_grader_is_recorded_not_raised():
    # A domain scorer that fails (a grader bug on some answer) must not lose the episode.
    env = submit_env("drug_interaction")

    def broken_scorer(record, task, weights, context):
        raise ZeroDivisionError("grader bug")

    env.domain_env.scorer = broken_scorer
    observation, reward, terminated, truncated, info = env.step('submit_answer(answer="x")')
    assert terminated and reward == 0.0 and info["is_correct"] is False
    assert info["grader_error"] == "ZeroDivisionError: grader bug"
    record = env.trajectory()
    assert record.reward == 0.0 and record.reward_details == {"grader_error": "ZeroDivisionError: grader bug"}
    assert env.step("anything")[4] == {"error": "episode_over"}


class TickingClock:
    """A clock that advances `tick` seconds every time it is read: each tool call "takes" one tick."""

    def __init__(self, tick: float) -> None:
        self.now, self.tick = 0.0, tick

    def __call__(self) -> float:
        self.now += self.tick
        return self.now


def budget_env(domain="drug_interaction", max_turns=3, budget=0.0, clock=None):
    env = HealthcareGymEnv(domain=domain, max_turns=max_turns, step_time_budget_s=budget)
    if clock is not None:
        env.clock = clock
    env.reset(seed=0)
    return env


def test_time_budget_refuses_the_calls_after_it_is_spent():
    # The budget is read before each call: start at t=1, calls checked at t=2, 3, 4, 5 -> with a
    # budget of 2.5 s the first two run (elapsed 1 and 2) and the other two are refused.
    env = budget_env(budget=2.5, clock=TickingClock(1.0))
    action = "\n".join(f'lookup_drug(name="zq{i:04d}xkv")' for i in range(4))
    observation, reward, terminated, truncated, info = env.step(action)
    assert info["tool_calls"] == ["lookup_drug", "lookup_drug"] and info["calls_over_budget"] == 2
    refusal = ("2 tool calls (lookup_drug, lookup_drug) were not run: this action's tool calls took longer "
               "than the step time budget of 2.5 s")
    assert refusal in info["parse_errors"] and refusal in observation
    assert len(env.trajectory().turns[-1].tool_calls) == 2 and not terminated and not truncated


def test_time_budget_still_runs_the_submit_and_scores_the_episode():
    # The slowest action (3,300 unknown-drug lookups) followed by the answer: with the budget
    # spent from the start, no lookup runs but the submit does, and the episode is scored.
    env = budget_env(budget=0.0)
    action = "\n".join(f'lookup_drug(name="zq{i:04d}xkv")' for i in range(20)) + '\nsubmit_answer(answer="x")'
    observation, reward, terminated, truncated, info = env.step(action)
    assert terminated and info["tool_calls"] == ["submit_answer"] and info["calls_over_budget"] == 20
    assert_scored(env, (observation, reward, terminated, truncated, info))
    assert any("20 tool calls (lookup_drug, " in e and e.count("lookup_drug") == 8 for e in info["parse_errors"])


@pytest.mark.parametrize("domain", DOMAINS)
def test_time_budget_never_skips_terminal_scoring(domain):
    # A 300-call action on the last turn (3-15 s in eight domains in the issue): cut to the call cap,
    # then by the budget, and the turn-limit truncation is still scored.
    env = budget_env(domain=domain, max_turns=1, budget=3.0, clock=TickingClock(1.0))
    action = "\n".join(['think(thought="weighing the options")'] * 300)
    out = env.step(action)
    assert_scored(env, out, terminated=False)
    info = out[4]
    assert len(info["tool_calls"]) == 2 and info["calls_over_budget"] == MAX_CALLS_PER_ACTION - 2
    assert any("after the first 32 were not run" in e for e in info["parse_errors"])


def test_no_budget_runs_every_call_and_bad_budgets_are_named():
    env = budget_env(budget=None, clock=TickingClock(1000.0))
    out = env.step("\n".join(['think(thought="a")'] * 5))
    assert len(out[4]["tool_calls"]) == 5 and "calls_over_budget" not in out[4]
    for bad in (-1, float("nan"), float("inf"), True, "5"):
        with pytest.raises(ValueError, match="step_time_budget_s must be a finite number of seconds >= 0 or None"):
            HealthcareGymEnv(domain="drug_interaction", step_time_budget_s=bad)
