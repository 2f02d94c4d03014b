"""The weight-sync transport is chosen from the members' device identities: NCCL only when no two
members share a GPU, gloo with CPU-staged buckets otherwise (a learner and a generator colocated on
one GPU). The decision is a pure function; the colocated transport runs as a real 3-process group."""

from __future__ import annotations

import multiprocessing as mp
import threading

import pytest
import torch

from learner.learner_actor import free_port
from modeling.config_models import WeightSyncConfig
from modeling.weight_sync import (
    DeviceIdentity,
    WeightSyncError,
    WeightSyncGroup,
    choose_transport,
    local_device_identity,
    manifest_from_tensors,
)

NAMES = ["learner-rank0", "vllm-0", "teacher"]


def gpu(node: str, uuid: str | None = None, pci: str | None = None, index: int = 0) -> DeviceIdentity:
    return DeviceIdentity(node=node, device="cuda", uuid=uuid, pci_bus_id=pci, index=index)


def test_distinct_gpus_on_one_node_use_nccl():
    d = choose_transport([gpu("n1", "GPU-a", index=0), gpu("n1", "GPU-b", index=1), gpu("n1", "GPU-c", index=2)],
                         NAMES, "nccl")
    assert (d.backend, d.bucket_device, d.name) == ("nccl", "cuda", "nccl")
    assert "3 distinct devices" in d.reason


def test_same_gpu_index_on_different_nodes_is_not_a_shared_gpu():
    # Every Ray actor sees its GPU as cuda:0, and identical servers have identical PCI bus ids.
    assert choose_transport([gpu("n1", "GPU-a"), gpu("n2", "GPU-b")], NAMES[:2], "nccl").backend == "nccl"
    same_bus = [gpu("n1", pci="0000:18:00"), gpu("n2", pci="0000:18:00")]
    assert choose_transport(same_bus, NAMES[:2], "nccl").backend == "nccl"


def test_two_members_on_one_gpu_stage_through_cpu_and_the_reason_names_them():
    ids = [gpu("n1", "GPU-a", index=0), gpu("n1", "GPU-a", index=0), gpu("n1", "GPU-b", index=1)]
    d = choose_transport(ids, NAMES, "nccl")
    assert (d.backend, d.bucket_device, d.name) == ("gloo", "cpu", "gloo-cpu-staged")
    assert "learner-rank0 and vllm-0 share GPU uuid GPU-a" in d.reason and "teacher" not in d.reason
    # Without UUIDs, the PCI bus id on one machine identifies the GPU.
    by_bus = [gpu("n1", pci="0000:18:00", index=0), gpu("n1", pci="0000:18:00", index=1)]
    assert choose_transport(by_bus, NAMES[:2], "nccl").backend == "gloo"


def test_a_cpu_member_or_a_gloo_config_means_gloo():
    d = choose_transport([gpu("n1", "GPU-a"), DeviceIdentity(node="n1", device="cpu")], NAMES[:2], "nccl")
    assert d.backend == "gloo" and "vllm-0 on the CPU" in d.reason
    assert choose_transport([gpu("n1", "GPU-a"), gpu("n1", "GPU-b")], NAMES[:2], "gloo").bucket_device == "cpu"
    with pytest.raises(ValueError, match="2 identities for 3 members"):
        choose_transport([gpu("n1", "GPU-a"), gpu("n1", "GPU-b")], NAMES, "nccl")


def test_local_identity_on_this_machine():
    ident = local_device_identity("cpu")
    assert ident.device == "cpu" and ident.node and ident.gpu_key() is None


def _tensors() -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(7)
    return {"embed.weight": torch.randn(64, 16, generator=g), "layer.0.w": torch.randn(16, 16, generator=g),
            "layer.0.b": torch.randn(16, generator=g).to(torch.bfloat16),
            "head.scale": torch.randn(3, generator=g).to(torch.bfloat16)}


def _member(rank: int, port: int, identity: dict, out) -> None:
    """One group member in its own process: rank 0 sends `_tensors()`, receivers return what arrived."""
    try:
        cfg = WeightSyncConfig(transport="collective", backend="nccl", bucket_mb=0.002, timeout_s=60,
                               master_port=port)
        group = WeightSyncGroup(rank, 3, cfg, NAMES, device="cuda", identity=identity)
        if rank == 0:
            tensors = _tensors()
            manifest = manifest_from_tensors([(k, v.shape, v.dtype) for k, v in tensors.items()], 1,
                                             int(cfg.bucket_mb * 2**20))
            sent = group.send(manifest, tensors.items())
            out.put((rank, group.transport, group.transport_reason, sent["buckets"]))
        else:
            got = {k: v.clone() for k, v in group.receive(1)}
            out.put((rank, group.transport, group.transport_reason, got))
    except BaseException as exc:  # noqa: BLE001 - reported to the parent, which fails the test
        out.put((rank, "error", repr(exc), None))


def test_colocated_members_transfer_weights_bit_exactly_over_the_cpu_staged_transport():
    ctx = mp.get_context("spawn")
    out = ctx.Queue()
    port = free_port()
    # The learner and vLLM report one GPU (as on a one-GPU node), the teacher another.
    identities = [gpu("node-1", "GPU-shared").model_dump(), gpu("node-1", "GPU-shared").model_dump(),
                  gpu("node-1", "GPU-other", index=1).model_dump()]
    procs = [ctx.Process(target=_member, args=(r, port, identities[r], out), daemon=True) for r in range(3)]
    for p in procs:
        p.start()
    results = {}
    try:
        for _ in range(3):
            rank, transport, reason, payload = out.get(timeout=120)
            results[rank] = (transport, reason, payload)
    finally:
        for p in procs:
            p.join(timeout=30)
            if p.is_alive():
                p.kill()
    errors = {r: v[1] for r, v in results.items() if v[0] == "error"}
    assert not errors, errors
    assert {v[0] for v in results.values()} == {"gloo-cpu-staged"}
    assert all("learner-rank0 and vllm-0 share GPU" in v[1] for v in results.values())
    assert results[0][2] > 1  # several buckets travelled
    expected = _tensors()
    for rank in (1, 2):
        got = results[rank][2]
        assert list(got) == list(expected)
        for k, v in expected.items():
            assert got[k].dtype == v.dtype and torch.equal(got[k], v), (rank, k)


def test_a_communicator_that_cannot_be_created_is_a_weight_sync_error_naming_the_peers():
    # Three distinct GPUs decide NCCL; this CPU build of torch cannot create it.
    if torch.cuda.is_available():
        pytest.skip("needs a machine where NCCL cannot be created (CPU-only torch); a GPU would create it")
    cfg = WeightSyncConfig(transport="collective", backend="nccl", timeout_s=5, master_port=free_port())
    errors: dict[int, BaseException] = {}

    def member(rank: int) -> None:
        try:
            WeightSyncGroup(rank, 2, cfg, NAMES[:2], identity=gpu("n1", f"GPU-{rank}"))
        except BaseException as exc:  # noqa: BLE001
            errors[rank] = exc

    threads = [threading.Thread(target=member, args=(r,), daemon=True) for r in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=60)
    assert set(errors) == {0, 1}
    for exc in errors.values():
        assert isinstance(exc, WeightSyncError), repr(exc)
        assert "learner-rank0 (uuid GPU-0)" in str(exc) and "vllm-0 (uuid GPU-1)" in str(exc)
