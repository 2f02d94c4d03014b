"""Where the bf16 teacher keeps its fp32 EMA shadow (teacher.ema_shadow_device), and that the EMA
and hard-copy math is the same wherever it is."""

from __future__ import annotations

import pytest
import torch

from actors.teacher import Teacher
from modeling.config_models import TeacherConfig
from tests.training.learner_fixtures import tiny_model_dir


@pytest.fixture(scope="module")
def model_dir():
    return tiny_model_dir()


def shadow_devices(t: Teacher) -> set[torch.device]:
    return {v.device for v in t._shadow.values()}


def model_devices(t: Teacher) -> set[torch.device]:
    return {v.device for v in t.model.state_dict().values()}


@pytest.mark.parametrize("where", ["model", "cpu"])
def test_the_shadow_lives_where_configured_and_the_ema_math_is_unchanged(model_dir, where):
    alpha = 0.9
    t = Teacher(TeacherConfig(dtype="bfloat16", ema_alpha=alpha, ema_shadow_device=where), model_dir,
                start_worker=False)
    assert t.shadow_device == torch.device("cpu")  # the model is on the CPU here, so both settings are the CPU
    assert shadow_devices(t) == {torch.device("cpu")}
    state = t.model.state_dict()
    assert all(v.dtype == torch.float32 for v in t._shadow.values())
    assert all(t._shadow[k].data_ptr() != state[k].data_ptr() for k in state)  # its own storage
    base = {k: v.clone() for k, v in t._shadow.items()}
    gen = torch.Generator().manual_seed(0)
    student = {k: v + 1e-2 * torch.randn(v.shape, generator=gen) for k, v in base.items()}
    t.ema_update(student)
    for k in base:  # theta_T <- alpha * theta_T + (1 - alpha) * theta_S, in fp32; the model holds its bf16 rounding
        want = alpha * base[k] + (1 - alpha) * student[k]
        assert torch.allclose(t._shadow[k], want, atol=1e-6), k
        assert torch.equal(state[k], t._shadow[k].to(torch.bfloat16)), k
    t.hard_copy(student)
    assert all(torch.equal(t._shadow[k], student[k]) for k in base)
    assert all(torch.equal(state[k], student[k].to(torch.bfloat16)) for k in base)
    assert t.get_weights().keys() == base.keys()


def test_an_unknown_shadow_device_is_refused():
    with pytest.raises(ValueError, match="ema_shadow_device"):
        TeacherConfig(ema_shadow_device="gpu")


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a GPU: the shadow's device differs from the "
                                                         "model's only when the teacher runs on CUDA")
@pytest.mark.parametrize("where, expected", [("model", "cuda"), ("cpu", "cpu")])
def test_on_cuda_the_shadow_is_on_the_gpu_or_in_host_memory(model_dir, where, expected):
    t = Teacher(TeacherConfig(dtype="bfloat16", device="cuda", ema_alpha=0.9, ema_shadow_device=where), model_dir,
                start_worker=False)
    assert {d.type for d in shadow_devices(t)} == {expected}
    assert {d.type for d in model_devices(t)} == {"cuda"}
    student = {k: v.cpu() + 1e-2 for k, v in t._shadow.items()}
    before = {k: v.cpu().clone() for k, v in t._shadow.items()}
    t.ema_update(student)
    for k, v in t._shadow.items():
        assert torch.allclose(v.cpu(), 0.9 * before[k] + 0.1 * student[k], atol=1e-6)
