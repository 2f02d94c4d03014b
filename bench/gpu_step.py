"""GPU throughput: DeepSpeed ZeRO-3 learner tokens/s and MFU, vLLM generation tokens/s, 0.5B-config model.

Needs a CUDA GPU. Without one it prints that no GPU was found and exits with status 0 (so
`make bench` passes on the CPU machines). Each part runs in its own subprocess, so vLLM's memory
reservation and DeepSpeed's process group never share a process.

* learner: our `Learner` with `backend: deepspeed` (ZeRO-3, 1 rank, bf16) on synthetic multi-turn
  samples; tokens/s counts every position of the batch; MFU = (6 + 2) * N * tokens/s / peak, i.e.
  policy forward+backward plus the frozen reference forward (attention FLOPs left out).
* vllm: `vllm.LLM` on the same weights, sampling with log-probs (as the generator does).

The model: Qwen2 architecture in the 0.5B shape (hidden 896, 24 layers, 14 heads, 2 KV heads,
intermediate 4864, vocabulary 151,936, tied embeddings), randomly initialised, tokenizer trained
locally (the prompts are token ids, so its size does not matter).

Run: python bench/gpu_step.py [--steps 5] [--batch 8] [--seq 2048] [--peak-tflops 989]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

PEAK_BF16_TFLOPS = {"H200": 989.0, "H100": 989.0, "A100": 312.0, "L40S": 362.0, "A10": 125.0}

QWEN2_05B = {"hidden_size": 896, "intermediate_size": 4864, "num_hidden_layers": 24, "num_attention_heads": 14,
             "num_key_value_heads": 2, "tie_word_embeddings": True, "max_position_embeddings": 32768,
             "rope_theta": 1_000_000.0, "rms_norm_eps": 1e-6}


def detect_gpu(parser: argparse.ArgumentParser, args: argparse.Namespace, script: str) -> str | None:
    """The GPU's name on a GPU node (and `args.peak_tflops` filled from it when not given); else prints
    why nothing runs and returns None, so the script exits 0 on CPU machines."""
    import torch

    if not torch.cuda.is_available():
        print(f"{script}: no GPU found (torch {torch.__version__}, torch.cuda.is_available() is False); "
              "nothing run. Run it on a GPU node (cluster.yaml installs both venvs).")
        return None
    name = torch.cuda.get_device_name(0)
    if args.peak_tflops is None:
        args.peak_tflops = next((v for k, v in PEAK_BF16_TFLOPS.items() if k in name), None)
        if args.peak_tflops is None:
            parser.error(f"unknown GPU {name!r}: pass --peak-tflops (dense bf16) for the MFU")
    return name


def build_model(root: Path) -> str:
    import torch
    from transformers import AutoModelForCausalLM, Qwen2Config

    from modeling.model import train_tokenizer

    tok_dir = train_tokenizer(["Healthcare AI GYM GPU benchmark corpus."] * 10, 4096, root / "tok",
                              max_stdlib_files=100)
    from modeling.model import load_tokenizer

    tok = load_tokenizer(tok_dir)
    config = Qwen2Config(vocab_size=151_936, pad_token_id=tok.pad_token_id, eos_token_id=tok.eos_token_id,
                         bos_token_id=None, **QWEN2_05B)
    torch.manual_seed(0)
    model = AutoModelForCausalLM.from_config(config, dtype=torch.bfloat16)
    out = root / "model"
    model.save_pretrained(str(out), safe_serialization=True)
    tok.save_pretrained(str(out))
    n = sum(p.numel() for p in model.parameters())
    (out / "bench_params.json").write_text(json.dumps({"params": n}))
    return str(out)


def synthetic_samples(batch: int, seq: int, vocab: int, seed: int = 0):
    """Multi-turn episodes in token space: prompt, turn, tool result, turn (random ids)."""
    import random

    from actors.types import RolloutSample, TurnSpan

    rng = random.Random(seed)
    prompt, tool = seq // 4, seq // 16
    turn = (seq - prompt - tool) // 2
    out = []
    for i in range(batch):
        ids = [rng.randrange(10, vocab) for _ in range(seq)]
        mask = [0] * prompt + [1] * turn + [0] * tool + [1] * (seq - prompt - turn - tool)
        turns = [TurnSpan(start=prompt, end=prompt + turn), TurnSpan(start=prompt + turn + tool, end=seq)]
        out.append(RolloutSample(sample_id=f"s{i}", task_id=f"t{i // 4}", domain="bench", group_id=f"g{i // 4}",
                                 seed=i, prompt_length=prompt, input_ids=ids, loss_mask=mask,
                                 sampling_logprobs=[0.0] * seq, policy_versions=[0 if m else -1 for m in mask],
                                 turns=turns, reward=float(i % 2), correct=bool(i % 2), response_tokens=sum(mask)))
    return out


def part_learner(args) -> dict:
    import torch

    from modeling.config_models import LearnerConfig
    from learner.learner_actor import Learner

    params = json.loads((Path(args.model_dir) / "bench_params.json").read_text())["params"]
    cfg = LearnerConfig(backend="deepspeed", device="cuda", dtype="bfloat16", gradient_checkpointing=True,
                        optim={"lr": 1e-6, "micro_batch_size": args.micro_batch},
                        deepspeed={"world_size": 1, "num_gpus_per_rank": 1})
    learner = Learner(cfg, args.model_dir, seed=0)
    samples = synthetic_samples(args.batch, args.seq, 151_936)
    learner.train_step(samples)  # warm-up (allocations, kernels)
    torch.cuda.synchronize()
    t0 = time.perf_counter()
    for _ in range(args.steps):
        learner.train_step(samples)
    torch.cuda.synchronize()
    dt = time.perf_counter() - t0
    tokens = args.steps * args.batch * args.seq
    tps = tokens / dt
    peak = args.peak_tflops * 1e12
    mfu = (6 + 2) * params * tps / peak
    learner.shutdown()
    return {"learner_tokens_per_s": tps, "learner_step_s": dt / args.steps, "mfu": mfu, "params": params,
            "peak_tflops": args.peak_tflops, "max_mem_gib": torch.cuda.max_memory_allocated() / 2**30}


def part_vllm(args) -> dict:
    try:
        from vllm import LLM, SamplingParams
    except ImportError as exc:
        return {"vllm": f"not installed ({exc}); run this part with the vLLM venv's python "
                         "(~/hcgym-vllm on cluster.yaml nodes, docs/cluster.md)"}
    import random

    llm = LLM(model=args.model_dir, dtype="bfloat16", max_model_len=args.seq + args.new_tokens,
              gpu_memory_utilization=0.6, seed=0)
    rng = random.Random(0)
    prompts = [{"prompt_token_ids": [rng.randrange(10, 151_936) for _ in range(args.seq // 4)]}
               for _ in range(args.prompts)]
    params = SamplingParams(temperature=1.0, max_tokens=args.new_tokens, ignore_eos=True, logprobs=1)
    llm.generate(prompts[:4], params)  # warm-up
    t0 = time.perf_counter()
    outs = llm.generate(prompts, params)
    dt = time.perf_counter() - t0
    generated = sum(len(o.outputs[0].token_ids) for o in outs)
    return {"vllm_tokens_per_s": generated / dt, "vllm_prompts": args.prompts, "vllm_new_tokens": args.new_tokens}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=5)
    parser.add_argument("--batch", type=int, default=8)
    parser.add_argument("--micro-batch", type=int, default=2)
    parser.add_argument("--seq", type=int, default=2048)
    parser.add_argument("--prompts", type=int, default=64)
    parser.add_argument("--new-tokens", type=int, default=512)
    parser.add_argument("--peak-tflops", type=float, default=None, help="dense bf16 peak of the GPU")
    parser.add_argument("--part", choices=["learner", "vllm"], default=None, help=argparse.SUPPRESS)
    parser.add_argument("--model-dir", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()

    name = detect_gpu(parser, args, "bench/gpu_step.py")
    if name is None:
        return 0
    import torch
    if args.part:
        result = part_learner(args) if args.part == "learner" else part_vllm(args)
        print("RESULT " + json.dumps(result))
        return 0

    root = Path(tempfile.mkdtemp(prefix="bench_gpu_"))
    model_dir = build_model(root)
    results = {"device": name, "torch": torch.__version__}
    for part in ("learner", "vllm"):
        cmd = [sys.executable, __file__, "--part", part, "--model-dir", model_dir, "--steps", str(args.steps),
               "--batch", str(args.batch), "--micro-batch", str(args.micro_batch), "--seq", str(args.seq),
               "--prompts", str(args.prompts), "--new-tokens", str(args.new_tokens),
               "--peak-tflops", str(args.peak_tflops)]
        env = {**os.environ, "DS_ACCELERATOR": "cuda"}
        proc = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
        lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
        if proc.returncode != 0 or not lines:
            results[part] = f"failed (exit {proc.returncode}): {proc.stderr[-2000:]}"
        else:
            results.update(json.loads(lines[-1][len("RESULT "):]))
    print(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
