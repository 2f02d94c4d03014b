"""Run configs: every shipped YAML validates; mistakes fail with the key's path."""

from __future__ import annotations

from pathlib import Path

import pytest

from learner.config import ConfigError, RunConfig, load_config

CONFIGS = sorted((Path(__file__).resolve().parents[2] / "configs").rglob("*.yaml"))


def test_configs_exist():
    names = {p.name for p in CONFIGS if p.parent.name == "configs"}
    for required in ("tiny_cpu_grpo.yaml", "tiny_cpu_ttopd.yaml", "qwen35_9b_grpo.yaml", "qwen35_9b_ttopd.yaml"):
        assert required in names, f"configs/{required} is missing"
    arms = {p.stem for p in CONFIGS if p.parent.name == "ablations"}
    assert {"grpo", "periodic_reset", "ema_no_hints", "ema_hints_no_length", "ttopd"} <= arms


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.name)
def test_shipped_config_validates(path):
    cfg = load_config(path)
    assert isinstance(cfg, RunConfig)
    # TT-OPD arms need the teacher and the distillation term together (the validator enforces it).
    assert cfg.teacher.enabled == cfg.learner.loss.distill.enabled


def test_paper_hyperparameters():
    root = Path(__file__).resolve().parents[2] / "configs"
    grpo = load_config(root / "qwen35_9b_grpo.yaml")
    ttopd = load_config(root / "qwen35_9b_ttopd.yaml")
    for cfg in (grpo, ttopd):
        assert cfg.learner.optim.lr == 5e-7 and cfg.learner.optim.max_grad_norm == 1.0
        assert cfg.trainer.batch_size == 8 and cfg.learner.optim.micro_batch_size == 1
        assert cfg.rollout.group_size == 3 and cfg.learner.loss.grpo.kl_beta == 0.01
        assert (cfg.rollout.max_prompt_tokens, cfg.rollout.max_response_tokens, cfg.rollout.max_turns) == (8192, 12288, 5)
        assert cfg.learner.dtype == "bfloat16"
    assert not grpo.teacher.enabled and grpo.reward.kind == "total"
    d, t, r = ttopd.learner.loss.distill, ttopd.teacher, ttopd.reward
    assert (d.lambda_distill, t.ema_alpha, t.ema_interval, t.hard_copy_interval) == (4.0, 0.995, 5, 30)
    assert (r.kind, r.r_max, r.r_min, r.r_penalty) == ("cosine", 1.1, 0.7, -0.5)
    # The five ablation arms differ exactly where the paper says.
    arms = {p.stem: load_config(p) for p in (root / "ablations").glob("*.yaml")}
    assert not arms["grpo"].teacher.enabled
    assert arms["periodic_reset"].teacher.ema_interval == 0 and arms["periodic_reset"].teacher.hard_copy_interval > 0
    assert not arms["ema_no_hints"].teacher.hints.enabled and arms["ema_no_hints"].teacher.ema_interval == 5
    assert arms["ema_hints_no_length"].teacher.hints.enabled and arms["ema_hints_no_length"].reward.kind == "total"
    assert arms["ttopd"].teacher.hints.enabled and arms["ttopd"].reward.kind == "cosine"


def _write(tmp_path, text: str, name: str = "c.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_unknown_key_names_its_path(tmp_path):
    path = _write(tmp_path, "trainer:\n  batch_size: 4\n  dynamic_sampling:\n    enabeld: true\n")
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert "trainer.dynamic_sampling.enabeld: unknown key" in str(info.value)
    assert str(path) in str(info.value)


def test_unknown_top_level_section(tmp_path):
    with pytest.raises(ConfigError, match=r"optimiser: unknown key"):
        load_config(_write(tmp_path, "optimiser:\n  lr: 1.0\n"))


def test_wrong_type_names_its_path_and_value(tmp_path):
    path = _write(tmp_path, "rollout:\n  group_size: three\nlearner:\n  optim:\n    lr: fast\n")
    with pytest.raises(ConfigError) as info:
        load_config(path)
    text = str(info.value)
    assert "rollout.group_size:" in text and "'three'" in text
    assert "learner.optim.lr:" in text and "'fast'" in text


def test_bad_value_in_a_t1_section(tmp_path):
    with pytest.raises(ConfigError, match=r"teacher\.ema_alpha"):
        load_config(_write(tmp_path, "teacher:\n  ema_alpha: 1.5\n"))


def test_inconsistent_sections_are_named(tmp_path):
    with pytest.raises(ConfigError, match=r"teacher.enabled"):
        load_config(_write(tmp_path, "learner:\n  loss:\n    distill:\n      enabled: true\n"))
    with pytest.raises(ConfigError, match=r"generator.sampling.temperature"):
        load_config(_write(tmp_path, "generator:\n  sampling:\n    temperature: 0.7\n"))


def test_yaml_syntax_error_names_line(tmp_path):
    with pytest.raises(ConfigError, match=r"not valid YAML at line 2, column 16"):
        load_config(_write(tmp_path, "trainer:\n  batch_size: 4: 5\n"))


def test_extends_and_overrides(tmp_path):
    _write(tmp_path, "name: base\ntrainer:\n  batch_size: 4\n  max_steps: 10\n", "base.yaml")
    child = _write(tmp_path, "extends: base.yaml\nname: child\ntrainer:\n  max_steps: 3\n", "child.yaml")
    cfg = load_config(child, ["trainer.max_staleness=2", "rollout.max_turns=4"])
    assert (cfg.name, cfg.trainer.batch_size, cfg.trainer.max_steps) == ("child", 4, 3)
    assert cfg.trainer.max_staleness == 2 and cfg.rollout.max_turns == 4
    with pytest.raises(ConfigError, match=r"trainer.max_staleness"):
        load_config(child, ["trainer.max_staleness=-1"])
    with pytest.raises(ConfigError, match=r"expected key.path=value"):
        load_config(child, ["trainer.max_staleness"])


def test_extends_cycle_and_missing_file(tmp_path):
    _write(tmp_path, "extends: b.yaml\n", "a.yaml")
    _write(tmp_path, "extends: a.yaml\n", "b.yaml")
    with pytest.raises(ConfigError, match="cycle"):
        load_config(tmp_path / "a.yaml")
    with pytest.raises(ConfigError, match="not found"):
        load_config(tmp_path / "nope.yaml")


def test_the_demo_config_is_tiny_ttopd_with_the_vllm_generator_only():
    """`make demo` runs tiny_cpu_ttopd_vllm.yaml: its figures are compared with tiny_cpu_ttopd.yaml's
    (docs/benchmarks.md), which holds only if nothing but the generator differs."""
    root = Path(__file__).resolve().parents[2] / "configs"
    hf = load_config(root / "tiny_cpu_ttopd.yaml").model_dump(mode="json")
    vllm = load_config(root / "tiny_cpu_ttopd_vllm.yaml").model_dump(mode="json")
    differing = {k for k in hf if hf[k] != vllm[k]}
    assert differing == {"name", "output_dir", "generator"}, differing
    assert vllm["generator"]["backend"] == "vllm" and hf["generator"]["backend"] == "hf"
    same = {k: v for k, v in hf["generator"].items() if k not in ("backend", "options")}
    assert same == {k: v for k, v in vllm["generator"].items() if k not in ("backend", "options")}
    makefile = (root.parent / "Makefile").read_text()
    assert "--config configs/tiny_cpu_ttopd_vllm.yaml" in makefile
