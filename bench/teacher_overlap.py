"""Teacher overlap: how much of a learner step waits on the EMA teacher, async vs synchronous.

A real (tiny) pipeline on a local Ray cluster: this process generates multi-turn episodes with
the HF generator (sampling for real from the tiny policy), a TeacherActor scores them and a
LearnerActor trains on them with TT-OPD; weights flow back to the generator every step and to
the teacher at EMA steps.

* async  (the design): each group is `submit`ted to the teacher the moment it finishes, so scoring
  overlaps the generation of the following groups; at the step the learner receives the ref of
  `fetch` and resolves it after its reference forward, so the last group's scoring overlaps that.
* sync   (the baseline, same run, same model): the batch is scored with `score` only when the
  learner needs it.

teacher_wait_frac = teacher wait / (teacher wait + learner step), the driver's definition. Target
for async: below 5 %. The first step of each mode is a warm-up and not counted.

Run: python bench/teacher_overlap.py [--steps 5] [--groups 4] [--group-size 3] [--new-tokens 48]
"""

from __future__ import annotations

import argparse
import json
import random
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import envs  # noqa: F401  (CPU runtime defaults)

CORPUS = [
    "A 64-year-old man on warfarin presents with melena; INR is 5.2. What is the next step?",
    "Check the interaction between clarithromycin and simvastatin before prescribing.",
    '<tool_call>\n{"name": "get_patient", "arguments": {"patient_id": "P-102"}}\n</tool_call>',
    "Creatinine clearance 28 mL/min: adjust enoxaparin to 1 mg/kg once daily. Answer: C",
] * 50


def build_model(root: Path) -> str:
    from modeling.model import build_tiny_model, train_tokenizer

    tok = train_tokenizer(CORPUS, 4096, root / "tok", max_stdlib_files=200)
    return str(build_tiny_model(root / "model", tok, seed=0))  # hidden 128, 2 layers, vocab 4096


def make_group(gen, tok, rng: random.Random, gid: int, group_size: int, new_tokens: int, version: int):
    """One GRPO group: G two-turn episodes sampled by the generator (tool result between turns)."""
    from actors.generator import GenerationRequest
    from actors.types import RolloutSample, TurnSpan
    from modeling.model import tool_turn_text

    question = rng.choice(CORPUS[:4])
    prompt = tok.apply_chat_template([{"role": "user", "content": question}], tokenize=False,
                                     add_generation_prompt=True)
    prompt_ids = tok.encode(prompt, add_special_tokens=False)
    ids = [list(prompt_ids) for _ in range(group_size)]
    masks = [[0] * len(prompt_ids) for _ in range(group_size)]
    lps = [[0.0] * len(prompt_ids) for _ in range(group_size)]
    turns: list[list] = [[] for _ in range(group_size)]
    for turn in range(2):
        reqs = [GenerationRequest(request_id=f"{gid}:{i}:{turn}", prompt_ids=ids[i], max_new_tokens=new_tokens,
                                  seed=rng.randrange(1 << 30), min_version=version) for i in range(group_size)]
        for i, res in enumerate(gen.generate(reqs)):
            start = len(ids[i])
            ids[i] += res.token_ids
            masks[i] += [1] * len(res.token_ids)
            lps[i] += res.logprobs
            turns[i].append(TurnSpan(start=start, end=len(ids[i]), truncated=res.finish_reason == "length"))
            if turn == 0:
                tool = tok.encode(tool_turn_text("INR 5.2; no interaction found."), add_special_tokens=False)
                ids[i] += tool
                masks[i] += [0] * len(tool)
                lps[i] += [0.0] * len(tool)
    samples = []
    for i in range(group_size):
        correct = (i + gid) % 2 == 0  # mixed outcomes, so every group trains
        samples.append(RolloutSample(
            sample_id=f"{gid}:{i}", task_id=f"t{gid}", domain="bench", group_id=f"g{gid}", seed=i,
            prompt_length=len(prompt_ids), input_ids=ids[i], loss_mask=masks[i], sampling_logprobs=lps[i],
            policy_versions=[version if m else -1 for m in masks[i]], turns=turns[i],
            reward=1.0 if correct else 0.0, correct=correct, response_tokens=sum(masks[i])))
    return samples


def run_mode(mode: str, args, model_dir: str) -> list[dict]:
    import ray

    from actors.generator import SamplingConfig
    from actors.generator_hf import HFGenerator
    from actors.teacher import TeacherActor
    from actors.types import PendingTeacherBatch, TeacherBatch
    from modeling.config_models import LearnerConfig, TeacherConfig, teacher_update_action
    from learner.learner_actor import LearnerActor
    from modeling.model import ENDOFTEXT, IM_END, load_tokenizer

    tok = load_tokenizer(model_dir)
    stop = [tok.convert_tokens_to_ids(IM_END), tok.convert_tokens_to_ids(ENDOFTEXT)]
    gen = HFGenerator(model_dir, SamplingConfig(), stop)
    tcfg = TeacherConfig(enabled=True, ema_interval=2, hard_copy_interval=0, batch_size=args.group_size)
    lcfg = LearnerConfig(optim={"lr": 1e-4}, loss={"distill": {"enabled": True}})
    teacher = TeacherActor.options(num_cpus=1).remote(tcfg, model_dir)
    learner = LearnerActor.options(num_cpus=1).remote(lcfg, model_dir, 0)
    ray.get([teacher.teacher_version.remote(), learner.policy_version.remote()])
    rng = random.Random(0)
    rows = []
    gid = 0
    for step in range(1, args.steps + 1):
        t_step = time.perf_counter()
        batch = []
        for _ in range(args.groups):
            group = make_group(gen, tok, rng, gid, args.group_size, args.new_tokens, step - 1)
            gid += 1
            batch += group
            if mode == "async":
                teacher.submit.remote(group)  # scoring starts now, generation goes on
        t_ready = time.perf_counter()
        if mode == "async":
            # The learner gets the fetch's ref (wrapped, so Ray does not resolve it first) and only
            # blocks on it after its reference forward; the time it blocks is its teacher_wait_s.
            fetch_ref = teacher.fetch.remote([s.sample_id for s in batch], 600.0)
            metrics = ray.get(learner.train_step.remote(batch, PendingTeacherBatch(fetch_ref), step))
            wait = metrics["teacher_wait_s"]
            learner_s = time.perf_counter() - t_ready - wait
        else:
            outs = ray.get(teacher.score.remote(batch))
            wait = time.perf_counter() - t_ready
            t_learn = time.perf_counter()
            metrics = ray.get(learner.train_step.remote(batch, TeacherBatch(outputs=outs), step))
            learner_s = time.perf_counter() - t_learn
        weights = learner.get_weights.remote()
        gen.update_weights(ray.get(weights), step)
        if teacher_update_action(step, tcfg) != "none":
            ray.get(teacher.update.remote(weights, step))
        rows.append({"mode": mode, "step": step, "teacher_wait_s": wait, "learner_s": learner_s,
                     "generation_s": t_ready - t_step, "step_s": time.perf_counter() - t_step,
                     "teacher_wait_frac": wait / max(wait + learner_s, 1e-9),
                     "train_tokens": metrics["train_tokens"], "kl_teacher": metrics["kl_teacher"]})
        print(f"  {mode} step {step}: gen {rows[-1]['generation_s']:.2f}s  teacher wait {wait * 1000:.0f} ms  "
              f"learner {learner_s * 1000:.0f} ms  wait frac {rows[-1]['teacher_wait_frac']:.1%}", flush=True)
    ray.kill(teacher)
    ray.kill(learner)
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=5)
    parser.add_argument("--groups", type=int, default=4, help="groups per batch")
    parser.add_argument("--group-size", type=int, default=3)
    parser.add_argument("--new-tokens", type=int, default=48, help="max new tokens per assistant turn")
    parser.add_argument("--model-dir", default=None, help="an existing policy directory (default: build the tiny one)")
    parser.add_argument("--json", default=None, help="also write the per-step rows to this file")
    args = parser.parse_args()
    if args.steps < 2:
        parser.error("--steps must be >= 2 (the first step of each mode is a warm-up)")
    import ray
    import torch

    model_dir = args.model_dir or build_model(Path(tempfile.mkdtemp(prefix="bench_teacher_")))
    from envs._runtime import init_ray  # a local cluster on 127.0.0.1 only

    init_ray(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        rows = []
        for mode in ("async", "sync"):
            print(f"[{mode}] {args.steps} steps x {args.groups} groups x {args.group_size} samples, "
                  f"2 turns <= {args.new_tokens} new tokens each", flush=True)
            rows += run_mode(mode, args, model_dir)
    finally:
        ray.shutdown()

    def summary(mode):
        r = [x for x in rows if x["mode"] == mode and x["step"] > 1]
        wait = statistics.mean(x["teacher_wait_s"] for x in r)
        learn = statistics.mean(x["learner_s"] for x in r)
        return {"teacher_wait_ms": 1000 * wait, "learner_ms": 1000 * learn, "wait_frac": wait / (wait + learn),
                "step_s": statistics.mean(x["step_s"] for x in r)}

    a, s = summary("async"), summary("sync")
    print("\nmode   teacher wait   learner step   wait frac   step time")
    for name, r in (("async", a), ("sync", s)):
        print(f"{name:6} {r['teacher_wait_ms']:9.0f} ms  {r['learner_ms']:9.0f} ms  {r['wait_frac']:9.1%}  "
              f"{r['step_s']:8.2f} s")
    # Sub-millisecond async waits are timer noise: the ratio uses a 1 ms floor and says "at least".
    ratio = s["teacher_wait_ms"] / max(a["teacher_wait_ms"], 1.0)
    bound = "at least " if a["teacher_wait_ms"] < 1.0 else ""
    print(f"\nsynchronous teacher waits {bound}{ratio:.0f}x longer ({s['teacher_wait_ms']:.0f} ms vs "
          f"{a['teacher_wait_ms']:.2f} ms); async wait fraction {a['wait_frac']:.1%} "
          f"(target < 5 %: {'met' if a['wait_frac'] < 0.05 else 'NOT met'}); torch {torch.__version__}, "
          f"{torch.get_num_threads()} thread(s)")
    if args.json:
        Path(args.json).write_text(json.dumps({"rows": rows, "async": a, "sync": s, "ratio": ratio}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
