"""Checkpoints as people have them: tiny twins of Qwen3, Qwen3.5 (with its vision tower) and a tied Llama,
saved sharded, loaded through the one loading path (modeling/hf_checkpoint.py) by every component.

Log-prob agreement is checked on the generator's own samples: the HF generator reports the log-prob
of each token it draws; the learner's `logprob_abs_diff` (mean |learner - rollout| over the sampled
tokens) and the teacher's log-probs (hints off) must match them. Tolerance: 2e-5 nats per token
(fp32; the generator scores incrementally over a KV cache / recurrent state with left padding, the
learner and teacher in one right-padded forward, so only float summation order differs; the observed
differences: docs/benchmarks.md, "Figures behind code defaults"). After one learner step (lr 1e-2)
the old log-probs are off by > 1e-3.
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from actors.types import RolloutSample, TurnSpan
from tests.training.learner_fixtures import CORPUS
from tests.training.twins import TWIN_ARCHITECTURES, TWIN_FAMILIES, build_twin

WARD = {"ward": "tests.fixtures.ward_domain.environment"}
LOGPROB_TOL = 2e-5
STEP_MOVES_LOGPROBS = 1e-3


@pytest.fixture(scope="module")
def twin_root(tmp_path_factory) -> Path:
    from modeling.model import train_tokenizer

    root = tmp_path_factory.mktemp("twins")
    tok = train_tokenizer(CORPUS, 1024, root / "tok", max_stdlib_files=40)
    for family in TWIN_FAMILIES:
        build_twin(family, root / family, tok)
    return root


def _weight_map(model_dir: Path) -> dict[str, str]:
    return json.loads((model_dir / "model.safetensors.index.json").read_text())["weight_map"]


# -- layouts and the loader ------------------------------------------------------------------------


def test_twins_have_the_real_layouts_and_are_sharded(twin_root):
    for family in TWIN_FAMILIES:
        d = twin_root / family
        names = _weight_map(d)
        assert len(set(names.values())) >= 2, family
        assert json.loads((d / "config.json").read_text())["architectures"] == [TWIN_ARCHITECTURES[family]]
        assert (d / "tokenizer.json").exists()
    assert "model.layers.0.self_attn.q_norm.weight" in _weight_map(twin_root / "qwen3")
    qwen35 = _weight_map(twin_root / "qwen3_5")
    assert any(n.startswith("model.visual.blocks.0.") for n in qwen35)
    assert "model.language_model.layers.0.linear_attn.A_log" in qwen35  # the hybrid linear-attention layer
    assert "model.language_model.layers.1.self_attn.q_proj.weight" in qwen35
    assert "lm_head.weight" in qwen35 and not any(n.startswith("model.layers.") for n in qwen35)
    assert "lm_head.weight" not in _weight_map(twin_root / "llama_tied")  # tied: not stored


@pytest.mark.parametrize("family", TWIN_FAMILIES)
def test_load_model_equals_transformers_from_pretrained(twin_root, family):
    import transformers

    from modeling.hf_checkpoint import load_model, tied_parameter_aliases

    d = twin_root / family
    ours = load_model(d)
    theirs = getattr(transformers, TWIN_ARCHITECTURES[family]).from_pretrained(str(d))
    assert type(ours) is type(theirs)
    a, b = ours.state_dict(), theirs.state_dict()
    assert set(a) == set(b)
    assert all(torch.equal(a[k], b[k]) for k in a)
    if family == "llama_tied":
        assert tied_parameter_aliases(ours) == {"lm_head.weight": "model.embed_tokens.weight"}
        assert ours.lm_head.weight is ours.model.embed_tokens.weight
    half = load_model(d, torch.bfloat16)
    assert all(p.dtype == torch.bfloat16 for p in half.parameters())


def test_a_bf16_checkpoint_loads_in_fp32_like_transformers_does(twin_root, tmp_path):
    import transformers

    from modeling.hf_checkpoint import load_model

    d = build_twin("qwen3_5", tmp_path / "bf16", twin_root / "tok", dtype=torch.bfloat16)
    ours = load_model(d, torch.float32).state_dict()
    theirs = transformers.Qwen3_5ForConditionalGeneration.from_pretrained(str(d), dtype=torch.float32).state_dict()
    assert all(v.dtype == torch.float32 and torch.equal(v, theirs[k]) for k, v in ours.items())


def test_a_pre_4_52_multimodal_layout_loads_into_the_same_names(twin_root, tmp_path):
    """Qwen2.5-VL checkpoints published before transformers nested the language model store
    `model.layers.*` and `visual.*`; the loader reads them into `model.language_model.*` / `model.visual.*`."""
    import shutil

    from safetensors.torch import save_file

    from modeling.hf_checkpoint import load_model, read_checkpoint_tensors

    src = twin_root / "qwen3_5"
    legacy = {}
    for name, t in read_checkpoint_tensors(src).items():
        name = name.replace("model.language_model.", "model.").replace("model.visual.", "visual.")
        legacy[name] = t.contiguous()
    for f in src.iterdir():
        if not f.name.startswith("model"):
            shutil.copy2(f, tmp_path / f.name)
    save_file(legacy, str(tmp_path / "model.safetensors"))  # unsharded this time
    a, b = load_model(tmp_path).state_dict(), load_model(src).state_dict()
    assert set(a) == set(b) and all(torch.equal(a[k], b[k]) for k in a)
    # A checkpoint missing a tensor is named, with the folder.
    del legacy["visual.blocks.0.norm1.weight"]
    save_file(legacy, str(tmp_path / "model.safetensors"))
    with pytest.raises(KeyError, match=r"has no tensor 'model\.visual\.blocks\.0\.norm1\.weight'"):
        load_model(tmp_path)


def test_missing_weights_and_bad_index_are_named(tmp_path, twin_root):
    import shutil

    from modeling.hf_checkpoint import checkpoint_weight_map

    (tmp_path / "config.json").write_text("{}")
    (tmp_path / "pytorch_model.bin").write_bytes(b"")
    with pytest.raises(FileNotFoundError, match="only safetensors checkpoints are read"):
        checkpoint_weight_map(tmp_path)
    broken = tmp_path / "broken"
    shutil.copytree(twin_root / "qwen3", broken)
    next(broken.glob("model-00002-of-*.safetensors")).unlink()
    with pytest.raises(FileNotFoundError, match="names shard model-00002-of-"):
        checkpoint_weight_map(broken)
    from modeling.hf_checkpoint import architecture_class, load_hf_config

    config = load_hf_config(twin_root / "qwen3")
    config.architectures = ["Qwen3Model"]  # no LM head: no token log-probs
    with pytest.raises(ValueError, match="'Qwen3Model' is not a generative language model class"):
        architecture_class(config)
    config.architectures = ["Qwen9ForCausalLM"]
    with pytest.raises(ValueError, match="'Qwen9ForCausalLM' is not a class of transformers"):
        architecture_class(config)


# -- hub ids through the Hugging Face cache ---------------------------------------------------------


def _write_cache_snapshot(cache: Path, repo_id: str, revision: str, twin_dir: Path) -> Path:
    """The hub cache layout, written by us: models--org--name/{blobs,snapshots/<rev>,refs/main}."""
    repo = cache / ("models--" + repo_id.replace("/", "--"))
    snapshot = repo / "snapshots" / revision
    snapshot.mkdir(parents=True)
    (repo / "blobs").mkdir()
    for f in twin_dir.iterdir():  # the hub cache stores blobs by hash and links them from the snapshot
        blob = repo / "blobs" / f"blob-{f.name}"
        blob.write_bytes(f.read_bytes())
        (snapshot / f.name).symlink_to(os.path.relpath(blob, snapshot))
    (repo / "refs").mkdir()
    (repo / "refs" / "main").write_text(revision)
    return snapshot


def test_hub_id_resolves_from_the_cache_offline_and_its_absence_is_named(twin_root, tmp_path, monkeypatch):
    from learner.config import ModelConfig
    from modeling.hf_checkpoint import resolve_model_path
    from modeling.model import load_policy

    cache = tmp_path / "hub"
    rev = "0123456789abcdef0123456789abcdef01234567"
    snapshot = _write_cache_snapshot(cache, "tiny-org/Tiny-Qwen3.5", rev, twin_root / "qwen3_5")
    monkeypatch.setenv("HF_HUB_CACHE", str(cache))
    assert resolve_model_path("tiny-org/Tiny-Qwen3.5") == snapshot
    assert resolve_model_path("tiny-org/Tiny-Qwen3.5", revision=rev) == snapshot
    model, tokenizer = load_policy("tiny-org/Tiny-Qwen3.5")
    assert type(model).__name__ == "Qwen3_5ForConditionalGeneration" and len(tokenizer) == 1024
    with pytest.raises(FileNotFoundError, match=rf"'tiny-org/absent' is not in the Hugging Face cache {cache}"):
        resolve_model_path("tiny-org/absent")
    with pytest.raises(FileNotFoundError, match="at revision 'v2'"):
        resolve_model_path("tiny-org/Tiny-Qwen3.5", revision="v2")
    with pytest.raises(ValueError, match="does not exist and is not a hub id"):
        resolve_model_path(str(tmp_path / "no" / "such" / "dir"))
    with pytest.raises(FileNotFoundError, match="has no config.json"):
        resolve_model_path(tmp_path)
    ModelConfig(kind="pretrained", path="tiny-org/Tiny-Qwen3.5", revision=rev)
    with pytest.raises(ValueError, match="model.revision is for hub ids"):
        ModelConfig(kind="pretrained", path=str(snapshot), revision=rev)


def test_model_fetch_offline_fails_with_a_clear_message(tmp_path, capsys):
    from envs.cli import main

    # huggingface_hub reads HF_HUB_OFFLINE when it is imported: a fresh process sees the setting.
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "HF_HUB_CACHE": str(tmp_path)}
    proc = subprocess.run([sys.executable, "-m", "envs.cli", "model", "fetch", "tiny-org/never-fetched"],
                          capture_output=True, text=True, env=env, timeout=120, cwd=Path(__file__).parents[2])
    assert proc.returncode == 2
    assert "could not download 'tiny-org/never-fetched'" in proc.stderr and str(tmp_path) in proc.stderr
    assert "HF_HUB_OFFLINE" in proc.stderr
    # Without HF_HUB_OFFLINE from the user, fetch goes online although importing the project sets it
    # (envs/_runtime.py): here it reaches a closed local port, and says so.
    online = {k: v for k, v in env.items() if k != "HF_HUB_OFFLINE"} | {"HF_ENDPOINT": "http://127.0.0.1:9"}
    proc = subprocess.run([sys.executable, "-m", "envs.cli", "model", "fetch", "tiny-org/never-fetched"],
                          capture_output=True, text=True, env=online, timeout=120, cwd=Path(__file__).parents[2])
    assert proc.returncode == 2 and "could not download 'tiny-org/never-fetched'" in proc.stderr
    assert "Connection refused" in proc.stderr and "HF_HUB_OFFLINE is set" not in proc.stderr
    assert main(["model", "fetch", "not a model id", "--cache-dir", str(tmp_path)]) == 2
    assert "is not of the form 'org/name'" in capsys.readouterr().err


def test_a_run_starts_from_a_cached_hub_id_and_names_a_missing_one(twin_root, tmp_path, monkeypatch):
    from learner.config import validate_config
    from learner.sft import prepare_policy

    cache = tmp_path / "hub"
    snapshot = _write_cache_snapshot(cache, "tiny-org/Tiny-Llama", "a" * 40, twin_root / "llama_tied")
    monkeypatch.setenv("HF_HUB_CACHE", str(cache))

    def config(path: str):
        return validate_config({"name": "t", "output_dir": str(tmp_path / "run"), "model": {"kind": "pretrained",
                                "path": path}, "data": {"domains": ["ward"], "domain_modules": WARD}})

    assert prepare_policy(config("tiny-org/Tiny-Llama"), tmp_path / "run", log=lambda _: None) == snapshot
    with pytest.raises(FileNotFoundError, match=rf"model.path: model 'tiny-org/Nope' is not in the Hugging Face "
                                                rf"cache {cache}.*hcgym model fetch tiny-org/Nope"):
        prepare_policy(config("tiny-org/Nope"), tmp_path / "run2", log=lambda _: None)


# -- every component holds the same weights --------------------------------------------------------


def _generate_samples(generator, tokenizer, prompts: list[str], version: int, max_new_tokens: int = 6):
    from actors.generator import GenerationRequest

    requests = [GenerationRequest(request_id=f"r{i}", prompt_ids=tokenizer.encode(p, add_special_tokens=False),
                                  max_new_tokens=max_new_tokens, seed=i)
                for i, p in enumerate(prompts)]
    samples = []
    for i, (req, res) in enumerate(zip(requests, generator.generate(requests))):
        ids = list(req.prompt_ids) + list(res.token_ids)
        n_prompt = len(req.prompt_ids)
        samples.append(RolloutSample(
            sample_id=f"g:{i}", task_id="g", domain="synthetic", group_id="g", seed=i, prompt_length=n_prompt,
            input_ids=ids, loss_mask=[0] * n_prompt + [1] * len(res.token_ids),
            sampling_logprobs=[0.0] * n_prompt + list(res.logprobs),
            policy_versions=[-1] * n_prompt + [version] * len(res.token_ids),
            turns=[TurnSpan(start=n_prompt, end=len(ids))], reward=float(i % 2), correct=bool(i % 2),
            reward_components={"accuracy": float(i % 2), "total": float(i % 2)}, response_tokens=len(res.token_ids)))
    return samples


def _teacher_gap(teacher, samples) -> float:
    """Max |teacher - generator| log-prob over the sampled tokens."""
    gap = 0.0
    for s, out in zip(samples, teacher.compute(samples)):
        for p, m in enumerate(s.loss_mask):
            if m:
                gap = max(gap, abs(out.logprobs[p] - s.sampling_logprobs[p]))
    return gap


PROMPTS = ["Check the interaction between warfarin and aspirin", "Creatinine clearance is 45", "Answer: B."]


def _learner_cfg(backend: str, **extra):
    from modeling.config_models import LearnerConfig

    return LearnerConfig(backend=backend, optim={"lr": 1e-2, "micro_batch_size": 2},
                         deepspeed={"world_size": 2 if backend == "deepspeed" else 1, "num_cpus_per_rank": 1},
                         **extra)


def assert_components_agree(model_dir: Path, learner, family: str):
    """Generator, learner and teacher agree before and after one learner step."""
    from actors.generator import SamplingConfig
    from actors.generator_hf import HFGenerator
    from actors.teacher import Teacher
    from modeling.config_models import TeacherConfig
    from modeling.model import IM_END, load_tokenizer

    tokenizer = load_tokenizer(model_dir)
    generator = HFGenerator(str(model_dir), SamplingConfig(), [tokenizer.convert_tokens_to_ids(IM_END)])
    teacher = Teacher(TeacherConfig(hints={"enabled": False}), str(model_dir), start_worker=False)
    before = _generate_samples(generator, tokenizer, PROMPTS, 0)
    assert learner.evaluate_loss(before)["logprob_abs_diff"] < LOGPROB_TOL
    assert _teacher_gap(teacher, before) < LOGPROB_TOL

    initial = learner.get_state_dict()
    learner.train_step(before, step=1)
    weights = learner.get_state_dict()
    # Published under the checkpoint's own names; a tied lm_head.weight is included.
    assert set(weights) == set(generator.model.state_dict()) and "lm_head.weight" in weights
    if family == "llama_tied":
        assert torch.equal(weights["lm_head.weight"], weights["model.embed_tokens.weight"])
    moved = [k for k in weights if not torch.equal(weights[k], initial[k])]
    if family == "qwen3_5":  # the vision tower is frozen by default; the language model trains
        assert moved and not any(k.startswith("model.visual.") for k in moved)
        assert any(k.startswith("model.language_model.") for k in moved)
    generator.update_weights(weights, 1)
    teacher.hard_copy(weights)
    after = _generate_samples(generator, tokenizer, PROMPTS, 1)
    assert learner.evaluate_loss(after)["logprob_abs_diff"] < LOGPROB_TOL
    assert _teacher_gap(teacher, after) < LOGPROB_TOL
    # The step really changed what everyone computes: the pre-step log-probs no longer match.
    assert learner.evaluate_loss(before)["logprob_abs_diff"] > STEP_MOVES_LOGPROBS
    assert _teacher_gap(teacher, before) > STEP_MOVES_LOGPROBS
    teacher.shutdown()
    return weights


@pytest.mark.parametrize("family", TWIN_FAMILIES)
def test_generator_torch_learner_and_teacher_agree_before_and_after_a_step(twin_root, family, tmp_path):
    import transformers

    from modeling.hf_checkpoint import checkpoint_metadata, load_model
    from learner.learner_actor import Learner

    model_dir = twin_root / family
    learner = Learner(_learner_cfg("torch"), str(model_dir))
    try:
        weights = assert_components_agree(model_dir, learner, family)
        # The learner's checkpoint is a Hugging Face checkpoint that transformers loads unchanged.
        learner.save_checkpoint(str(tmp_path), max_shard_size="1MB")
    finally:
        learner.shutdown()
    saved = tmp_path / "learner" / "policy"
    assert len(set(_weight_map(saved).values())) >= 2
    assert checkpoint_metadata(saved)["policy_version"] == "1"
    auto = transformers.AutoModelForImageTextToText if family == "qwen3_5" else transformers.AutoModelForCausalLM
    reloaded = auto.from_pretrained(str(saved)).state_dict()
    assert all(torch.equal(reloaded[k], weights[k]) for k in weights)
    assert transformers.AutoTokenizer.from_pretrained(str(saved)).chat_template
    assert all(torch.equal(v, weights[k]) for k, v in load_model(saved).state_dict().items())


@pytest.mark.ray
@pytest.mark.parametrize("family", ["qwen3_5", "llama_tied"])
def test_zero3_two_ranks_agree_with_generator_and_teacher(ray_cluster, twin_root, family):
    """Packed forwards under ZeRO-3 (gathered parameters, Qwen3.5's linear-attention layers run once per
    sequence) against the generator's incremental log-probs, before and after a step."""
    from learner.learner_actor import Learner

    model_dir = twin_root / family
    learner = Learner(_learner_cfg("deepspeed", pack_sequences=True), str(model_dir))
    try:
        assert_components_agree(model_dir, learner, family)
    finally:
        learner.shutdown()


def test_vision_tower_trains_only_when_configured(twin_root):
    from learner.backends.torch_backend import TorchBackend
    from modeling.hf_checkpoint import freeze_vision_tower, load_model

    model_dir = str(twin_root / "qwen3_5")
    frozen = TorchBackend(_learner_cfg("torch"), model_dir, seed=0)
    trainable = TorchBackend(_learner_cfg("torch", train_vision_tower=True), model_dir, seed=0)

    def optimised(backend) -> set[str]:
        ids = {id(p) for g in backend._optimizer.param_groups for p in g["params"]}
        return {n for n, p in backend.policy.named_parameters() if id(p) in ids}

    visual = {n for n, _ in frozen.policy.named_parameters() if n.startswith("model.visual.")}
    assert visual and not visual & optimised(frozen)
    assert visual <= optimised(trainable)
    assert {n for n, _ in frozen.policy.named_parameters()} - visual <= optimised(frozen)
    assert freeze_vision_tower(load_model(twin_root / "qwen3"), train_vision_tower=False) == []


def test_receivers_accept_a_subset_and_name_unknown_weights(twin_root):
    from actors.generator import SamplingConfig
    from actors.generator_hf import HFGenerator

    generator = HFGenerator(str(twin_root / "qwen3_5"), SamplingConfig(), [0])
    state = generator.model.state_dict()
    language_only = {k: v + 0.5 for k, v in state.items() if not k.startswith("model.visual.")}
    generator.update_weights(language_only, 3)
    after = generator.model.state_dict()
    assert generator.version == 3
    assert all(torch.equal(after[k], v) for k, v in language_only.items())
    with pytest.raises(ValueError, match=r"unknown\) name\(s\).*model\.layers\.0\.mlp\.up_proj\.weight"):
        # the text-model name of a multimodal checkpoint's weight is unknown to it
        generator.update_weights({"model.layers.0.mlp.up_proj.weight": torch.zeros(1)}, 4)
    assert generator.version == 3


def test_finished_rows_leave_the_batch_for_every_cache_kind(twin_root):
    """The generator drops finished rows from its KV cache: per-token keys/values (Qwen3, Llama) and
    Qwen3.5's linear-attention conv/recurrent states alike; tokens and log-probs are those of a
    batch that keeps its finished rows."""
    from actors.generator import GenerationRequest, SamplingConfig
    from actors.generator_hf import HFGenerator
    from modeling.model import IM_END, load_tokenizer

    for family in TWIN_FAMILIES:
        model_dir = str(twin_root / family)
        tokenizer = load_tokenizer(model_dir)
        stop = [tokenizer.convert_tokens_to_ids(IM_END)]
        requests = [GenerationRequest(request_id=f"r{i}", prompt_ids=tokenizer.encode(p, add_special_tokens=False),
                                      max_new_tokens=n, seed=i)
                    for i, (p, n) in enumerate(zip(PROMPTS + PROMPTS[:1], [1, 12, 3, 7]))]
        compact = HFGenerator(model_dir, SamplingConfig(), stop)
        full = HFGenerator(model_dir, SamplingConfig(), stop, options={"compact_finished_rows": False})
        packed, kept = compact.generate(requests), full.generate(requests)
        assert compact.cache_stats["compactions"] >= 2, family
        assert compact.cache_stats["decode_row_steps"] < full.cache_stats["decode_row_steps"], family
        for a, b in zip(packed, kept):
            assert a.token_ids == b.token_ids and a.finish_reason == b.finish_reason, (family, a.request_id)
            assert max(abs(x - y) for x, y in zip(a.logprobs, b.logprobs)) < LOGPROB_TOL, (family, a.request_id)


def test_save_sharded_checkpoint_checks_names_and_sft_output_loads(twin_root, tmp_path):
    import transformers

    from modeling.hf_checkpoint import load_model, parse_size, save_sharded_checkpoint
    from modeling.model import load_tokenizer
    from learner.sft import SFTExample, run_sft

    assert parse_size("5GB") == 5 * 10**9 and parse_size("2MiB") == 2 * 2**20 and parse_size(7) == 7
    with pytest.raises(ValueError, match="max_shard_size='lots'"):
        parse_size("lots")
    src = twin_root / "llama_tied"
    state = load_model(src).state_dict()
    with pytest.raises(ValueError, match=r"unknown \['model.bogus'\]"):
        save_sharded_checkpoint(tmp_path / "x", {**state, "model.bogus": torch.zeros(1)}, source_dir=src)
    with pytest.raises(ValueError, match=r"missing \['model.norm.weight'\]"):
        save_sharded_checkpoint(tmp_path / "x", {k: v for k, v in state.items() if k != "model.norm.weight"},
                                source_dir=src)
    half = save_sharded_checkpoint(tmp_path / "half", state, source_dir=src, dtype=torch.bfloat16, max_shard_size="1MB")
    assert transformers.AutoModelForCausalLM.from_pretrained(str(half)).dtype == torch.bfloat16

    tok = load_tokenizer(src)
    ids = tok.encode("Check the interaction between warfarin and aspirin before prescribing.", add_special_tokens=False)
    examples = [SFTExample(ids, [0] * 3 + [1] * (len(ids) - 3))] * 2
    run_sft(src, tmp_path / "sft", examples, epochs=1, lr=1e-2, batch_size=2, seed=0, max_shard_size="1MB",
            log=lambda _: None)
    out = tmp_path / "sft"
    assert len(set(_weight_map(out).values())) >= 2 and "lm_head.weight" not in _weight_map(out)
    tuned = transformers.AutoModelForCausalLM.from_pretrained(str(out))
    assert tuned.lm_head.weight is tuned.model.embed_tokens.weight
    assert not torch.equal(tuned.model.norm.weight, state["model.norm.weight"])
    assert transformers.AutoTokenizer.from_pretrained(str(out)).chat_template


# -- packed sequences --------------------------------------------------------------------------------


@pytest.mark.parametrize("family", TWIN_FAMILIES)
def test_packed_forwards_equal_the_padded_ones(twin_root, family):
    """Rows of unequal length packed into one sequence (position ids restarting per row, no decoder
    position on padding): log-probs, entropies and gradients (also under gradient checkpointing, whose
    backward recomputes the layers) equal the padded pass's within 1e-5. Qwen3.5's linear-attention
    layers run each packed sequence on its own: a recurrent state or conv window carried over from
    the previous row would move the next row's values far beyond 1e-5."""
    from modeling.attention import SDPA_VARLEN, decoder_config
    from modeling.model import load_policy, pad_batch, packing_unsupported, packs_sequences, token_stats

    model, _ = load_policy(twin_root / family)
    assert decoder_config(model)._attn_implementation == SDPA_VARLEN  # packed rows attend per sequence
    generator = torch.Generator().manual_seed(0)
    rows = [torch.randint(5, 900, (n,), generator=generator).tolist() for n in (37, 5, 64, 1, 20)]
    ids, mask = pad_batch(rows, 0)
    trained = mask.clone()
    trained[:, :3] = 0
    assert packing_unsupported(model) is None and packs_sequences("auto", model, mask)
    for positions in (None, trained > 0):
        padded = token_stats(model, ids, mask, with_entropy=True, positions=positions)
        packed = token_stats(model, ids, mask, with_entropy=True, positions=positions, packed=True)
        assert torch.allclose(padded.logprobs, packed.logprobs, atol=1e-5)
        assert torch.allclose(padded.entropy, packed.entropy, atol=1e-5)
    left_ids, left_mask = pad_batch(rows, 0, side="left")
    padded = token_stats(model, left_ids, left_mask, with_entropy=True)
    packed = token_stats(model, left_ids, left_mask, with_entropy=True, packed=True)
    assert torch.allclose(padded.logprobs, packed.logprobs, atol=1e-5)
    assert torch.allclose(padded.entropy, packed.entropy, atol=1e-5)
    model.train()
    for checkpointing in (False, True):
        if checkpointing:
            model.gradient_checkpointing_enable({"use_reentrant": False})
        grads = []
        for packed in (False, True):
            model.zero_grad()
            token_stats(model, ids, mask, positions=trained > 0, packed=packed).logprobs.sum().backward()
            grads.append([p.grad.clone() for p in model.parameters() if p.grad is not None])
        assert grads[0] and all(torch.allclose(a, b, atol=1e-5) for a, b in zip(*grads))
    model.gradient_checkpointing_disable()
    model.eval()
    # A row's statistics do not depend on its neighbours: alone it gives the same values as packed.
    alone = token_stats(model, ids[2:3, :64], mask[2:3, :64], packed=True).logprobs
    assert torch.allclose(alone, token_stats(model, ids, mask, packed=True).logprobs[2:3, :64], atol=1e-5)


@contextlib.contextmanager
def _attention(model, name: str):
    """`model`'s decoder on attention implementation `name` inside the block."""
    from modeling.attention import decoder_config

    config = decoder_config(model)
    before = config._attn_implementation
    config._attn_implementation = name
    try:
        yield model
    finally:
        config._attn_implementation = before


@pytest.mark.parametrize("family", TWIN_FAMILIES)
def test_varlen_attention_is_sdpa_except_that_packed_rows_attend_per_sequence(twin_root, family):
    """`sdpa_varlen` (modeling/attention.py) builds no [N, N] mask for a packed row and attends within
    each sequence: packed it equals sdpa's dense block mask within 1e-5, and a sequence's values do not
    move when another sequence of the row changes (they would if attention crossed the boundary).
    Padded batches (right, left) and cached decoding (a prefill, then 2 tokens and 1 token against the
    cache, left padded) are transformers' sdpa bit for bit."""
    from transformers.masking_utils import create_causal_mask

    from modeling.attention import SDPA_VARLEN, decoder_config
    from modeling.model import load_policy, pad_batch, position_ids_from_mask, token_stats

    model, _ = load_policy(twin_root / family)
    config = decoder_config(model)
    generator = torch.Generator().manual_seed(1)
    rows = [torch.randint(5, 900, (n,), generator=generator).tolist() for n in (23, 40, 9)]
    ids, mask = pad_batch(rows, 0)
    # The mask side: none for a packed row under sdpa_varlen, sdpa's dense block mask otherwise.
    flat_positions = position_ids_from_mask(mask)[mask.bool()].unsqueeze(0)
    embeds = torch.zeros((1, flat_positions.shape[1], 8))
    assert create_causal_mask(config, embeds, None, None, position_ids=flat_positions) is None
    with _attention(model, "sdpa"):
        dense = create_causal_mask(config, embeds, None, None, position_ids=flat_positions)
    assert dense.shape == (1, 1, 72, 72) and not dense[0, 0, 30, 10] and dense[0, 0, 30, 23]

    packed = token_stats(model, ids, mask, with_entropy=True, packed=True)
    with _attention(model, "sdpa"):
        dense_packed = token_stats(model, ids, mask, with_entropy=True, packed=True)
    assert torch.allclose(packed.logprobs, dense_packed.logprobs, atol=1e-5)
    assert torch.allclose(packed.entropy, dense_packed.entropy, atol=1e-5)
    changed = ids.clone()
    changed[1, :40] = torch.randint(5, 900, (40,), generator=generator)
    moved = token_stats(model, changed, mask, packed=True).logprobs
    assert (moved[1] - packed.logprobs[1]).abs().max() > 1e-3
    for row in (0, 2):
        assert (moved[row] - packed.logprobs[row]).abs().max() <= 1e-6, row

    for side in ("right", "left"):
        ids, mask = pad_batch(rows, 0, side=side)
        varlen = token_stats(model, ids, mask, with_entropy=True)
        with _attention(model, "sdpa"):
            sdpa = token_stats(model, ids, mask, with_entropy=True)
        assert torch.equal(varlen.logprobs, sdpa.logprobs) and torch.equal(varlen.entropy, sdpa.entropy), side

    ids, mask = pad_batch([r[:12] for r in rows[:2]] + [rows[2][:5]], 0, side="left")
    steps = [torch.randint(5, 900, (3, 2), generator=generator), torch.randint(5, 900, (3, 1), generator=generator)]

    def decode() -> list[torch.Tensor]:
        full_mask = mask
        out = model(input_ids=ids, attention_mask=mask, position_ids=position_ids_from_mask(mask), use_cache=True)
        logits, cache = [out.logits], out.past_key_values
        for step in steps:
            full_mask = torch.cat([full_mask, torch.ones_like(step)], dim=1)
            position_ids = position_ids_from_mask(full_mask)[:, -step.shape[1]:]
            out = model(input_ids=step, attention_mask=full_mask, position_ids=position_ids, past_key_values=cache,
                        use_cache=True)
            logits.append(out.logits)
            cache = out.past_key_values
        return logits

    with torch.no_grad():
        varlen = decode()
        with _attention(model, "sdpa"):
            sdpa = decode()
    assert config._attn_implementation == SDPA_VARLEN
    assert all(torch.equal(a, b) for a, b in zip(varlen, sdpa))


def test_packing_is_refused_by_name_for_recurrent_layers_without_a_per_sequence_path():
    """LFM2's short-conv layers ("conv") carry a conv window along the row and have no per-sequence
    path here: packing them is refused, naming the layer kind."""
    import transformers

    from modeling.model import packing_unsupported, packs_sequences, token_stats

    config = transformers.Lfm2Config(vocab_size=64, hidden_size=32, intermediate_size=64, num_hidden_layers=2,
                                     num_attention_heads=2, num_key_value_heads=1, full_attn_idxs=[1])
    model = transformers.Lfm2ForCausalLM(config).eval()
    ids, mask = torch.randint(3, 64, (2, 6)), torch.ones(2, 6, dtype=torch.long)
    assert "conv layers" in packing_unsupported(model)
    assert not packs_sequences(True, model, mask)
    with pytest.raises(ValueError, match="packed sequences: .*conv layers"):
        token_stats(model, ids, mask, packed=True)
