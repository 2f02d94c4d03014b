"""`hcgym plan`: its figures for the shipped 9B configs against hand computations, its parameter
formula against transformers' own Qwen3.5 model, and its refusal of a config that does not fit."""

from __future__ import annotations

from pathlib import Path

import pytest

from learner.config import load_config
from modeling.plan import (BUILTIN_CONFIGS, GIB, MIB, architecture_from_config, format_plan, plan_run,
                           qwen3_5_vision_parameters, text_parameters)

REPO_ROOT = Path(__file__).resolve().parents[2]
GRPO = REPO_ROOT / "configs" / "qwen35_9b_grpo.yaml"
TTOPD = REPO_ROOT / "configs" / "qwen35_9b_ttopd.yaml"
SHIPPED = [GRPO, TTOPD, *sorted((REPO_ROOT / "configs" / "ablations").glob("*.yaml"))]

# Qwen3.5-9B by hand (model card / transformers 5.19 defaults): h 4096, 32 layers = 8 full + 24 linear.
H, I, V = 4096, 12288, 248320
EMBED = V * H                                       # 1,017,118,720 (and the same again for the untied LM head)
MLP_AND_NORMS = 3 * H * I + 2 * H                   # gate/up/down + input and post-attention RMSNorm
FULL_ATTN = (H * (16 * 256 * 2)                     # q_proj: 16 heads x 256, doubled for the output gate
             + 2 * H * (4 * 256)                    # k_proj, v_proj: 4 KV heads x 256
             + (16 * 256) * H                       # o_proj
             + 2 * 256)                             # q_norm, k_norm
QKV = 2 * 16 * 128 + 32 * 128                       # GatedDeltaNet q, k (16 heads x 128) and v (32 x 128) = 8192
LINEAR_ATTN = (H * QKV                              # in_proj_qkv
               + H * 32 * 128                       # in_proj_z
               + 2 * H * 32                         # in_proj_b, in_proj_a
               + QKV * 4                            # depthwise conv1d, kernel 4
               + 2 * 32                             # dt_bias, A_log
               + 128                                # gated RMSNorm over the head dim
               + 32 * 128 * H)                      # out_proj
TEXT_9B = 2 * EMBED + 8 * (FULL_ATTN + MLP_AND_NORMS) + 24 * (LINEAR_ATTN + MLP_AND_NORMS) + H
VISION_9B = 456_010_480                             # transformers 5.19 Qwen3_5VisionModel, counted (test below)
N_9B = TEXT_9B + VISION_9B


def test_the_9b_parameter_count_is_the_hand_count_and_transformers_own_model():
    arch = architecture_from_config(BUILTIN_CONFIGS["Qwen/Qwen3.5-9B"])
    assert text_parameters(arch) == TEXT_9B == 8_953_803_264
    assert arch.vision_params == VISION_9B
    assert (arch.full_attention_layers, arch.linear_attention_layers) == (8, 24)
    # The same config through transformers' own classes, on the meta device (no memory, no weights),
    # with one block of the 3:1 pattern instead of eight (the other seven repeat it).
    import torch
    from transformers import Qwen3_5Config, Qwen3_5ForConditionalGeneration

    builtin = BUILTIN_CONFIGS["Qwen/Qwen3.5-9B"]
    config = Qwen3_5Config(text_config={**builtin["text_config"], "num_hidden_layers": 4},
                           vision_config=builtin["vision_config"], tie_word_embeddings=False)
    with torch.device("meta"):
        model = Qwen3_5ForConditionalGeneration(config)
    vision = sum(p.numel() for n, p in model.named_parameters() if n.startswith("model.visual."))
    assert vision == qwen3_5_vision_parameters(builtin["vision_config"]) == VISION_9B
    block = 2 * EMBED + (FULL_ATTN + MLP_AND_NORMS) + 3 * (LINEAR_ATTN + MLP_AND_NORMS) + H + VISION_9B
    assert sum(p.numel() for p in model.parameters()) == block


def test_a_checkpoint_config_json_is_read_before_the_builtin_table(tmp_path):
    import json

    (tmp_path / "config.json").write_text(json.dumps({
        "model_type": "qwen3", "vocab_size": 1000, "hidden_size": 64, "intermediate_size": 128,
        "num_hidden_layers": 2, "num_attention_heads": 4, "num_key_value_heads": 2, "head_dim": 16,
        "tie_word_embeddings": True}))
    cfg = load_config(GRPO, [f"model.path={tmp_path}"])
    plan = plan_run(cfg, "a100-80gb")
    # embed + 2 x (q 64x64, k and v 64x32, o 64x64, q/k norms 2x16, MLP 3x64x128, 2 norms) + final norm; tied head
    assert plan.parameters == 1000 * 64 + 2 * (64 * 64 + 2 * 64 * 32 + 64 * 64 + 2 * 16 + 3 * 64 * 128 + 2 * 64) + 64
    assert plan.architecture_source == str(tmp_path / "config.json")


def items(plan, actor: str) -> dict[str, tuple[float, str]]:
    found = next(a for a in plan.actors if a.actor.startswith(actor))
    return {i.name: (i.gib, i.where) for i in found.items}


def test_grpo_9b_on_a100_80gb_matches_the_hand_computation():
    plan = plan_run(load_config(GRPO), "a100-80gb")
    n, n_t, w = N_9B, TEXT_9B, 4                   # all parameters, trained ones (vision frozen), ranks
    learner = items(plan, "learner")
    expected = {
        "policy params (bfloat16, 1/4)": 2 * n / w,           # 4.38 GiB
        "KL reference params (bfloat16, 1/4)": 2 * n / w,     # kl_beta 0.01: a frozen reference engine
        "fp32 master weights": 4 * n_t / w,                  # 8.34 GiB
        "Adam m and v (fp32)": 8 * n_t / w,                  # 16.68 GiB
        "gradient partition (bfloat16)": 2 * n_t / w,        # 4.17 GiB
        "fp32 gradients of one optimizer sub-group": 4 * 1e9,  # sub_group_size 1e9 < 2.24e9 per rank
        "ZeRO-3 gathered module + prefetch + reduce bucket": 2 * (V * H + 5e7) + 2 * 5e8,
        # micro-batch 1, s = 8192 + 12288 = 20480: each layer's input kept ...
        "activations: layer inputs (checkpointed)": 32 * 20480 * H * 2,
        # ... one layer recomputed: 4h + P (GatedDeltaNet qkv 8192 + z 4096 + b, a 64 + core 4096) + 4I
        "activations: one layer recomputed": 20480 * 2 * (4 * H + (8192 + 4096 + 64 + 4096) + 4 * I),
        "activations: LM-head chunk": 1024 * V * 4 * 3,
    }
    assert set(learner) == set(expected)
    for name, value in expected.items():
        assert learner[name][0] == pytest.approx(value / GIB, rel=1e-9), name
        assert learner[name][1] == "gpu", name                   # offload is off in the shipped config
    rank = sum(expected.values()) / GIB
    assert rank == pytest.approx(55.6, abs=0.05) and rank < 0.9 * 80
    generator = next(a for a in plan.actors if a.actor.startswith("generator"))
    # KV: 8 full-attention layers x 4 KV heads x 256 x (K, V) x 2 bytes = 32 KiB per token
    assert "KV per token 32 KiB" in generator.notes[0]
    per_seq = 20480 * 8 * 4 * 256 * 2 * 2 + 24 * (32 * 128 * 128 * 4 + QKV * 3 * 2)
    room = 0.85 * 80 * GIB - 2 * n
    assert f"{int(room // per_seq)} full-length sequences" in generator.notes[1]
    assert (plan.gpus, plan.nodes) == (8, 1)
    # Checkpoint: bf16 policy + fp32 master + Adam m, v at 1000 MiB/s, every 10 of 60 steps.
    size = 2 * n + 12 * n_t
    assert plan.checkpoint.size_gib == pytest.approx(size / GIB)
    assert plan.checkpoint.write_minutes == pytest.approx(size / (1000 * MIB) / 60)
    assert (plan.checkpoint.interval_steps, plan.checkpoint.writes) == (10, 6)
    assert plan.fits and plan.problems == []


def test_ttopd_9b_teacher_holds_weights_and_its_fp32_shadow_on_the_gpu():
    plan = plan_run(load_config(TTOPD), "a100-80gb")
    teacher = items(plan, "teacher")
    assert teacher["weights (bfloat16)"] == (pytest.approx(2 * N_9B / GIB), "gpu")
    assert teacher["EMA shadow (fp32)"] == (pytest.approx(4 * N_9B / GIB), "gpu")   # 35.05 GiB
    tokens = 4 * 20480                                    # teacher.batch_size x sequence
    assert teacher["forward working set (one layer)"][0] == pytest.approx(
        tokens * 2 * (2 * H + 16448 + 2 * I) / GIB)
    assert teacher["LM-head chunk"][0] == pytest.approx(4 * 1024 * V * 4 * 2 / GIB)
    total = next(a for a in plan.actors if a.actor == "teacher").gpu_gib
    assert total == pytest.approx(67.7, abs=0.05) and total < 72
    # The checkpoint also holds the teacher's fp32 weights.
    assert plan.checkpoint.size_gib == pytest.approx((2 * N_9B + 12 * TEXT_9B + 4 * N_9B) / GIB)
    # With the shadow on the host, it leaves the GPU and shows up as host memory.
    cpu = plan_run(load_config(TTOPD, ["teacher.ema_shadow_device=cpu"]), "a100-80gb")
    assert items(cpu, "teacher")["EMA shadow (fp32)"] == (pytest.approx(4 * N_9B / GIB), "host")
    assert "would fit on the GPU" in " ".join(next(a for a in cpu.actors if a.actor == "teacher").notes)


@pytest.mark.parametrize("config", SHIPPED, ids=lambda p: p.name)
def test_every_shipped_9b_config_follows_its_plan(config):
    plan = plan_run(load_config(config))
    assert plan.fits, plan.problems
    learner = next(a for a in plan.actors if a.actor.startswith("learner"))
    assert not any("fits without offload" in note for note in learner.notes), learner.notes
    assert plan.checkpoint.write_minutes < 5, "checkpoints every 10 steps should not stall the run for long"
    assert "flash-linear-attention" in plan.linear_attention_kernels


def test_a_config_that_does_not_fit_is_refused_naming_what_to_change(capsys):
    from envs.cli import main

    code = main(["plan", "--config", str(GRPO), "--gpu", "a100-40gb"])
    out = capsys.readouterr()
    assert code == 1
    assert "learner rank needs 55.6 GiB" in out.err
    assert "turn on learner.deepspeed.offload_optimizer" in out.err and "ranks (learner.deepspeed.world_size" in out.err
    # The teacher: 67.7 GiB on a 40 GB GPU; moving the shadow to the host is not enough, batches of 1 are not either.
    code = main(["plan", "--config", str(TTOPD), "--gpu", "a100-40gb", "--set", "learner.deepspeed.offload_optimizer=true",
                 "--set", "learner.deepspeed.offload_param=true"])
    out = capsys.readouterr()
    assert code == 1 and "teacher needs" in out.err
    # And the suggested fix is accepted: offload on, on the 80 GB GPU offload is reported as unneeded.
    assert main(["plan", "--config", str(GRPO), "--gpu", "a100-40gb",
                 "--set", "learner.deepspeed.offload_optimizer=true"]) == 0
    assert "DOES NOT FIT" not in capsys.readouterr().out
    assert main(["plan", "--config", str(GRPO), "--gpu", "h200-141gb"]) == 0
    assert "fits." in format_plan(plan_run(load_config(GRPO), "h200-141gb"))
