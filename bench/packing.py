"""Sequence packing on CPU: the learner's forward + backward of one micro-batch, padded vs packed.

A micro-batch of 8 sequences, with a long-tail length mix (most short, two long) and with an even one, on a
tiny Qwen3 model (hidden 64, 2 layers), on a wider one (hidden 256, 4 layers) and on the Qwen3.5 twin
(hidden 128, one Gated DeltaNet linear-attention layer and one full-attention layer; packed, the
linear-attention layer runs each sequence on its own), through
`modeling.model.token_stats` (the learner's forward: LM head on the trained positions only) and its
backward. Packed, the decoder runs on the real tokens only, but attention under sdpa takes a dense
block-diagonal [N, N] mask over the whole packed row; padded, each row attends over its own [T, T].
Prints tokens/s of both and the ratio packed / padded (the baseline), and the padding share.

    .venv/bin/python bench/packing.py
"""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

import torch

from modeling.model import build_tiny_model, build_twin_model, load_policy, pad_batch, token_stats, train_tokenizer

MIXES = {"long tail": [96, 128, 160, 192, 256, 384, 1024, 2048],  # two long episodes among short ones
         "even": [480, 496, 512, 512, 512, 528, 528, 544]}         # little padding to remove
ROUNDS = 5


def timed(model, ids, mask, trained, packed: bool) -> float:
    times = []
    for _ in range(ROUNDS):
        model.zero_grad()
        start = time.perf_counter()
        token_stats(model, ids, mask, positions=trained, packed=packed).logprobs.sum().backward()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    torch.manual_seed(0)
    root = Path(tempfile.mkdtemp(prefix="bench_packing_"))
    tok = train_tokenizer(["the patient was given warfarin and aspirin"] * 200, 512, root / "tok", max_stdlib_files=5)
    sizes = {"tiny (hidden 64, 2 layers)": dict(hidden_size=64, intermediate_size=128, num_hidden_layers=2,
                                                num_attention_heads=4, num_key_value_heads=2, head_dim=16),
             "wider (hidden 256, 4 layers)": dict(hidden_size=256, intermediate_size=768, num_hidden_layers=4,
                                                  num_attention_heads=4, num_key_value_heads=2, head_dim=64)}
    models = {name: load_policy(build_tiny_model(root / name.split()[0], tok, seed=0, **size))[0]
              for name, size in sizes.items()}
    models["Qwen3.5 twin (hidden 128, linear + full attention)"] = load_policy(
        build_twin_model("qwen3_5", root / "qwen3_5", tok, seed=0))[0]
    print(f"torch {torch.__version__}, threads {torch.get_num_threads()}, sdpa attention, median of {ROUNDS}")
    for mix, lengths in MIXES.items():
        generator = torch.Generator().manual_seed(0)
        ids, mask = pad_batch([torch.randint(5, 500, (n,), generator=generator).tolist() for n in lengths], 0)
        trained = mask.bool().clone()
        trained[:, :32] = False
        real = int(mask.sum())
        print(f"{mix}: {len(lengths)} sequences, {real} real tokens, padded to {mask.numel()} "
              f"(padding {1 - real / mask.numel():.1%})")
        for name, model in models.items():
            model.train()
            padded = timed(model, ids, mask, trained, packed=False)
            packed = timed(model, ids, mask, trained, packed=True)
            print(f"  {name}: padded {real / padded:,.0f} tok/s ({padded * 1000:.0f} ms), packed "
                  f"{real / packed:,.0f} tok/s ({packed * 1000:.0f} ms); packed / padded = {padded / packed:.2f}x")


if __name__ == "__main__":
    main()
