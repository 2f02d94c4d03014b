"""GPU throughput: DeepSpeed ZeRO-3 learner tokens/s and MFU, vLLM generation tokens/s, 0.5B-config model.

Needs a CUDA GPU. Without one it prints that no GPU was found and exits with status 0 (so
`make bench` passes on the CPU machines); `--cpu` rehearses it on the CPU (tiny model, the same
code paths). Each half runs in its own subprocess and interpreter, as on the cluster nodes, where
DeepSpeed and vLLM live in two venvs: the learner half in this interpreter (~/hcgym-venv), the vLLM
half in `--vllm-python` (default auto: this interpreter if it imports vllm, else .venv-vllm, else
~/hcgym-vllm). Each half prints its figures as soon as it ends (a `PHASE <name> {...}` line) and
`--json-out` is rewritten after each, so a later failure keeps what was measured.

* learner: our `Learner` with `backend: deepspeed` (ZeRO-3, 1 rank, bf16) on synthetic multi-turn
  samples, `--lengths even` (every sample --seq tokens) or `long-tail` (bench/packing.py's log-normal
  mix rescaled to --seq: most samples short, a few up to --seq). Two learners from the same weights,
  `pack_sequences: false` (padded) and `auto` (packed: flash attention or sdpa_varlen), take turns
  step by step (which goes first alternates). Per arm: tokens/s counting real tokens only (padding
  positions are work, not throughput), step seconds, the learner's `learner_padding_frac`, and MFU
  on real tokens: FLOPs = 8 (N - N_head) real tokens + 8 N_head loss_tokens (bench/gpu_figures.py:
  the LM head runs on the loss positions only), against the dense bf16 peak of the device model
  (none for an unknown device); and packed / padded. The top-level figures are the packed arm's
  (the learner's default, `auto`).
* vllm: `vllm.LLM` on the same weights, sampling with log-probs (as the generator does).

The model: Qwen2 architecture in the 0.5B shape (hidden 896, 24 layers, 14 heads, 2 KV heads,
intermediate 4864, vocabulary 151,936, tied embeddings), randomly initialised, tokenizer trained
locally (the prompts are token ids, so its size does not matter).

Run: python bench/gpu_step.py [--steps 5] [--batch 8] [--seq 2048] [--lengths even|long-tail]
     [--vllm-python PY] [--json-out F]
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
sys.path.insert(0, str(Path(__file__).resolve().parent))

from gpu_figures import FigureLog, device_peak, head_params, learner_step_flops, mfu, resolve_vllm_python  # noqa: E402

QWEN2_05B = {"hidden_size": 896, "intermediate_size": 4864, "num_hidden_layers": 24, "num_attention_heads": 14,
             "num_key_value_heads": 2, "tie_word_embeddings": True, "max_position_embeddings": 32768,
             "rope_theta": 1_000_000.0, "rms_norm_eps": 1e-6}
# --cpu: the same architecture at a size a CPU core runs in seconds (head_dim 64: vLLM's CPU
# attention rejects smaller heads).
QWEN2_CPU = {"hidden_size": 128, "intermediate_size": 256, "num_hidden_layers": 2, "num_attention_heads": 2,
             "num_key_value_heads": 1, "tie_word_embeddings": True, "max_position_embeddings": 4096,
             "rope_theta": 1_000_000.0, "rms_norm_eps": 1e-6}
VOCAB = 151_936
VOCAB_CPU = 4096


def detect_gpu(script: str) -> str | None:
    """The GPU's name, or None after printing why nothing runs (the script then exits 0)."""
    import torch

    if not torch.cuda.is_available():
        print(f"{script}: no GPU found (torch {torch.__version__}, torch.cuda.is_available() is False); "
              "nothing run. Run it on a GPU node (cluster.yaml installs both venvs), or pass --cpu to rehearse.")
        return None
    return torch.cuda.get_device_name(0)


def build_model(root: Path, cpu: bool = False) -> str:
    import torch
    from transformers import AutoModelForCausalLM, Qwen2Config

    from modeling.model import load_tokenizer, train_tokenizer

    tok = load_tokenizer(train_tokenizer(["Healthcare AI GYM GPU benchmark corpus."] * 10, 4096, root / "tok",
                                         max_stdlib_files=100))
    config = Qwen2Config(vocab_size=VOCAB_CPU if cpu else VOCAB, pad_token_id=tok.pad_token_id,
                         eos_token_id=tok.eos_token_id, bos_token_id=None, **(QWEN2_CPU if cpu else QWEN2_05B))
    torch.manual_seed(0)
    model = AutoModelForCausalLM.from_config(config, dtype=torch.float32 if cpu else torch.bfloat16)
    out = root / "model"
    model.save_pretrained(str(out), safe_serialization=True)
    tok.save_pretrained(str(out))
    n = sum(p.numel() for p in model.parameters())
    (out / "bench_params.json").write_text(json.dumps({"params": n, "head_params": head_params(config),
                                                       "vocab": config.vocab_size}))
    return str(out)


LENGTHS = ("even", "long-tail")


def sample_lengths(mix: str, batch: int, seq: int, seed: int = 0) -> list[int]:
    """Each sample's tokens: `even`, all `seq`; `long-tail`, bench/packing.py's log-normal mix
    rescaled to a cap of `seq` (between seq / 16 and seq, median about seq / 5.4), seeded."""
    if mix == "even":
        return [seq] * batch
    if mix == "long-tail":
        from packing import long_tail_batch

        return long_tail_batch(batch, seed, longest=seq)
    raise ValueError(f"--lengths: unknown mix {mix!r} (known: {', '.join(LENGTHS)})")


def synthetic_samples(batch: int, seq: int, vocab: int, seed: int = 0, lengths: list[int] | None = None):
    """Multi-turn episodes in token space: prompt, turn, tool result, turn (random ids); sample i has
    `lengths[i]` tokens (default: all `seq`)."""
    import random

    from actors.types import RolloutSample, TurnSpan

    lengths = lengths or [seq] * batch
    if len(lengths) != batch or min(lengths) < 4:
        raise ValueError(f"lengths: need {batch} lengths of at least 4 tokens, got {lengths}")
    rng = random.Random(seed)
    out = []
    for i, n in enumerate(lengths):
        prompt, tool = n // 4, n // 16
        turn = (n - prompt - tool) // 2
        ids = [rng.randrange(10, vocab) for _ in range(n)]
        mask = [0] * prompt + [1] * turn + [0] * tool + [1] * (n - prompt - turn - tool)
        turns = [TurnSpan(start=prompt, end=prompt + turn), TurnSpan(start=prompt + turn + tool, end=n)]
        out.append(RolloutSample(sample_id=f"s{i}", task_id=f"t{i // 4}", domain="bench", group_id=f"g{i // 4}",
                                 seed=i, prompt_length=prompt, input_ids=ids, loss_mask=mask,
                                 sampling_logprobs=[0.0] * n, policy_versions=[0 if m else -1 for m in mask],
                                 turns=turns, reward=float(i % 2), correct=bool(i % 2), response_tokens=sum(mask)))
    return out


ARMS = {"padded": False, "packed": "auto"}  # learner.pack_sequences of each arm


def arm_figures(step_seconds: list[float], real_tokens: int, loss_tokens: int, padding_fracs: list[float],
                meta: dict, peak, reference: bool) -> dict:
    """One arm's figures from its timed steps: tokens/s and MFU count the real tokens of a step
    (`real_tokens`, `loss_tokens`: per step), never its padding positions."""
    dt, steps = sum(step_seconds), len(step_seconds)
    flops = learner_step_flops(meta["params"], meta["head_params"], steps * real_tokens, steps * loss_tokens,
                               reference=reference)
    return {"learner_tokens_per_s": steps * real_tokens / dt, "learner_step_s": dt / steps,
            "learner_step_s_each": step_seconds, "learner_padding_frac": sum(padding_fracs) / steps,
            "tflops_achieved": flops / dt / 1e12, "mfu": mfu(flops, dt, peak)}


def part_learner(args) -> dict:
    import torch

    from modeling.attention import decoder_config
    from modeling.config_models import LearnerConfig
    from learner.learner_actor import Learner

    meta = json.loads((Path(args.model_dir) / "bench_params.json").read_text())
    cuda = not args.cpu
    learners = {}
    for arm, pack in ARMS.items():
        cfg = LearnerConfig(backend="deepspeed", device="cuda" if cuda else "cpu",
                            dtype="bfloat16" if cuda else "float32", gradient_checkpointing=True,
                            pack_sequences=pack, optim={"lr": 1e-6, "micro_batch_size": args.micro_batch},
                            deepspeed={"world_size": 1, "num_gpus_per_rank": 1 if cuda else 0})
        learners[arm] = Learner(cfg, args.model_dir, seed=0)
    lengths = sample_lengths(args.lengths, args.batch, args.seq)
    samples = synthetic_samples(args.batch, args.seq, meta["vocab"], lengths=lengths)
    sync = torch.cuda.synchronize if cuda else (lambda: None)
    for learner in learners.values():
        learner.train_step(samples)  # warm-up (allocations, kernels)
    sync()
    seconds: dict[str, list[float]] = {arm: [] for arm in ARMS}
    padding: dict[str, list[float]] = {arm: [] for arm in ARMS}
    order = list(ARMS)
    for k in range(args.steps):
        for arm in (order if k % 2 == 0 else order[::-1]):  # neither arm always runs on a warmer machine
            t0 = time.perf_counter()
            metrics = learners[arm].train_step(samples)
            sync()
            seconds[arm].append(time.perf_counter() - t0)
            padding[arm].append(metrics["learner_padding_frac"])
    real = sum(len(s.input_ids) for s in samples)
    loss_tokens = sum(sum(s.loss_mask) for s in samples)
    peak = device_peak(torch.cuda.get_device_name(0) if cuda else "cpu", args.peak_tflops)
    reference = learners["packed"].config.loss.grpo.kl_beta > 0
    arms = {arm: arm_figures(seconds[arm], real, loss_tokens, padding[arm], meta, peak, reference) for arm in ARMS}
    # The packed arm's attention: flash attention where installed on the GPU, else sdpa_varlen.
    attention = getattr(decoder_config(learners["packed"]._local.backend.policy), "_attn_implementation", None)
    for learner in learners.values():
        learner.shutdown()
    return {**{k: v for k, v in arms["packed"].items() if k != "learner_step_s_each"},
            "tokens_per_step": real, "loss_tokens_per_step": loss_tokens,
            "lengths": args.lengths,
            "sample_lengths": lengths, "micro_batch": args.micro_batch, "steps_per_arm": args.steps,
            "packed_attention": attention, "arms": arms,
            "packed_over_padded_tokens_per_s": arms["packed"]["learner_tokens_per_s"]
            / arms["padded"]["learner_tokens_per_s"],
            "params": meta["params"], "head_params": meta["head_params"],
            "peak_tflops": peak.tflops, "peak_reason": peak.reason,
            "max_mem_gib": torch.cuda.max_memory_allocated() / 2**30 if cuda else None}


def part_vllm(args) -> dict:
    try:
        from vllm import LLM, SamplingParams
    except ImportError as exc:
        return {"error": f"vllm not installed in {sys.executable} ({exc}); pass --vllm-python with the vLLM "
                         "venv's python (~/hcgym-vllm/bin/python on cluster.yaml nodes, docs/cluster.md)"}
    import random

    vocab = json.loads((Path(args.model_dir) / "bench_params.json").read_text())["vocab"]
    # CPU build: the fraction is of host RAM (0.1 starts on a shared box), no chunked prefill.
    options = ({"gpu_memory_utilization": 0.1, "enforce_eager": True,
                "max_num_batched_tokens": args.seq + args.new_tokens} if args.cpu
               else {"gpu_memory_utilization": 0.6})
    llm = LLM(model=args.model_dir, dtype="float32" if args.cpu else "bfloat16",
              max_model_len=args.seq + args.new_tokens, seed=0, **options)
    rng = random.Random(0)
    prompts = [{"prompt_token_ids": [rng.randrange(10, vocab) for _ in range(args.seq // 4)]}
               for _ in range(args.prompts)]
    params = SamplingParams(temperature=1.0, max_tokens=args.new_tokens, ignore_eos=True, logprobs=1)
    llm.generate(prompts[:4], params)  # warm-up
    t0 = time.perf_counter()
    outs = llm.generate(prompts, params)
    dt = time.perf_counter() - t0
    generated = sum(len(o.outputs[0].token_ids) for o in outs)
    return {"vllm_tokens_per_s": generated / dt, "vllm_prompts": args.prompts, "vllm_new_tokens": args.new_tokens,
            "python": sys.executable}


def run_part(args, part: str, model_dir: str, python: str) -> dict:
    """One half in its own interpreter; its figures, or the reason it has none."""
    cmd = [python, __file__, "--part", part, "--model-dir", model_dir, "--steps", str(args.steps),
           "--batch", str(args.batch), "--micro-batch", str(args.micro_batch), "--seq", str(args.seq),
           "--lengths", args.lengths,
           "--prompts", str(args.prompts), "--new-tokens", str(args.new_tokens)]
    if args.peak_tflops is not None:
        cmd += ["--peak-tflops", str(args.peak_tflops)]
    if args.cpu:
        cmd.append("--cpu")
    env = {**os.environ, "DS_ACCELERATOR": "cpu" if args.cpu else "cuda"}
    if args.cpu:  # vLLM's CPU build: a 1 GiB KV cache, the engine core in this process (no spawn)
        env.setdefault("VLLM_CPU_KVCACHE_SPACE", "1")
        env.setdefault("VLLM_ENABLE_V1_MULTIPROCESSING", "0")
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False, timeout=args.part_timeout)
    except subprocess.TimeoutExpired as exc:
        tail = exc.stderr or ""
        tail = tail.decode(errors="replace") if isinstance(tail, bytes) else tail
        return {"error": f"timed out after {args.part_timeout:.0f}s", "stderr_tail": tail[-2000:]}
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    if proc.returncode != 0 or not lines:
        return {"error": f"exit {proc.returncode}", "python": python, "stderr_tail": proc.stderr[-3000:]}
    return {**json.loads(lines[-1][len("RESULT "):]), "wall_s": time.perf_counter() - t0}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=5)
    parser.add_argument("--batch", type=int, default=8)
    parser.add_argument("--micro-batch", type=int, default=2)
    parser.add_argument("--seq", type=int, default=2048, help="tokens per sample (even), the longest (long-tail)")
    parser.add_argument("--lengths", choices=LENGTHS, default="even",
                        help="the learner half's sample lengths: all --seq, or a seeded log-normal long tail")
    parser.add_argument("--prompts", type=int, default=64)
    parser.add_argument("--new-tokens", type=int, default=512)
    parser.add_argument("--peak-tflops", type=float, default=None,
                        help="dense bf16 peak of the GPU (default: from the device model; unknown -> no MFU)")
    parser.add_argument("--vllm-python", default="auto", help="interpreter with vLLM for the vLLM half")
    parser.add_argument("--json-out", default=None, help="figures file, rewritten as each half ends")
    parser.add_argument("--part-timeout", type=float, default=600.0, help="seconds each half may take")
    parser.add_argument("--parts", default="learner,vllm", help="comma-separated halves to run")
    parser.add_argument("--cpu", action="store_true", help="rehearse on the CPU (tiny model, gloo, vLLM CPU build)")
    parser.add_argument("--part", choices=["learner", "vllm"], default=None, help=argparse.SUPPRESS)
    parser.add_argument("--model-dir", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    parts = [p for p in args.parts.split(",") if p]
    if unknown := sorted(set(parts) - {"learner", "vllm"}):
        parser.error(f"--parts: unknown {unknown} (learner, vllm)")

    if args.part:
        result = part_learner(args) if args.part == "learner" else part_vllm(args)
        print("RESULT " + json.dumps(result))
        return 0
    name = "cpu" if args.cpu else detect_gpu("bench/gpu_step.py")
    if name is None:
        return 0
    import torch

    log = FigureLog(args.json_out, {"bench": "gpu_step", "device": name, "torch": torch.__version__,
                                    "cpu_rehearsal": args.cpu})
    try:
        vllm_python = resolve_vllm_python(args.vllm_python) if "vllm" in parts else None
    except ValueError as exc:
        log.record("vllm", {"error": str(exc)})
        parts, vllm_python = [p for p in parts if p != "vllm"], None
    t0 = time.perf_counter()
    model_dir = build_model(Path(tempfile.mkdtemp(prefix="bench_gpu_")), cpu=args.cpu)
    log.record("build", {"seconds": time.perf_counter() - t0, "model_dir": model_dir})
    for part in parts:
        log.record(part, run_part(args, part, model_dir, sys.executable if part == "learner" else vllm_python))
    return 0


if __name__ == "__main__":
    sys.exit(main())
