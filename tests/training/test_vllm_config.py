"""The vllm backend's settings checked when the config loads, the engine environment per platform,
and the weight-sync rank layout with tensor parallelism. No engine starts here: the engines run in
test_generator_vllm.py, whose GPU-topology engine runs at tensor parallel 2 on vLLM's CPU build
(each TP worker joins the group as `rank_offset + tp_rank`, with the layout tested here).
"""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from learner.config import GeneratorConfig
from learner.weight_publisher import weight_sync_layout


def test_tensor_parallel_needs_one_gpu_per_worker():
    GeneratorConfig(backend="vllm", num_gpus=2, options={"tensor_parallel_size": 2})
    GeneratorConfig(backend="vllm", num_gpus=1)
    with pytest.raises(ValidationError, match=r"generator\.num_gpus \(1\) must equal "
                                              r"generator\.options\.tensor_parallel_size \(2\)"):
        GeneratorConfig(backend="vllm", num_gpus=1, options={"tensor_parallel_size": 2})
    with pytest.raises(ValidationError, match=r"generator\.num_gpus \(0\.5\).*tensor_parallel_size \(1\)"):
        GeneratorConfig(backend="vllm", num_gpus=0.5)
    GeneratorConfig(backend="hf", num_gpus=0.5)  # the hf backend has no such option


def test_cpu_options_known_to_fail_are_refused_at_load():
    """On vLLM's CPU build (num_gpus 0) chunked prefill of seeded requests fails mid-run: turning it on,
    or a token budget below max_model_len (which vLLM needs with chunking off), is refused."""
    cfg = GeneratorConfig(backend="vllm", options={"max_model_len": 2048, "max_num_batched_tokens": 65536})
    assert cfg.options["max_num_batched_tokens"] == 65536
    with pytest.raises(ValidationError, match=r"enable_chunked_prefill: true.*CPU Generator does not use offset"):
        GeneratorConfig(backend="vllm", options={"enable_chunked_prefill": True})
    with pytest.raises(ValidationError, match=r"max_num_batched_tokens \(1024\) is below "
                                              r"generator\.options\.max_model_len \(2048\)"):
        GeneratorConfig(backend="vllm", options={"max_model_len": 2048, "max_num_batched_tokens": 1024})
    # On GPU both are vLLM's business (its default chunks, and CUDA generators support it).
    GeneratorConfig(backend="vllm", num_gpus=1, options={"max_model_len": 2048, "max_num_batched_tokens": 1024,
                                                         "enable_chunked_prefill": True})
    with pytest.raises(ValidationError, match=r"(?s)generator\.options.*not_an_option"):
        GeneratorConfig(backend="vllm", options={"not_an_option": 1})


def test_engine_platform_settings():
    """CUDA: the engine core in its own process unless engine_in_process says otherwise, V1 model runner
    pinned, chunked prefill vLLM's default. CPU: in-process by default, chunked prefill off."""
    from actors.generator_vllm import VLLMOptions, engine_environment, engine_kwargs

    default = VLLMOptions()
    cuda = engine_environment(default, on_cuda=True)
    assert cuda == {"VLLM_USE_V2_MODEL_RUNNER": "0"}
    assert engine_environment(VLLMOptions(engine_in_process=True), on_cuda=True)["VLLM_ENABLE_V1_MULTIPROCESSING"] == "0"
    assert engine_environment(VLLMOptions(use_v2_model_runner=True), on_cuda=True)["VLLM_USE_V2_MODEL_RUNNER"] == "1"
    cpu = engine_environment(default, on_cuda=False)
    assert cpu["VLLM_ENABLE_V1_MULTIPROCESSING"] == "0" and cpu["VLLM_USE_V2_MODEL_RUNNER"] == "0"
    assert engine_environment(VLLMOptions(engine_in_process=False), on_cuda=False)["VLLM_ENABLE_V1_MULTIPROCESSING"] == "1"
    assert engine_kwargs(default, on_cuda=True) == {}
    assert engine_kwargs(default, on_cuda=False) == {"enable_chunked_prefill": False}
    with pytest.raises(ValueError, match="enable_chunked_prefill"):
        engine_kwargs(VLLMOptions(enable_chunked_prefill=True), on_cuda=False)


def test_weight_sync_ranks_are_allocated_per_engine_times_tensor_parallel():
    """Generator i's TP workers join as first_rank(i) + tp_rank: every rank of the group is taken by
    exactly one member and lies inside the world, the teacher included."""
    for generators, tp, teacher in [(1, 1, False), (2, 1, True), (2, 2, True), (3, 4, False), (4, 2, True)]:
        layout = weight_sync_layout(generators, tp, teacher)
        assert layout.world_size == 1 + generators * tp + int(teacher)
        members = [0] + [first + r for first in layout.generator_ranks for r in range(tp)]
        members += [layout.teacher_rank] if teacher else []
        assert sorted(members) == list(range(layout.world_size)), (generators, tp, teacher)
        assert len(set(layout.names)) == layout.world_size
    layout = weight_sync_layout(2, 2, True)
    assert layout.names == ["learner-rank0", "generator-0-tp0", "generator-0-tp1", "generator-1-tp0",
                            "generator-1-tp1", "teacher"]
    assert layout.generator_ranks == [1, 3] and layout.teacher_rank == 5
    assert weight_sync_layout(2, 1, False).names == ["learner-rank0", "generator-0", "generator-1"]
    assert GeneratorConfig(backend="vllm", num_gpus=2, options={"tensor_parallel_size": 2}).ranks_per_generator() == 2
    assert GeneratorConfig(backend="hf").ranks_per_generator() == 1
