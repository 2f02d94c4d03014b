"""GPU smoke test of the whole loop on one GPU: vLLM CUDA generation, 3 ZeRO-3 learner steps on what
it sampled, a weight sync learner -> vLLM, and vLLM sampling again with the new weights.

Prints generation tokens/s, learner tokens/s, MFU, the weight-sync time and transport, and the
learner-vs-vLLM log-prob gap on the tokens vLLM sampled after the sync (bf16 on both sides: expect a
few 1e-2 at most; a gap near the random-init entropy would mean the sync did not land). Each phase
prints its figures as soon as it ends (`PHASE <name> {...}`) and `--json-out` is rewritten after
each, so a later failure keeps what was measured.

Without a GPU it prints why and exits with status 0 (so `make bench` passes on CPU machines);
`--cpu` rehearses the same phases on the CPU (tiny Qwen3, DeepSpeed on CPU, vLLM's CPU build,
gloo). Without vLLM in the generator's interpreter (`--vllm-python`, default: this one if it
imports vllm, else `.venv-vllm`; on cluster nodes `~/hcgym-vllm/bin/python`) it says which install
is missing.

The pieces are the production ones, as Ray actors on a local cluster with one GPU shared by
fractions: `GeneratorService` with the `vllm` backend (actors/generator_vllm.py), `LearnerActor`
with `backend: deepspeed` (ZeRO-3, 1 rank, bf16), and `modeling.weight_sync`. The learner and the
generator share the GPU, so the weight-sync group picks its colocated transport (gloo, buckets
staged through CPU memory: NCCL refuses two ranks on one device); the JSON records which.

The model: Qwen3 in the 0.6B shape (hidden 1024, 28 layers, 16 heads, 8 KV heads, head_dim 128,
intermediate 3072, vocabulary 151,936, tied embeddings), random init from the config (no hub),
with a locally trained tokenizer (prompts are token ids, so its size does not matter).
FLOPs = 8 (N - N_head) tokens + 8 N_head loss_tokens (bench/gpu_figures.py), MFU against the
device model's dense bf16 peak (none for an unknown device).

Run: python bench/gpu_smoke.py [--prompts 32] [--new-tokens 256] [--json-out F] [--cpu]
"""

from __future__ import annotations

import argparse
import json
import random
import socket
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from gpu_figures import FigureLog, Peak, device_peak, head_params, learner_step_flops, mfu  # noqa: E402
from gpu_step import detect_gpu  # noqa: E402

VOCAB = 151_936
QWEN3_06B = {"hidden_size": 1024, "intermediate_size": 3072, "num_hidden_layers": 28, "num_attention_heads": 16,
             "num_key_value_heads": 8, "head_dim": 128, "tie_word_embeddings": True, "max_position_embeddings": 40960,
             "rope_theta": 1_000_000.0, "rms_norm_eps": 1e-6}
# --cpu: the same architecture at a size the CPU runs in seconds (head_dim 64 for vLLM's CPU attention).
QWEN3_CPU = {"hidden_size": 128, "intermediate_size": 256, "num_hidden_layers": 2, "num_attention_heads": 2,
             "num_key_value_heads": 1, "head_dim": 64, "tie_word_embeddings": True, "max_position_embeddings": 4096,
             "rope_theta": 1_000_000.0, "rms_norm_eps": 1e-6}
VOCAB_CPU = 4096


def build_model(root: Path, cpu: bool = False) -> tuple[str, int, int, int]:
    """Save the Qwen3 (bf16; fp32 tiny with `cpu`) with a local tokenizer; returns (dir, params,
    LM-head params, stop id)."""
    import torch
    from transformers import AutoModelForCausalLM, Qwen3Config

    from modeling.model import IM_END, load_tokenizer, train_tokenizer

    tok = load_tokenizer(train_tokenizer(["Healthcare AI GYM GPU smoke corpus."] * 10, 4096, root / "tok",
                                         max_stdlib_files=100))
    stop_id = tok.convert_tokens_to_ids(IM_END)
    config = Qwen3Config(vocab_size=VOCAB_CPU if cpu else VOCAB, pad_token_id=tok.pad_token_id,
                         eos_token_id=stop_id, bos_token_id=None, **(QWEN3_CPU if cpu else QWEN3_06B))
    config.architectures = ["Qwen3ForCausalLM"]
    torch.manual_seed(0)
    model = AutoModelForCausalLM.from_config(config, dtype=torch.float32 if cpu else torch.bfloat16)
    out = root / "model"
    model.save_pretrained(str(out))
    tok.save_pretrained(str(out))
    return str(out), sum(p.numel() for p in model.parameters()), head_params(config), stop_id


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def requests_for(prompts: list[list[int]], new_tokens: int, version: int, seed: int):
    from actors.generator import GenerationRequest

    return [GenerationRequest(request_id=f"p{i}", prompt_ids=p, max_new_tokens=new_tokens, seed=seed + i,
                              min_version=version) for i, p in enumerate(prompts)]


def rollout_samples(requests, results, group_size: int = 4):
    """Prompt + sampled completion as `RolloutSample`s in groups, rewards alternating within a group."""
    from actors.types import RolloutSample, TurnSpan

    samples = []
    for i, (req, res) in enumerate(zip(requests, results)):
        n_prompt, n_new = len(req.prompt_ids), len(res.token_ids)
        samples.append(RolloutSample(
            sample_id=f"s{i}", task_id=f"t{i // group_size}", domain="bench", group_id=f"g{i // group_size}",
            seed=req.seed, prompt_length=n_prompt, input_ids=req.prompt_ids + res.token_ids,
            loss_mask=[0] * n_prompt + [1] * n_new, sampling_logprobs=[0.0] * n_prompt + res.logprobs,
            policy_versions=[-1] * n_prompt + [res.policy_version] * n_new,
            turns=[TurnSpan(start=n_prompt, end=n_prompt + n_new)], reward=float(i % 2), correct=bool(i % 2),
            response_tokens=n_new))
    return samples


def run(args, model_dir: str, params: int, n_head: int, stop_id: int, runtime_env: dict | None,
        log: FigureLog, peak: Peak | None) -> None:
    import ray

    from actors.generator import generator_actor_class
    from modeling.config_models import LearnerConfig, WeightSyncConfig
    from learner.learner_actor import LearnerActor

    from envs._runtime import init_ray  # a local cluster on 127.0.0.1 only

    cpu = args.cpu
    vocab = VOCAB_CPU if cpu else VOCAB
    init_ray(num_gpus=0 if cpu else 1, include_dashboard=False)
    max_len = args.prompt_tokens + args.new_tokens + 16
    gen_cls = generator_actor_class().options(num_gpus=0 if cpu else 0.4, num_cpus=0, max_concurrency=1000,
                                              runtime_env=runtime_env)
    if cpu:  # vLLM's CPU build: fp32, eager, a 1 GiB KV cache, a RAM fraction that fits a shared box
        options = {"dtype": "float32", "gpu_memory_utilization": 0.1, "max_model_len": max_len,
                   "enforce_eager": True, "cpu_kvcache_space_gib": 1, "enable_prefix_caching": False}
    else:
        options = {"dtype": "bfloat16", "gpu_memory_utilization": 0.35, "max_model_len": max_len,
                   "enable_prefix_caching": False}
    t0 = time.perf_counter()
    generator = gen_cls.remote("vllm", model_dir, {"temperature": 1.0}, [stop_id], 0, options, args.prompts, 0.01)
    ray.get(generator.version.remote())
    start_s = time.perf_counter() - t0

    rng = random.Random(0)
    prompts = [[rng.randrange(10, vocab) for _ in range(args.prompt_tokens)] for _ in range(args.prompts)]
    ray.get([generator.generate.remote(r) for r in requests_for(prompts[:4], 16, 0, 999)])  # warm-up
    requests = requests_for(prompts, args.new_tokens, 0, 0)
    t0 = time.perf_counter()
    results = ray.get([generator.generate.remote(r) for r in requests])
    dt = time.perf_counter() - t0
    generated = sum(len(r.token_ids) for r in results)
    log.record("vllm_generation", {"engine_start_s": start_s, "prompts": args.prompts, "generated_tokens": generated,
                                   "seconds": dt, "tokens_per_s": generated / dt})

    learner_cfg = LearnerConfig(backend="deepspeed", device="cpu" if cpu else "cuda",
                                dtype="float32" if cpu else "bfloat16", gradient_checkpointing=True,
                                optim={"lr": 1e-5, "micro_batch_size": args.micro_batch},
                                deepspeed={"world_size": 1, "num_gpus_per_rank": 0 if cpu else 1})
    learner = LearnerActor.options(num_gpus=0 if cpu else 0.5, num_cpus=0).remote(learner_cfg.model_dump(),
                                                                                 model_dir, 0)
    samples = rollout_samples(requests, results)
    tokens = sum(len(s.input_ids) for s in samples)
    loss_tokens = sum(sum(s.loss_mask) for s in samples)
    step_s = []
    for _ in range(3):
        t0 = time.perf_counter()
        metrics = ray.get(learner.train_step.remote(samples))
        step_s.append(time.perf_counter() - t0)
    # The first step pays DeepSpeed's warm-up; rates from steps 2-3.
    steady = sum(step_s[1:]) / len(step_s[1:])
    flops = learner_step_flops(params, n_head, tokens, loss_tokens, reference=learner_cfg.loss.grpo.kl_beta > 0)
    log.record("learner_steps", {
        "step_s": step_s, "tokens_per_step": tokens, "loss_tokens_per_step": loss_tokens,
        "tokens_per_s": tokens / steady, "tflops_achieved": flops / steady / 1e12,
        "mfu": mfu(flops, steady, peak) if peak is not None else None,
        "step1_logprob_abs_diff": metrics["logprob_abs_diff"]})

    sync = WeightSyncConfig(transport="collective", backend="nccl", bucket_mb=512, timeout_s=300,
                            master_addr="127.0.0.1", master_port=free_port()).model_dump()
    names = ["learner-rank0", "vllm-0"]
    chosen, _ = ray.get([learner.join_weight_sync.remote(sync, 2, names),
                         generator.join_weight_sync.remote(sync, 1, 2, names)])
    version = ray.get(learner.policy_version.remote())
    t0 = time.perf_counter()
    received = generator.receive_weights.remote(version)
    sent = ray.get(learner.broadcast_weights.remote())
    ray.get(received)
    dt = time.perf_counter() - t0
    log.record("weight_sync", {"transport": chosen["transport"], "reason": chosen["reason"], "seconds": dt,
                               "gib": sent["bytes"] / 2**30, "gib_per_s": sent["bytes"] / 2**30 / dt,
                               "buckets": sent["buckets"], "version": version})

    after = requests_for(prompts[:8], 64, version, 100)
    fresh = ray.get([generator.generate.remote(r) for r in after])
    check = ray.get(learner.evaluate_loss.remote(rollout_samples(after, fresh)))
    # Tokens sampled by vLLM after the sync, scored by the learner's current weights.
    log.record("post_sync_logprobs", {"logprob_abs_diff": check["logprob_abs_diff"],
                                      "tokens": sum(len(r.token_ids) for r in fresh)})
    ray.get(learner.shutdown.remote())
    ray.shutdown()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--prompts", type=int, default=32)
    parser.add_argument("--prompt-tokens", type=int, default=512)
    parser.add_argument("--new-tokens", type=int, default=256)
    parser.add_argument("--micro-batch", type=int, default=4)
    parser.add_argument("--peak-tflops", type=float, default=None,
                        help="dense bf16 peak of the GPU (default: from the device model; unknown -> no MFU)")
    parser.add_argument("--vllm-python", default="auto", help="interpreter with vLLM (generator.python_executable)")
    parser.add_argument("--json-out", default=None, help="figures file, rewritten as each phase ends")
    parser.add_argument("--cpu", action="store_true", help="rehearse on the CPU (tiny model, gloo, vLLM CPU build)")
    args = parser.parse_args(argv)

    name = "cpu" if args.cpu else detect_gpu("bench/gpu_smoke.py")
    if name is None:
        return 0
    import torch
    from learner.config import GeneratorConfig

    peak = device_peak(name, args.peak_tflops) if not args.cpu else None
    log = FigureLog(args.json_out, {"bench": "gpu_smoke", "device": name, "torch": torch.__version__,
                                    "cpu_rehearsal": args.cpu,
                                    "peak": peak.model_dump() if peak else {"reason": "CPU rehearsal: no MFU"}})
    if peak is not None:
        print(f"bench/gpu_smoke.py: peak: {peak.reason}")
    try:  # the generator's interpreter: --vllm-python, or this one if it imports vllm, or .venv-vllm
        runtime_env = GeneratorConfig(backend="vllm", python_executable=args.vllm_python).runtime_env()
    except ValueError as exc:
        log.record("vllm_generation", {"error": f"no vLLM for the generator: {exc}"})
        return 1
    t0 = time.perf_counter()
    model_dir, params, n_head, stop_id = build_model(Path(tempfile.mkdtemp(prefix="gpu_smoke_")), cpu=args.cpu)
    log.record("build", {"seconds": time.perf_counter() - t0, "params": params, "head_params": n_head})
    try:
        run(args, model_dir, params, n_head, stop_id, runtime_env, log, peak)
    finally:
        log.set("finished", time.strftime("%Y-%m-%dT%H:%M:%S%z"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
