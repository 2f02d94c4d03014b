"""Run configs refuse, at load time and with the key path, what would otherwise fail later or
silently train nonsense: non-finite or absurd numbers, booleans and strings as numbers, GRPO groups
of one, thresholds outside their range, unknown domains / splits, missing local paths, files that
are not UTF-8."""

from __future__ import annotations

from pathlib import Path

import pytest

from learner.config import ConfigError, load_config, validate_config

ROOT = Path(__file__).resolve().parents[2]
TINY = ROOT / "configs" / "tiny_cpu_grpo.yaml"  # triage_emergency, splits from its committed split file
WARD = {"ward": "tests.fixtures.ward_domain.environment"}


@pytest.fixture(autouse=True)
def _local_run(monkeypatch):
    # Local paths are checked only for a run on this machine; a RAY_ADDRESS in the environment
    # (a `ray job submit` job) would make every config a remote one.
    monkeypatch.delenv("RAY_ADDRESS", raising=False)


def _problems(overrides, path=TINY) -> str:
    with pytest.raises(ConfigError) as err:
        load_config(path, overrides)
    text = str(err.value)
    assert text.startswith(f"{path}: invalid config"), text
    return text


def _write(tmp_path, text: str | bytes, name: str = "c.yaml") -> Path:
    path = tmp_path / name
    path.write_bytes(text if isinstance(text, bytes) else text.encode("utf-8"))
    return path


# ---------------------------------------------------------------------------------------------- numbers


@pytest.mark.parametrize("key", ["learner.optim.lr", "sft.lr", "rollout.max_turns", "trainer.teacher_timeout_s",
                                 "generator.sampling.temperature", "ray.learner_resources.gpu_node"])
@pytest.mark.parametrize("value", [".inf", "-.inf", ".nan"])
def test_non_finite_numbers_are_refused_with_their_key(key, value):
    text = _problems([f"{key}={value}"])
    assert f"{key}: must be a finite number" in text


def test_absurd_learning_rates_are_refused(tmp_path):
    # Written as people write them: PyYAML alone would read `1e6` as the string "1e6".
    path = _write(tmp_path, "extends: " + str(TINY) + "\nlearner:\n  optim:\n    lr: 1e6\nsft:\n  lr: 2e3\n")
    text = _problems([], path)
    assert "learner.optim.lr: Input should be less than or equal to 1 (got 1000000.0)" in text
    assert "sft.lr: Input should be less than or equal to 1 (got 2000.0)" in text
    path = _write(tmp_path, "extends: " + str(TINY) + "\nlearner:\n  optim:\n    lr: 3e-4\n    eps: 1e-8\n")
    cfg = load_config(path)
    assert (cfg.learner.optim.lr, cfg.learner.optim.eps) == (3e-4, 1e-8)


def test_adam_betas_must_lie_in_0_1():
    text = _problems(["learner.optim.betas=[0.9, 1.5]"])
    assert "learner.optim.betas.1: Input should be less than 1" in text
    text = _problems(["learner.optim.betas=[0.9, .nan]"])
    assert "learner.optim.betas[1]: must be a finite number" in text
    assert text.count("learner.optim.betas") == 1, "one line per problem"


@pytest.mark.parametrize("key, wanted", [("trainer.batch_size", "an integer"), ("seed", "an integer"),
                                         ("learner.deepspeed.zero_stage", "an integer"),
                                         ("rollout.max_turns", "an integer"), ("learner.optim.lr", "a number")])
def test_booleans_are_not_numbers(key, wanted):
    text = _problems([f"{key}=true"])
    assert f"{key}: expected {wanted}, got a boolean (true)" in text


def test_quoted_numbers_are_refused():
    text = _problems(["trainer.batch_size='8'", "learner.optim.lr='5e-7'"])
    assert "trainer.batch_size: expected a number, got the string '8'" in text
    assert "learner.optim.lr: expected a number, got the string '5e-7'" in text


def test_booleans_stay_booleans_where_they_belong():
    cfg = load_config(TINY, ["trainer.val_at_start=false", "model.tiny.overrides={tie_word_embeddings: true}"])
    assert cfg.trainer.val_at_start is False and cfg.model.tiny.overrides["tie_word_embeddings"] is True


# ---------------------------------------------------------------------------------------------- rules


@pytest.mark.parametrize("size", [1, 0, -3])
def test_grpo_needs_groups_of_two(size):
    text = _problems([f"rollout.group_size={size}"])
    assert "rollout.group_size: Value error, GRPO needs at least 2 rollouts per prompt" in text


@pytest.mark.parametrize("value", [1.5, -0.1])
def test_accuracy_threshold_must_lie_in_0_1(value):
    text = _problems(["reward.correct_if=accuracy_at_least", f"reward.accuracy_threshold={value}"])
    assert "reward.accuracy_threshold:" in text


def test_hint_reward_threshold_must_lie_in_the_reward_range(tmp_path):
    ttopd = ROOT / "configs" / "tiny_cpu_ttopd.yaml"
    rule = "teacher.hints.correctness_rule=reward_above"
    text = _problems([rule, "teacher.hints.reward_threshold=1.0"], ttopd)
    assert "teacher.hints.reward_threshold: 1.0 is outside the total reward's range [0.0, 1.0)" in text
    # The cosine reward (Eq. 4) reaches below zero: -0.2 is a threshold that separates trajectories there.
    cfg = load_config(ttopd, [rule, "teacher.hints.reward_threshold=-0.2", "reward.kind=cosine"])
    assert cfg.reward_range == (-0.7, 1.1)
    text = _problems([rule, "teacher.hints.reward_threshold=-0.9", "reward.kind=cosine"], ttopd)
    assert "teacher.hints.reward_threshold: -0.9 is outside the cosine reward's range" in text


def test_cosine_reward_needs_r_min_below_r_max():
    text = _problems(["reward.kind=cosine", "reward.r_min=1.5"])
    assert "reward.r_min: 1.5 exceeds reward.r_max (1.1)" in text


# ---------------------------------------------------------------------------------------------- references


def test_unknown_domain_is_named_with_its_index():
    text = _problems(["data.domains=[triage_emergency, cardiology]"])
    assert "data.domains[1]: unknown domain 'cardiology'; registered domains: clinical_diagnosis, cross_domain" in text


def test_missing_domain_module_is_named():
    text = _problems(["data.domains=[icu]", "data.domain_modules={icu: tests.fixtures.no_such_domain}"])
    assert "data.domain_modules.icu: module 'tests.fixtures.no_such_domain' not found" in text
    text = _problems(["data.domains=[ward]", "data.domain_modules={ward: tests.fixtures.other_ward}"])
    assert "data.domain_modules.ward: 'ward' is already the registered domain module" in text


def test_splits_are_checked_against_the_domain():
    text = _problems(["data.train_split=trian"])
    assert "data.train_split: domain 'triage_emergency' has no split 'trian' (it has: test, train, validation)" in text
    text = _problems(["data.val_split=heldout"])
    assert "data.val_split: domain 'triage_emergency' has no split 'heldout'" in text
    # Without validation the validation split is never read, so it is not checked.
    cfg = load_config(TINY, ["data.val_split=heldout", "trainer.val_interval=0", "trainer.val_at_start=false"])
    assert cfg.data.val_split == "heldout"


def test_custom_domain_modules_are_checked_too():
    data = {"data": {"domains": ["ward"], "domain_modules": WARD, "train_split": "train", "val_split": "test"}}
    assert validate_config(data).data.domains == ["ward"]
    data["data"]["train_split"] = "nope"
    with pytest.raises(ConfigError, match="data.train_split: domain 'ward' has no split 'nope'"):
        validate_config(data)
    assert validate_config(data, check_references=False).data.train_split == "nope"


def test_local_paths_must_exist(tmp_path):
    text = _problems(["model.kind=pretrained", f"model.path={tmp_path / 'no_model'}"])
    assert f"model.path: '{tmp_path / 'no_model'}' does not exist and is not a hub id" in text
    (tmp_path / "empty").mkdir()
    text = _problems(["model.kind=pretrained", f"model.path={tmp_path / 'empty'}"])
    assert "model.path:" in text and "has no config.json" in text
    text = _problems([f"kb.path={tmp_path / 'kb'}", f"learner.reference_model_dir={tmp_path / 'ref'}",
                      f"generator.python_executable={tmp_path / 'python'}"])
    assert f"kb.path: '{tmp_path / 'kb'}' is not a directory" in text
    assert f"learner.reference_model_dir: '{tmp_path / 'ref'}' is not a checkpoint folder" in text
    assert f"generator.python_executable: '{tmp_path / 'python'}' is not an executable file" in text
    (tmp_path / "a_file").write_text("x", encoding="utf-8")
    text = _problems([f"output_dir={tmp_path / 'a_file'}"])
    assert "output_dir:" in text and "is not a directory" in text


def test_hub_ids_and_remote_node_paths_are_not_checked_here(monkeypatch):
    cfg = load_config(TINY, ["model.kind=pretrained", "model.path=Qwen/Qwen3.5-9B"])
    assert cfg.model.path == "Qwen/Qwen3.5-9B"  # resolved in the Hugging Face cache when the run starts
    # A config for a remote cluster names paths on its nodes.
    remote = ["ray.address=ray://head:10001", "generator.python_executable=~/.venv-vllm/bin/python"]
    assert load_config(TINY, remote).generator.python_executable == "~/.venv-vllm/bin/python"
    monkeypatch.setenv("RAY_ADDRESS", "http://head:8265")  # inside a `ray job submit` job
    assert load_config(TINY, remote[1:]).generator.python_executable == "~/.venv-vllm/bin/python"


# ---------------------------------------------------------------------------------------------- files


def test_non_utf8_config_names_the_file(tmp_path):
    path = _write(tmp_path, b"name: caf\xe9\ntrainer:\n  batch_size: 4\n")
    with pytest.raises(ConfigError) as err:
        load_config(path)
    assert f"{path.resolve()}: config file is not UTF-8 text (byte 0xe9 at line 1)" in str(err.value)


def test_non_utf8_parent_config_names_the_parent(tmp_path):
    parent = _write(tmp_path, b"# \xff\xfe comment\nseed: 1\n", "base.yaml")
    child = _write(tmp_path, "extends: base.yaml\nseed: 2\n")
    with pytest.raises(ConfigError) as err:
        load_config(child)
    assert str(parent.resolve()) in str(err.value) and "not UTF-8" in str(err.value)


def test_utf8_bom_config_loads(tmp_path):
    path = _write(tmp_path, b"\xef\xbb\xbfextends: " + str(TINY).encode() + b"\nseed: 7\n")
    assert load_config(path).seed == 7


def test_deeply_nested_yaml_names_the_file(tmp_path):
    path = _write(tmp_path, "a: " + "[" * 50_000 + "]" * 50_000 + "\n")
    with pytest.raises(ConfigError) as err:
        load_config(path)
    assert str(path.resolve()) in str(err.value)


def test_sections_built_in_code_refuse_non_finite_numbers():
    # The learner actor re-validates its section from a dict: NaN must not slip in that way either.
    from pydantic import ValidationError

    from modeling.config_models import LearnerConfig, TeacherConfig

    with pytest.raises(ValidationError, match="loss.grpo.kl_beta"):
        LearnerConfig(loss={"grpo": {"kl_beta": float("inf")}})
    with pytest.raises(ValidationError, match="ema_alpha"):
        TeacherConfig(ema_alpha=float("nan"))
