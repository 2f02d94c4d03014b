"""The GPU benches' arithmetic and plumbing, checked on CPU: learner FLOPs against a hand count, the
dense bf16 peak from the device model name, figures written as each phase ends, argument checks."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
import torch

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))

import gpu_figures  # noqa: E402
from gpu_figures import FigureLog, device_peak, head_params, learner_step_flops, mfu  # noqa: E402


def test_flops_against_a_hand_count_of_a_tiny_qwen2():
    from transformers import AutoModelForCausalLM, Qwen2Config

    config = Qwen2Config(vocab_size=100, hidden_size=8, intermediate_size=16, num_hidden_layers=1,
                         num_attention_heads=2, num_key_value_heads=1, tie_word_embeddings=True)
    model = AutoModelForCausalLM.from_config(config)
    # By hand (head_dim 4): q 8x8+8, k 8x4+4, v 8x4+4, o 8x8, MLP 3 x 8x16, two norms 2x8 -> 608 a
    # layer; embedding (= the tied head) 100x8 = 800; final norm 8.
    n = sum(p.numel() for p in model.parameters())
    assert n == 608 + 800 + 8 == 1416
    assert head_params(config) == 800
    # 10 positions of which 4 are trained: the body runs on all 10, the head on the 4.
    assert learner_step_flops(n, 800, tokens=10, loss_tokens=4) == 8 * 616 * 10 + 8 * 800 * 4 == 74_880
    assert learner_step_flops(n, 800, tokens=10, loss_tokens=4, reference=False) == 6 * 616 * 10 + 6 * 800 * 4
    assert learner_step_flops(n, 800, 10, 4) < 8 * n * 10  # the former 8 N tokens overstated it
    with pytest.raises(ValueError, match="loss_tokens"):
        learner_step_flops(n, 800, tokens=10, loss_tokens=11)
    with pytest.raises(ValueError, match="n_head"):
        learner_step_flops(100, 800, tokens=10, loss_tokens=1)


def test_head_params_of_a_multimodal_config_come_from_its_text_config():
    class Text:
        vocab_size, hidden_size = 248_320, 4096

    class Multimodal:
        text_config = Text()

    assert head_params(Multimodal()) == 248_320 * 4096


@pytest.mark.parametrize("name, model, tflops", [
    ("NVIDIA H100 80GB HBM3", "H100 SXM", 989.5),
    ("NVIDIA H100 PCIe", "H100 PCIe", 756.5),
    ("NVIDIA H100 NVL", "H100 NVL", 835.5),
    ("NVIDIA H200", "H200 SXM", 989.5),
    ("NVIDIA H200 NVL", "H200 NVL", 835.5),
    ("NVIDIA A100-SXM4-80GB", "A100", 312.0),
    ("NVIDIA A100-SXM4-40GB", "A100", 312.0),
    ("NVIDIA A100-PCIE-40GB", "A100", 312.0),
    ("NVIDIA A100 80GB PCIe", "A100", 312.0),
])
def test_peak_from_the_device_model(name, model, tflops):
    peak = device_peak(name)
    assert (peak.model, peak.tflops) == (model, tflops)


@pytest.mark.parametrize("name", ["NVIDIA H100", "NVIDIA GH200 480GB", "NVIDIA L40S", "NVIDIA B200", "cpu"])
def test_an_unknown_or_ambiguous_device_has_no_peak_and_says_why(name):
    peak = device_peak(name)
    assert peak.tflops is None and repr(name) in peak.reason and "--peak-tflops" in peak.reason
    assert mfu(1e15, 1.0, peak) is None
    assert device_peak(name, 500.0).tflops == 500.0
    with pytest.raises(ValueError, match="--peak-tflops"):
        device_peak(name, 0.0)


def test_learner_arm_figures_count_real_tokens_not_padding():
    """gpu_step's per-arm figures: tokens/s and MFU on the real tokens of a step, whatever the arm
    padded; the padding fraction is the mean of the learner's per-step figure."""
    import gpu_step

    meta = {"params": 1416, "head_params": 800}
    peak = device_peak("NVIDIA H200")
    figures = gpu_step.arm_figures([2.0, 4.0], real_tokens=300, loss_tokens=120, padding_fracs=[0.25, 0.35],
                                   meta=meta, peak=peak, reference=True)
    assert figures["learner_tokens_per_s"] == pytest.approx(2 * 300 / 6.0)
    assert figures["learner_step_s"] == pytest.approx(3.0)
    assert figures["learner_padding_frac"] == pytest.approx(0.30)
    flops = learner_step_flops(1416, 800, 600, 240)
    assert figures["tflops_achieved"] == pytest.approx(flops / 6.0 / 1e12)
    assert figures["mfu"] == pytest.approx(flops / 6.0 / (989.5e12))


def test_learner_length_mixes_are_seeded_and_shape_the_samples():
    import gpu_step

    assert gpu_step.sample_lengths("even", 3, 64) == [64, 64, 64]
    tail = gpu_step.sample_lengths("long-tail", 16, 2048)
    assert tail == gpu_step.sample_lengths("long-tail", 16, 2048)  # seeded
    assert all(128 <= n <= 2048 for n in tail) and max(tail) > 3 * sorted(tail)[len(tail) // 2]  # a long tail
    samples = gpu_step.synthetic_samples(16, 2048, 500, lengths=tail)
    assert [len(s.input_ids) for s in samples] == tail
    for s in samples:
        assert len(s.loss_mask) == len(s.sampling_logprobs) == len(s.input_ids) and s.turns[-1].end == len(s.input_ids)
        assert s.response_tokens == sum(s.loss_mask) > 0 and s.loss_mask[:s.prompt_length] == [0] * s.prompt_length
    # No lengths: the even mix.
    assert [s.input_ids for s in gpu_step.synthetic_samples(2, 64, 500)] == \
        [s.input_ids for s in gpu_step.synthetic_samples(2, 64, 500, lengths=[64, 64])]
    with pytest.raises(ValueError, match="--lengths"):
        gpu_step.sample_lengths("bimodal", 4, 64)
    with pytest.raises(ValueError, match="lengths"):
        gpu_step.synthetic_samples(2, 64, 500, lengths=[64])


def test_figures_are_on_disk_after_each_phase(tmp_path, capsys):
    path = tmp_path / "figures.json"
    log = FigureLog(path, {"device": "cpu"})
    log.record("first", {"tokens_per_s": 1.5})
    assert json.loads(path.read_text())["phases"] == {"first": {"tokens_per_s": 1.5}}
    log.record("second", {"error": "boom"})
    data = json.loads(path.read_text())
    assert list(data["phases"]) == ["first", "second"] and data["device"] == "cpu"
    assert 'PHASE first {"tokens_per_s": 1.5}' in capsys.readouterr().out


def test_vllm_python_is_checked(tmp_path):
    with pytest.raises(ValueError, match="--vllm-python"):
        gpu_figures.resolve_vllm_python(str(tmp_path / "missing-python"))
    assert gpu_figures.resolve_vllm_python(sys.executable) == sys.executable


def test_gpu_step_runs_the_vllm_half_in_the_vllm_interpreter(tmp_path, monkeypatch):
    """The vLLM half runs under --vllm-python (the nodes keep vLLM in its own venv): here a stand-in
    interpreter that reports how it was called, run as a real subprocess."""
    import gpu_step

    monkeypatch.setattr(gpu_step, "build_model", lambda root, cpu=False: str(root))  # no model needed
    fake_vllm = tmp_path / "vllm-python"
    fake_vllm.write_text('#!/bin/sh\necho "RESULT {\\"interpreter\\": \\"$0\\", \\"args\\": \\"$*\\"}"\n')
    fake_vllm.chmod(0o755)
    out = tmp_path / "step.json"
    assert gpu_step.main(["--cpu", "--parts", "vllm", "--vllm-python", str(fake_vllm), "--json-out", str(out)]) == 0
    phases = json.loads(out.read_text())["phases"]
    assert list(phases) == ["build", "vllm"]
    assert phases["vllm"]["interpreter"] == str(fake_vllm)
    assert "--part vllm" in phases["vllm"]["args"] and "--cpu" in phases["vllm"]["args"]
    with pytest.raises(SystemExit):
        gpu_step.main(["--cpu", "--parts", "learner,bogus"])
    missing = tmp_path / "missing.json"
    assert gpu_step.main(["--cpu", "--parts", "vllm", "--vllm-python", str(tmp_path / "nope"),
                          "--json-out", str(missing)]) == 0
    assert "--vllm-python" in json.loads(missing.read_text())["phases"]["vllm"]["error"]


def test_without_a_gpu_the_benches_exit_0_and_say_why(capsys):
    if torch.cuda.is_available():
        pytest.skip("this machine has a GPU")
    import gpu_smoke
    import gpu_step

    assert gpu_step.main([]) == 0 and gpu_smoke.main([]) == 0
    assert capsys.readouterr().out.count("no GPU found") == 2
