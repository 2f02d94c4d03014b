"""The runner: resumable Parquet results, interruption, Ray pool vs plain loop, and `hcgym eval`
end to end on a run folder (Ray env actors + a Ray HF generator actor) as a user runs it."""

from __future__ import annotations

import json
import os

import pyarrow.parquet as pq
import pytest

from envs.cli import main as hcgym
from evals.conditions import ConditionSettings
from evals.policies import ScriptedPolicy
from evals.runner import EvalOptions, run_eval
from evals.types import RESULTS_FILE, TRAJECTORIES_FILE, EvalItem, read_results, row_to_record
from tests.evals.conftest import WARD
from tests.evals.test_policies import make_run_dir
from tests.training.conftest import NO_EMBEDDINGS, SESSION_RAY_INIT

ITEMS = [EvalItem(benchmark="ward", domain="ward", task_id=t) for t in ("ward_choice", "ward_dose", "ward_record")]


pytestmark = pytest.mark.usefixtures("ward_domain")


@pytest.fixture(scope="module")
def ray_session():
    import ray

    from envs._runtime import init_ray

    started = not ray.is_initialized()
    if started:
        init_ray(**SESSION_RAY_INIT)
    yield ray
    if started:
        ray.shutdown()


def options(**kw) -> EvalOptions:
    base = dict(condition="agent", seeds=(0, 1), use_ray=False, progress=False, domain_modules=WARD,
                settings=ConditionSettings(max_turns=3), flush_every_s=0.0, env_vars=NO_EMBEDDINGS)
    base.update(kw)
    return EvalOptions(**base)


def comparable(rows):
    return sorted((r.model_dump(exclude={"latency_s"}) for r in rows), key=lambda d: json.dumps(d, sort_keys=True))


class CrashingGold(ScriptedPolicy):
    """Gold replay that crashes (a process fault, not an episode outcome) on one task."""

    def __init__(self, crash_task: str) -> None:
        super().__init__("gold")
        self.crash_task = crash_task

    def for_episode(self, task, seed, benchmark=None, max_turns=5):
        if task.id == self.crash_task:
            raise RuntimeError(f"simulated crash on {task.id}")
        return super().for_episode(task, seed, benchmark, max_turns)


def test_results_are_keyed_resumed_and_never_recomputed(tmp_path):
    out = tmp_path / "gold"
    first = run_eval(ScriptedPolicy("gold"), ITEMS, out, options(), suite="ward")
    assert (first["episodes_run"], first["episodes_skipped_done"]) == (6, 0)
    rows = read_results(out)
    assert {r.key() for r in rows} == {("scripted:gold", "ward", i.task_id, "agent", s) for i in ITEMS for s in (0, 1)}
    assert all(r.correct and r.end_reason == "answer" for r in rows)
    # Every row's trajectory can be found.
    trajectories = {t["row_id"]: t for t in pq.read_table(out / TRAJECTORIES_FILE).to_pylist()}
    for row in rows:
        file, _, rid = row.trajectory_ref.partition("#")
        assert file == TRAJECTORIES_FILE and trajectories[rid]["task_id"] == row.task_id
        assert json.loads(trajectories[rid]["messages"])[0]["role"] == "system"
    spec = json.loads((out / "eval.json").read_text())
    assert spec["condition"] == "agent" and spec["seeds"] == [0, 1]

    again = run_eval(ScriptedPolicy("gold"), ITEMS, out, options(), suite="ward")
    assert (again["episodes_run"], again["episodes_skipped_done"]) == (0, 6)
    assert comparable(read_results(out)) == comparable(rows)

    # An interruption: the process crashes mid-run; what finished is on disk, the rest resumes.
    crashed = tmp_path / "crashed"
    with pytest.raises(RuntimeError, match="simulated crash on ward_record"):
        run_eval(CrashingGold("ward_record"), ITEMS, crashed, options(concurrency=1), suite="ward")
    kept = read_results(crashed)
    assert 0 < len(kept) < 6 and all(r.task_id != "ward_record" for r in kept)
    resumed = run_eval(ScriptedPolicy("gold"), ITEMS, crashed, options(), suite="ward")
    assert resumed["episodes_run"] == 6 - len(kept)
    assert comparable(read_results(crashed)) == comparable(rows)  # same rows as the uninterrupted run

    with pytest.raises(ValueError, match="condition='agent', not 'text'"):
        run_eval(ScriptedPolicy("gold"), ITEMS, out, options(condition="text"), suite="ward")


def test_results_file_round_trips_dict_columns(tmp_path):
    out = tmp_path / "r"
    run_eval(ScriptedPolicy("random"), ITEMS, out, options(seeds=(3,)), suite="ward")
    table = pq.read_table(out / RESULTS_FILE)
    assert table.num_rows == 3 and table.schema.field("options").type == "string"  # JSON text
    assert table.schema.field("cost_usd").type == "double"  # typed although null in every row
    rows = read_results(out)
    assert [row_to_record(r) for r in rows] == table.to_pylist()
    choice = next(r for r in rows if r.task_id == "ward_choice")
    assert choice.options == {"A": "Macrolides", "B": "Penicillins", "C": "Statins", "D": "Vitamin D analogues"}


def test_ray_pool_gives_the_plain_loop_results(tmp_path, ray_session):
    plain = run_eval(ScriptedPolicy("random"), ITEMS, tmp_path / "plain", options(seeds=(0, 1, 2)), suite="ward")
    pooled = run_eval(ScriptedPolicy("random"), ITEMS, tmp_path / "ray",
                      options(seeds=(0, 1, 2), use_ray=True, num_env_actors=2, slots_per_env_actor=2), suite="ward")
    assert plain["episodes_run"] == pooled["episodes_run"] == 9
    assert comparable(read_results(tmp_path / "plain")) == comparable(read_results(tmp_path / "ray"))


def test_hcgym_eval_on_a_run_folder_end_to_end(tmp_path, ray_session, ward_policy_dir, capsys):
    run = make_run_dir(tmp_path, ward_policy_dir, checkpoint=True)
    out = tmp_path / "eval"
    argv = ["eval", "--policy", str(run), "--suite", "gym-train:ward", "--condition", "agent", "--output", str(out),
            "--seeds", "2", "--max-tokens", "16", "--env-actors", "1", "--generators", "1", "--no-report"]
    assert hcgym(argv) == 0
    rows = read_results(out)
    assert sorted((r.task_id, r.seed) for r in rows) == [("ward_dose", 0), ("ward_dose", 1),
                                                         ("ward_record", 0), ("ward_record", 1)]
    for row in rows:
        assert row.policy_id == str(run.resolve()) and row.benchmark == "gym_ward_train"
        assert row.end_reason in ("answer", "turn_limit", "token_limit", "parse_failure")
        assert 1 <= row.turns <= 3 and row.reward is not None  # the run's max_turns=3 applies
        assert 0 < row.completion_tokens <= 3 * 16 and row.prompt_tokens > 0
    spec = json.loads((out / "eval.json").read_text())
    assert spec["max_turns"] == 3 and spec["policy"] == str(run)
    assert spec["policy_source"]["source"] == "checkpoint step_000002"
    assert "4 episodes run" in capsys.readouterr().out
    assert hcgym(argv) == 0  # resumed: nothing left to run
    assert "0 episodes run, 4 already done" in capsys.readouterr().out
    import ray

    assert ray.is_initialized()  # the session cluster is still up: nothing to run starts or stops nothing


def test_cli_errors_name_the_argument(tmp_path, capsys):
    assert hcgym(["eval", "--suite", "gym-test:ward", "--output", str(tmp_path)]) == 2
    assert "--policy" in capsys.readouterr().err
    assert hcgym(["eval", "--policy", "scripted:gold", "--suite", "gym-test:ward", "--output", str(tmp_path),
                  "--seeds", "0"]) == 2
    assert "--seeds must be >= 1" in capsys.readouterr().err
    assert hcgym(["eval", "--policy", "scripted:gold", "--suite", "gym-test:ward", "--output", str(tmp_path),
                  "--no-ray", "--generator-backend", "vllm"]) == 2
    assert "--generator-backend vllm" in capsys.readouterr().err
    assert hcgym(["eval", "--base-url", "http://127.0.0.1:9/v1", "--suite", "gym-test:ward", "--output", str(tmp_path)]) == 2
    assert "--base-url and --model go together" in capsys.readouterr().err
    assert hcgym(["eval", "--policy", "scripted:gold", "--base-url", "http://127.0.0.1:9/v1", "--model", "m",
                  "--suite", "gym-test:ward", "--output", str(tmp_path)]) == 2
    assert "either --policy or --base-url" in capsys.readouterr().err


def test_hcgym_eval_against_a_real_endpoint(tmp_path, openai_server, capsys):
    """`hcgym eval --policy openai:URL:MODEL` as a user runs it, on vLLM's CPU server (tests/evals/conftest.py):
    text condition answers, and the agent condition's prompt (the env's full system prompt with every tool
    schema) is over the tiny server's 1,024-token context: each episode ends as context_overflow, none lost."""
    from tests.evals.conftest import SERVED_MODEL_NAME

    policy = f"openai:{openai_server}:{SERVED_MODEL_NAME}"
    text_out, agent_out = tmp_path / "text", tmp_path / "agent"
    common = ["--policy", policy, "--suite", "gym-test:ward", "--seeds", "3", "--no-ray", "--concurrency", "3",
              "--no-report"]
    # The text run names the endpoint as --base-url/--model: the same policy as openai:URL:MODEL.
    assert hcgym(["eval", *common[2:], "--base-url", openai_server, "--model", SERVED_MODEL_NAME,
                  "--condition", "text", "--output", str(text_out)]) == 0
    rows = read_results(text_out)
    assert [(r.task_id, r.seed) for r in sorted(rows, key=lambda r: r.seed)] == [("ward_choice", s) for s in range(3)]
    for row in rows:
        assert (row.end_reason, row.answer, row.correct) == ("answer", "B", True)  # "The answer is B."
        assert row.policy_id == policy and row.prompt_tokens > 0 and row.completion_tokens > 0
    logprob_out = tmp_path / "logprob"
    assert hcgym(["eval", *common, "--condition", "logprob", "--output", str(logprob_out)]) == 0
    rows = read_results(logprob_out)
    assert len(rows) == 3
    for row in rows:  # vLLM serves top_logprobs: every letter gets a log-probability, the argmax is the answer
        scores = row.extra["option_logprobs"]
        assert row.end_reason == "answer" and set(scores) == {"A", "B", "C", "D"}
        assert row.answer == max(scores, key=scores.get) and row.correct == (row.answer == "B")
    assert hcgym(["eval", *common, "--condition", "agent", "--output", str(agent_out)]) == 0
    rows = read_results(agent_out)
    assert len(rows) == 3 and len({r.key() for r in rows}) == 3
    for row in rows:
        assert (row.end_reason, row.error_kind, row.turns) == ("context_overflow", "context_overflow", 0)
        assert row.reward is not None and row.correct is False  # scored by the env all the same
    capsys.readouterr()


def test_ctrl_c_keeps_finished_episodes_and_the_rerun_completes(tmp_path):
    """A real interruption: SIGINT to a running `hcgym eval`, then the same command again."""
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "interrupted"
    command = [sys.executable, "-m", "envs.cli", "eval", "--policy", "scripted:gold", "--suite",
               "gym-test:triage_emergency", "--condition", "agent", "--output", str(out), "--seeds", "40",
               "--no-ray", "--concurrency", "1", "--no-report"]
    env = dict(os.environ, HCGYM_EMBEDDINGS="0")
    # Ctrl-C's default disposition, as a shell gives it: a child inherits an ignored SIGINT, and
    # something earlier in a long test session may leave this process ignoring it (seen in a full run).
    process = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 120
    while not (out / RESULTS_FILE).exists() and time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.2)
    assert process.poll() is None, f"finished before it could be interrupted: {process.communicate()}"
    process.send_signal(signal.SIGINT)
    _, err = process.communicate(timeout=60)
    assert process.returncode == 130, err
    kept = read_results(out)
    from envs import registry

    total = len(registry.get_tasks("triage_emergency", "test")) * 40
    assert 0 < len(kept) < total
    done = subprocess.run(command, check=False, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert f"{total - len(kept)} episodes run, {len(kept)} already done" in done.stdout
    rows = read_results(out)
    assert len(rows) == len({r.key() for r in rows}) == total and all(r.correct for r in rows)
