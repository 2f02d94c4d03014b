"""Sequence packing on CPU: the learner's forward + backward of one micro-batch, padded vs packed.

A micro-batch of 8 sequences, with a long-tail length mix (most short, two long) and with an even one, on a
tiny Qwen3 model (hidden 64, 2 layers), on a wider one (hidden 256, 4 layers) and on the Qwen3.5 twin
(hidden 128, one Gated DeltaNet linear-attention layer and one full-attention layer; packed, the
linear-attention layer runs each sequence on its own), through
`modeling.model.token_stats` (the learner's forward: LM head on the trained positions only) and its
backward. Padded, each row attends over its own [T, T]. Packed, the decoder runs on the real tokens
only, and attention either runs per sequence (`sdpa_varlen`, modeling/attention.py, what the learner
and teacher load with: sum of L^2, no mask) or, under plain sdpa, through a dense block-diagonal
[N, N] mask over the whole packed row. Prints tokens/s of the three and the ratios packed / padded
(the baseline), and the padding share.

Then micro-batches by length: a long-tail batch of 32 sequences (64 tokens and up, at most 1,024, in a shuffled
order as a step's episodes arrive) cut into micro-batches of 8 in batch order and after sorting by
length (`modeling.model.split_by_length`, the learner's `optim.micro_batch_order: length`), each
micro-batch padded or packed as `pack_sequences: auto` decides: under plain sdpa (packed only where
N^2 <= B*T^2) and under sdpa_varlen (always packed); prints the padding fractions and the whole
batch's forward + backward time, and the ratios, on the tiny and the wider model.

With `--run RUN_DIR` (a finished `hcgym train` run, e.g. the demo's): its steps' batches (trajectories
and the teacher log-probs stored with them) are trained again from RUN_DIR/model/sft by two learners of
the run's config, micro-batches in batch order and by length (`--compare packing`: by length, padded
and packed), alternating which goes first; prints each step's padding fraction and learner time
(reference forwards, forward + backward) of both.

    .venv/bin/python bench/packing.py [--only packing|micro-batches] [--run RUN_DIR [--compare order|packing]]
"""

from __future__ import annotations

import argparse
import math
import os
import random
import statistics
import tempfile
import time
from pathlib import Path

import torch

from modeling.attention import SDPA_VARLEN, decoder_config
from modeling.model import (build_tiny_model, build_twin_model, load_policy, pad_batch, packs_sequences, padding_fraction,
                            split_by_budget, split_by_length, token_stats, train_tokenizer)

MIXES = {"long tail": [96, 128, 160, 192, 256, 384, 1024, 2048],  # two long episodes among short ones
         "even": [480, 496, 512, 512, 512, 528, 528, 544]}         # little padding to remove
ROUNDS = 5


def attention(model, name: str):
    """Put `model`'s decoder on attention implementation `name` (sdpa or sdpa_varlen); returns the model."""
    decoder_config(model)._attn_implementation = name
    return model


def timed(model, ids, mask, trained, packed: bool) -> float:
    times = []
    for _ in range(ROUNDS):
        model.zero_grad()
        start = time.perf_counter()
        token_stats(model, ids, mask, positions=trained, packed=packed).logprobs.sum().backward()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def long_tail_batch(count: int = 32, seed: int = 0, longest: int = 1024) -> list[int]:
    """Episode lengths of a step: mostly short, a few long (a log-normal between 64 and 1,024 tokens,
    median about 190), in a shuffled order. `longest` rescales the mix (bounds and median) to another
    cap: between longest / 16 and longest, median about longest / 5.4 (bench/gpu_step.py's --seq)."""
    rng = random.Random(seed)
    mu = 5.25 + math.log(longest / 1024)
    return [max(longest // 16, min(longest, int(rng.lognormvariate(mu, 0.8)))) for _ in range(count)]


def timed_batch(model, sequences: list[list[int]], groups: list[list[int]]) -> tuple[float, float]:
    """(median seconds, padding fraction) of the forward + backward of every micro-batch in `groups`,
    each packed or padded as `pack_sequences: auto` decides."""
    batches = []
    padded = computed = 0
    for group in groups:
        ids, mask = pad_batch([sequences[i] for i in group], 0)
        trained = mask.bool().clone()
        trained[:, :32] = False
        packed = packs_sequences("auto", model, mask)
        pad, total = padding_fraction(mask, packed)
        padded, computed = padded + pad, computed + total
        batches.append((ids, mask, trained, packed))
    times = []
    for _ in range(ROUNDS):
        model.zero_grad()
        start = time.perf_counter()
        for ids, mask, trained, packed in batches:
            token_stats(model, ids, mask, positions=trained, packed=packed).logprobs.sum().backward()
        times.append(time.perf_counter() - start)
    return statistics.median(times), padded / computed


def micro_batches(models: dict) -> None:
    lengths = long_tail_batch()
    generator = torch.Generator().manual_seed(1)
    sequences = [torch.randint(5, 500, (n,), generator=generator).tolist() for n in lengths]
    real = sum(lengths)
    print(f"micro-batches of 8 from a long-tail batch: {len(lengths)} sequences, {real} tokens "
          f"({min(lengths)} ... {max(lengths)}, median {statistics.median(lengths):.0f}), pack_sequences auto")
    by_index = split_by_budget(list(range(len(lengths))), lengths, 8)
    by_length = split_by_length(list(range(len(lengths))), lengths, 8)
    for name, model in models.items():
        model.train()
        attention(model, "sdpa")
        index_s, index_pad = timed_batch(model, sequences, by_index)
        length_s, length_pad = timed_batch(model, sequences, by_length)
        attention(model, SDPA_VARLEN)
        varlen_s, varlen_pad = timed_batch(model, sequences, by_length)
        print(f"  {name}: sdpa, batch order: padding {index_pad:.1%}, {real / index_s:,.0f} tok/s "
              f"({index_s * 1000:.0f} ms); sdpa, by length: padding {length_pad:.1%}, {real / length_s:,.0f} tok/s "
              f"({length_s * 1000:.0f} ms); sdpa_varlen, by length: padding {varlen_pad:.1%}, "
              f"{real / varlen_s:,.0f} tok/s ({varlen_s * 1000:.0f} ms); sdpa by length / batch order = "
              f"{index_s / length_s:.2f}x, sdpa_varlen / sdpa by length = {length_s / varlen_s:.2f}x")


def replay_run(run_dir: Path, compare: str = "order") -> None:
    """Train a run's stored batches again with micro-batches in batch order and by length, or (`compare`
    "packing") by length padded and packed (see the module doc)."""
    from actors.types import TeacherBatch, TeacherOutput
    from learner.config import load_config
    from learner.learner_actor import Learner
    from learner.metrics import read_samples

    cfg = load_config(str(run_dir / "config.yaml"), [])
    steps = []
    for path in sorted((run_dir / "trajectories").glob("step_*.parquet")):
        samples, extras = read_samples(path)
        samples = [s for s in samples if extras[s.sample_id]["accepted"]]
        teacher = None
        if cfg.learner.loss.distill.enabled:
            teacher = TeacherBatch(outputs=[TeacherOutput(
                sample_id=s.sample_id, teacher_version=int(extras[s.sample_id]["teacher_version"]),
                hint=extras[s.sample_id]["teacher_hint"] or "none", input_length=len(s.input_ids),
                logprobs=list(extras[s.sample_id]["teacher_logprobs"])) for s in samples])
        steps.append((path.stem, samples, teacher))
    if not steps:
        raise FileNotFoundError(f"{run_dir}/trajectories: no step_*.parquet to replay")
    learners = {}
    arms = ("index", "length") if compare == "order" else ("padded", "packed")
    for arm in arms:
        learner_cfg = cfg.learner.model_copy(deep=True)
        if compare == "order":
            learner_cfg.optim.micro_batch_order = arm
        else:
            learner_cfg.optim.micro_batch_order = "length"
            learner_cfg.pack_sequences = arm == "packed"
        learners[arm] = Learner(learner_cfg, str(run_dir / "model" / "sft"), cfg.seed)
    print(f"{run_dir}: micro-batches of {cfg.learner.optim.micro_batch_size}, pack_sequences "
          f"{cfg.learner.pack_sequences}, arms {' / '.join(arms)}; seconds: learner (reference forwards, "
          f"forward + backward)")
    totals = dict.fromkeys(arms, 0.0)
    for k, (name, samples, teacher) in enumerate(steps):
        lengths = sorted(len(s.input_ids) for s in samples)
        line = []
        for order in (arms if k % 2 == 0 else arms[::-1]):
            m = learners[order].train_step(samples, teacher, step=k + 1)
            totals[order] += m["learner_s"]
            line.append(f"{order}: padding {m['learner_padding_frac']:.1%}, {m['learner_s']:.2f} s "
                        f"({m['learner_ref_s']:.2f}, {m['learner_forward_backward_s']:.2f})")
        print(f"  {name}: {len(samples)} samples, {lengths[0]} ... {lengths[-1]} tokens; " + "; ".join(line))
    print(f"  learner time {arms[1]} / {arms[0]}: {totals[arms[1]] / totals[arms[0]]:.2f}")
    for learner in learners.values():
        learner.shutdown()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--only", choices=("packing", "micro-batches"), help="run one of the two measurements")
    parser.add_argument("--run", type=Path, help="replay this run's batches in batch order and by length, only")
    parser.add_argument("--compare", choices=("order", "packing"), default="order",
                        help="with --run: batch order vs by length, or (by length) padded vs packed")
    args = parser.parse_args()
    torch.manual_seed(0)
    if args.run is not None:
        replay_run(args.run, args.compare)
        return
    root = Path(tempfile.mkdtemp(prefix="bench_packing_"))
    tok = train_tokenizer(["the patient was given warfarin and aspirin"] * 200, 512, root / "tok", max_stdlib_files=5)
    sizes = {"tiny (hidden 64, 2 layers)": dict(hidden_size=64, intermediate_size=128, num_hidden_layers=2,
                                                num_attention_heads=4, num_key_value_heads=2, head_dim=16),
             "wider (hidden 256, 4 layers)": dict(hidden_size=256, intermediate_size=768, num_hidden_layers=4,
                                                  num_attention_heads=4, num_key_value_heads=2, head_dim=64)}
    models = {name: load_policy(build_tiny_model(root / name.split()[0], tok, seed=0, **size))[0]
              for name, size in sizes.items()}
    print(f"torch {torch.__version__}, threads {torch.get_num_threads()}, load average "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}, median of {ROUNDS}")
    if args.only != "packing":
        micro_batches(models)
    if args.only == "micro-batches":
        return
    models["Qwen3.5 twin (hidden 128, linear + full attention)"] = load_policy(
        build_twin_model("qwen3_5", root / "qwen3_5", tok, seed=0))[0]
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
            padded = timed(attention(model, SDPA_VARLEN), ids, mask, trained, packed=False)  # = sdpa's padded
            varlen = timed(model, ids, mask, trained, packed=True)
            dense = timed(attention(model, "sdpa"), ids, mask, trained, packed=True)
            print(f"  {name}: padded {real / padded:,.0f} tok/s ({padded * 1000:.0f} ms), packed sdpa_varlen "
                  f"{real / varlen:,.0f} tok/s ({varlen * 1000:.0f} ms), packed sdpa (dense mask) "
                  f"{real / dense:,.0f} tok/s ({dense * 1000:.0f} ms); packed / padded = {padded / varlen:.2f}x "
                  f"sdpa_varlen, {padded / dense:.2f}x sdpa")


if __name__ == "__main__":
    main()
