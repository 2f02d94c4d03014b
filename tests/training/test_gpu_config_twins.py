"""The shipped GPU configs run on CPU as twins (learner/cpu_twin.py, `hcgym train --cpu-twin`).

Each shipped GPU config (`configs/qwen35_9b_*.yaml`, read at test time, so the tests follow their
changes) differs from its CPU twin by exactly the documented overrides of `CPU_TWIN_OVERRIDES`, and
every other key runs as shipped: DeepSpeed ZeRO-3 at the shipped world size (4 ranks, each its own
Ray actor, over gloo) with gradient checkpointing, the shipped offload settings, bf16, micro-batches,
the frozen reference (kl_beta > 0), dynamic sampling, the teacher with hints, the cosine reward and
the collective weight sync.

What runs, and why not more (suite budget; measured in docs/benchmarks.md, "CPU twins"):
- the two base configs, two steps each: `qwen35_9b_grpo` on the Qwen3 twin with the vLLM generator
  (the engine in .venv-vllm's interpreter as a Ray actor, collective sync into its worker), and
  `qwen35_9b_ttopd` on the Qwen3.5 twin (hybrid linear/full attention, vision tower) with the
  teacher and hints. vLLM's CPU build cannot start Qwen3.5 (`VLLM_CPU_UNSUPPORTED`), so the Qwen3.5
  run samples with the HF generator: the table's `no_vllm_cpu` overrides.
- the five ablation arms are not run: each one's twin is built and validated, and each key in which
  an arm differs from its base config is exercised by a named test (`ARM_KEYS_EXERCISED`).
"""

from __future__ import annotations

import json
import math
import re
import shutil
from pathlib import Path

import pytest

from learner.config import ConfigError, load_config
from learner.cpu_twin import (
    CPU_TWIN_OVERRIDES,
    TWIN_MODEL,
    applicable_overrides,
    config_diff,
    flatten,
    gpu_residue,
    twin_config,
)

ROOT = Path(__file__).resolve().parents[2]
BASE_CONFIGS = sorted((ROOT / "configs").glob("qwen35_9b_*.yaml"))
ARM_CONFIGS = sorted((ROOT / "configs" / "ablations").glob("*.yaml"))

# Keys in which an ablation arm may differ from its base config, and the tests that run each setting.
ARM_KEYS_EXERCISED = {
    "name": [],
    "output_dir": [],
    "reward.kind": ["tests/training/test_train.py::test_teacher_updates_over_the_collective_group_equal_the_object_store_path"],
    "teacher.hints.enabled": ["tests/training/test_teacher.py::test_correctness_rule_and_disabled_hints"],
    "teacher.ema_interval": ["tests/training/test_gpu_config_twins.py::test_periodic_reset_schedule_never_runs_ema"],
    "teacher.hard_copy_interval": ["tests/training/test_teacher.py::test_ema_hard_copy_schedule_and_values"],
}


@pytest.fixture(scope="module")
def twin_models(tmp_path_factory) -> dict[str, str]:
    """The Qwen3.5 twin as `--cpu-twin` builds it (tokenizer trained on the configs' domains) and a
    Qwen3 twin with the same tokenizer (the family vLLM's CPU build can start)."""
    from learner.cpu_twin import build_cpu_twin_model
    from modeling.model import build_twin_model

    root = tmp_path_factory.mktemp("cpu_twins")
    qwen3_5 = build_cpu_twin_model(load_config(BASE_CONFIGS[0]), root / "qwen3_5", log=lambda line: None)
    qwen3 = build_twin_model("qwen3", root / "qwen3", root / "qwen3_5" / "tokenizer")
    return {"qwen3_5": str(qwen3_5), "qwen3": str(qwen3)}


def _covered(key: str, override_keys: set[str]) -> bool:
    return any(key == k or key.startswith(k + ".") for k in override_keys)


def test_the_shipped_configs_are_found():
    names = {p.name for p in BASE_CONFIGS}
    assert {"qwen35_9b_grpo.yaml", "qwen35_9b_ttopd.yaml"} <= names
    assert len(ARM_CONFIGS) >= 5


def test_each_twin_differs_from_its_config_exactly_by_the_documented_overrides(twin_models):
    """For every shipped GPU config and both twin families: every key of the diff is a documented
    override that applies, and every applicable override holds its value in the twin. Over all
    configs, every override of the table is used (no stale entry), and each has a reason."""
    used: set[str] = set()
    for path in BASE_CONFIGS + ARM_CONFIGS:
        shipped = load_config(path)
        for family, model_dir in twin_models.items():
            twin = twin_config(shipped, model_dir, output_dir=shipped.output_dir)
            applied = applicable_overrides(shipped, model_dir)
            keys = {o.key for o in applied}
            diff = config_diff(shipped, twin)
            undocumented = sorted(k for k in diff if not _covered(k, keys))
            assert not undocumented, f"{path.name} ({family}): twin differs in undocumented keys {undocumented}"
            flat = flatten(twin.model_dump(mode="json"))
            for o in applied:
                want = model_dir if o.value == TWIN_MODEL else o.value
                got = flat.get(o.key) if not isinstance(want, dict) else {
                    k[len(o.key) + 1:]: v for k, v in flat.items() if k.startswith(o.key + ".")}
                assert got == want, f"{path.name} ({family}): {o.key} = {got!r}, the table says {want!r}"
                if any(_covered(k, {o.key}) for k in diff):
                    used.add(o.key)
            assert not gpu_residue(twin), gpu_residue(twin)
    table = {o.key for o in CPU_TWIN_OVERRIDES}
    assert table - used == set(), f"overrides no shipped config needs (remove them): {sorted(table - used)}"
    assert len(table) == len(CPU_TWIN_OVERRIDES), "a key is listed twice"
    assert all(len(o.reason) > 10 for o in CPU_TWIN_OVERRIDES)


def test_a_new_gpu_only_key_fails_the_twin_until_it_is_listed(twin_models):
    """A GPU setting the table does not override (here the learner actor's own GPU) is refused by
    name when the twin is built, so it cannot slip onto a CPU rehearsal unnoticed."""
    shipped = load_config(BASE_CONFIGS[0], ["ray.learner_num_gpus=1"])
    with pytest.raises(ValueError, match=r"ray\.learner_num_gpus"):
        twin_config(shipped, twin_models["qwen3"])


def test_every_ablation_arm_has_a_valid_twin_and_its_settings_are_exercised(twin_models):
    """Arms are not run (suite budget): each twin validates, and each key in which an arm differs
    from its base config is exercised by a named test that exists."""
    for path in ARM_CONFIGS:
        text = path.read_text()
        base_name = re.search(r"^extends:\s*(\S+)", text, re.M).group(1)
        base = load_config(path.parent / base_name)
        arm = load_config(path)
        twin_config(arm, twin_models["qwen3_5"], output_dir=arm.output_dir)  # validates or raises
        for key in config_diff(base, arm):
            assert key in ARM_KEYS_EXERCISED, f"{path.name}: {key} differs from {base_name} and no test is named for it"
            for test_id in ARM_KEYS_EXERCISED[key]:
                file, name = test_id.split("::")
                assert re.search(rf"^def {name}\(", (ROOT / file).read_text(), re.M), f"{test_id} does not exist"


def test_periodic_reset_schedule_never_runs_ema():
    """The periodic_reset arm (ema_interval 0): hard copies every 30 steps, nothing in between."""
    from modeling.config_models import teacher_update_action

    arm = load_config(ROOT / "configs" / "ablations" / "periodic_reset.yaml")
    actions = [teacher_update_action(step, arm.teacher) for step in range(1, 91)]
    assert [s for s, a in enumerate(actions, 1) if a != "none"] == [30, 60, 90]
    assert set(actions) == {"none", "hard_copy"}


def test_cpu_twin_flag_of_hcgym_train(twin_models, tmp_path):
    """`hcgym train --config ... --cpu-twin` loads the shipped config and applies the table; the run
    folder gets a `_cpu_twin` suffix, and the twin model is built once beside it (reused here)."""
    from learner.train_args import build_arg_parser, config_from_args

    out = tmp_path / "runs" / "rehearsal"
    cached = out.parent / ".cpu_twin_models" / "qwen35_9b_ttopd" / "model"
    shutil.copytree(twin_models["qwen3_5"], cached)
    args = build_arg_parser().parse_args(["--config", str(ROOT / "configs" / "qwen35_9b_ttopd.yaml"),
                                          "--output-dir", str(out), "--cpu-twin"])
    lines: list[str] = []
    cfg = config_from_args(args, log=lines.append)
    assert cfg.model.path == str(cached) and cfg.output_dir == str(out)
    assert (cfg.learner.device, cfg.teacher.device, cfg.weight_sync.backend) == ("cpu", "cpu", "gloo")
    assert cfg.learner.deepspeed.world_size == load_config(ROOT / "configs" / "qwen35_9b_ttopd.yaml").learner.deepspeed.world_size
    assert any("learner.device" in line for line in lines)
    with pytest.raises(ConfigError, match="qwen35_9b_ttopd.yaml"):
        config_from_args(build_arg_parser().parse_args(
            ["--config", str(ROOT / "configs" / "qwen35_9b_ttopd.yaml"), "--output-dir", str(out), "--cpu-twin",
             "--set", "trainer.batch_size=0"]), log=lines.append)


def _run_twin(config: str, model_dir: str, run_dir: Path) -> list[dict]:
    from learner.metrics import read_metrics
    from learner.train import train

    shipped = load_config(ROOT / "configs" / config)
    cfg = twin_config(shipped, model_dir, output_dir=run_dir)
    summary = train(cfg, log=lambda line: None)
    assert summary["steps"] == 2
    records = read_metrics(run_dir)
    assert [r["step"] for r in records] == [1, 2]
    for r in records:
        assert all(math.isfinite(v) for v in r.values() if isinstance(v, float)), r
        assert r["grad_norm"] > 0 and r["policy_lag_max"] == 0
        # The generator sampled with the learner's weights of the previous step (bf16 on both sides).
        assert r["logprob_abs_diff"] < 0.05, r["logprob_abs_diff"]
    ckpt = run_dir / "checkpoints" / "step_000002" / "learner"
    ws = shipped.learner.deepspeed.world_size
    assert sorted(p.name for p in ckpt.glob("fp32_partition_rank*.safetensors")) == \
        [f"fp32_partition_rank{r}.safetensors" for r in range(ws)]
    return records


@pytest.mark.ray
def test_grpo_config_twin_runs_two_steps_with_vllm(ray_cluster, twin_models, tmp_path):
    """qwen35_9b_grpo on the Qwen3 twin: 4 ZeRO-3 ranks with gradient checkpointing and the shipped
    offload, the vLLM engine in its own interpreter, weights to it over the collective group."""
    records = _run_twin("qwen35_9b_grpo.yaml", twin_models["qwen3"], tmp_path / "grpo")
    saved = json.loads(json.dumps(load_config(tmp_path / "grpo" / "config.yaml").generator.model_dump()))
    assert saved["backend"] == "vllm"
    assert all(r["kl_ref"] >= 0 for r in records)


@pytest.mark.ray
def test_ttopd_config_twin_runs_two_steps_on_qwen3_5(ray_cluster, twin_models, tmp_path):
    """qwen35_9b_ttopd on the Qwen3.5 twin: the same learner topology, the EMA teacher with hints in
    the weight-sync group, the cosine reward, turn-level distillation."""
    records = _run_twin("qwen35_9b_ttopd.yaml", twin_models["qwen3_5"], tmp_path / "ttopd")
    for r in records:
        assert r["distill_tokens"] > 0 and r["kl_teacher"] != 0, r  # the hint moves the teacher
        assert -0.5 - 1e-9 <= r["reward_mean"] <= 1.1 + 1e-9  # Eq. 4's range
        assert r["teacher_sync_collective_bytes"] > 0 and r["teacher_sync_object_store"] == 0
