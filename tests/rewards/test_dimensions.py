"""The reward dimension registry: each dimension declared once (envs/rewards/dimensions/), and the
weights, the breakdown, `components()`, the verl keys and TRL's reward functions built from it."""

from __future__ import annotations

import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from envs.core.task import Task
from envs.rewards import RewardBreakdown, RewardWeights, score_episode
from envs.rewards.adapters import _VERL_KEYS
from envs.rewards.dimensions import ALWAYS_REPORTED, DIMENSIONS, GRADING_ORDER, Dimension, Graded, grading_order, registry
from learner.config import ConfigError, load_config
from tests.config_files import extended_config
from tests.rewards.builders import MC_OPTIONS, episode

REPO = Path(__file__).resolve().parents[2]


def _dimension(name: str, position: int = 9, after: tuple[str, ...] = ()) -> Dimension:
    return Dimension(name=name, default_weight=0.1, position=position, grade=lambda g: Graded(score=1.0), after=after)


def test_the_registry_holds_the_papers_dimensions_in_report_order_and_grades_dependencies_first():
    assert [d.name for d in DIMENSIONS] == ["accuracy", "process", "safety", "format", "coherence", "assertion"]
    assert ALWAYS_REPORTED == ("accuracy", "process", "safety", "format", "coherence")
    order = [d.name for d in GRADING_ORDER]
    # accuracy reads process's coverage and the assertion score; process reads the rubric score.
    assert order.index("assertion") < order.index("process") < order.index("accuracy")
    assert sorted(order) == sorted(d.name for d in DIMENSIONS)


def test_weights_breakdown_components_and_adapter_keys_are_built_from_the_registry():
    weights = RewardWeights()
    for dimension in DIMENSIONS:
        assert weights.weight(dimension.name) == dimension.default_weight
        field = RewardBreakdown.model_fields[dimension.name]
        assert field.is_required() == dimension.always_reported
    assert weights.model_dump()["accuracy"] == 0.25 and weights.assertion == 0.15  # paper section 3
    assert _VERL_KEYS == ALWAYS_REPORTED + ("safety_penalty",)
    from envs.integrations.trl import DIMENSIONS as TRL_DIMENSIONS, REWARD_NAMES

    assert TRL_DIMENSIONS == ALWAYS_REPORTED and REWARD_NAMES == ALWAYS_REPORTED + ("total",)
    with pytest.raises(KeyError, match="no reward dimension 'brevity'"):
        weights.weight("brevity")


def test_a_bad_declaration_is_refused_naming_the_module_and_dimension():
    with pytest.raises(ValueError, match="mod_b: dimension 'x' is declared twice"):
        registry([("mod_a", _dimension("x")), ("mod_b", _dimension("x"))])
    with pytest.raises(ValueError, match=r"'y' is graded after unknown dimension\(s\) \['z'\]"):
        registry([("mod_a", _dimension("y", after=("z",)))])
    with pytest.raises(ValueError, match="not a Python identifier"):
        registry([("mod_a", _dimension("two words"))])
    with pytest.raises(TypeError, match=r"mod_a.DIMENSION must be a Dimension, got dict"):
        registry([("mod_a", {"name": "x"})])
    with pytest.raises(ValueError, match="cycle: a -> b -> a"):
        grading_order((_dimension("a", 1, after=("b",)), _dimension("b", 2, after=("a",))))


def test_unknown_or_invalid_weights_name_the_field():
    with pytest.raises(ValueError, match="brevity"):
        RewardWeights.model_validate({"brevity": 1.0})
    with pytest.raises(ValueError, match="process must be a finite number >= 0, got -1.0"):
        RewardWeights(process=-1)
    with pytest.raises(ValueError, match="at least one of accuracy, process, safety, format, coherence must be > 0"):
        RewardWeights(accuracy=0, process=0, safety=0, format=0, coherence=0)


def _write_config(tmp_path: Path, weights: str) -> Path:
    return extended_config(tmp_path, f"reward:\n  weights: {weights}")


def test_reward_weights_from_the_run_config_reach_the_env_actors_and_change_the_score(tmp_path):
    with pytest.raises(ConfigError, match=r"reward\.weights.*brevity.*fields: .*accuracy"):
        load_config(_write_config(tmp_path, "{accuracy: 1.0, brevity: 2.0}"))
    with pytest.raises(ConfigError, match=r"reward\.weights.*safety must be a finite number >= 0"):
        load_config(_write_config(tmp_path, "{safety: -0.5}"))

    cfg = load_config(_write_config(tmp_path, "{accuracy: 1.0, process: 0, safety: 0, format: 0, coherence: 0}"))
    env_kwargs = cfg.rollout.env_pool_options(cfg.reward.env_kwargs())["env_kwargs"]
    assert env_kwargs["reward_weights"] == {"accuracy": 1.0, "process": 0, "safety": 0, "format": 0, "coherence": 0}

    # The env actors build their envs with these kwargs (actors.agent_loop.make_env): a wrong answer
    # on an accuracy-only reward scores 0, where the paper's weights pay its format and safety.
    from actors.agent_loop import make_env

    env = make_env("medical_qa", "test", 3, env_kwargs)
    task = env.tasks[0]
    wrong = next(k for k in (task.options or {"A": 0, "B": 0}) if k != task.correct_answer)
    env.reset(options={"task_id": task.id})
    env.call_tool("submit_answer", {"answer": wrong})
    assert env.done and env.reward == 0.0
    default_env = make_env("medical_qa", "test", 3, {})
    default_env.reset(options={"task_id": task.id})
    default_env.call_tool("submit_answer", {"answer": wrong})
    assert default_env.reward > 0.0


NEW_DIMENSION = '''
"""Brevity (a test dimension): 1 for an answer of at most 3 characters, else 0."""

from envs.rewards.dimensions.base import Dimension, Graded, Grading


def grade(grading: Grading) -> Graded:
    answer = grading.view.answer_text.strip()
    return Graded(score=1.0 if len(answer) <= 3 else 0.0, details={"chars": len(answer)})


DIMENSION = Dimension(name="brevity", default_weight=0.5, position=6, grade=grade)
'''

PROBE = '''
import envs
from envs.core.task import Task
from envs.rewards import RewardWeights, score_episode
from envs.rewards.adapters import _VERL_KEYS
from envs.integrations.trl import REWARD_NAMES
from tests.rewards.builders import MC_OPTIONS, episode

assert envs.__file__.startswith({root!r}), envs.__file__
task = Task(ticket="Which vitamin prevents scurvy?", options=MC_OPTIONS, correct_answer="B")
short = score_episode(episode(task, answer="B"), task)
long = score_episode(episode(task, answer="B: vitamin C"), task)
off = score_episode(episode(task, answer="B: vitamin C"), task, RewardWeights(brevity=0))
print(short.brevity, long.brevity, long.details["brevity"], round(long.weights["brevity"], 6),
      long.components()["brevity"], "brevity" in _VERL_KEYS, "reward_brevity" in ["reward_" + n for n in REWARD_NAMES],
      short.total > long.total, off.total == short.total, RewardWeights().brevity)
'''


def test_a_new_dimension_is_one_file(tmp_path):
    """Adding envs/rewards/dimensions/brevity.py (and nothing else) gives it a weight, a breakdown
    field, a component, a verl key and a TRL reward function, and it enters the weighted total."""
    shutil.copytree(REPO / "envs", tmp_path / "envs", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(REPO / "tests" / "rewards", tmp_path / "tests" / "rewards",
                    ignore=shutil.ignore_patterns("__pycache__", "test_*"))
    (tmp_path / "tests" / "__init__.py").write_text("")
    (tmp_path / "envs" / "rewards" / "dimensions" / "brevity.py").write_text(textwrap.dedent(NEW_DIMENSION))
    probe = PROBE.format(root=str(tmp_path))
    out = subprocess.run([sys.executable, "-c", probe], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-3000:]
    # "B" is short: brevity 1; "B: vitamin C" (12 characters) is not: brevity 0 with weight
    # 0.5 / (accuracy 0.25 + safety 0.20 + format 0.10 + coherence 0.10 + 0.5) = 0.434783 of the total
    # (process does not apply: no expected actions); weight 0 restores the total.
    assert out.stdout.split() == ["1.0", "0.0", "{'chars':", "12}", "0.434783", "0.0", "True", "True", "True", "True",
                                  "0.5"]


def test_scores_are_unchanged_by_the_registry():
    """The paper's combination (docs/rewards.md): a right answer with no process to judge."""
    task = Task(ticket="Which vitamin prevents scurvy?", options=MC_OPTIONS, correct_answer="B")
    breakdown = score_episode(episode(task, answer="B"), task)
    assert breakdown.accuracy == 1.0 and breakdown.assertion is None and "assertion" not in breakdown.weights
    assert breakdown.weights["process"] == 0.0  # no expected actions: process does not apply
    # accuracy 0.25, safety 0.20, format 0.10, coherence 0.10 normalised over 0.65
    assert breakdown.weights["accuracy"] == pytest.approx(0.25 / 0.65)
    assert set(breakdown.components()) == {*ALWAYS_REPORTED, "safety_penalty", "total"}
