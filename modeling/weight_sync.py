"""Moving the learner's weights to the generators (every step) and to the teacher (at EMA steps).

Two transports behind one idea: the learner produces `(name, full tensor)` pairs one module at a
time (ZeRO-3 gathers a module, the pair is consumed, the module is released), and receivers load
them by name.

* CPU / small models, `object_store`: the learner returns a CPU state dict, the caller passes the
  `ObjectRef` straight to the receivers (`load_state_dict_into`).
* GPUs, `collective`: a private torch.distributed group (NCCL on GPUs; gloo works too and is
  what the CPU tests run) between the learner's rank 0 and the receivers. Tensors travel in
  dtype-homogeneous buckets capped at `bucket_mb`, so neither side ever materialises the whole
  model. Every blocking point has a timeout that raises `WeightSyncError` naming the peer(s)
  that did not arrive: the rendezvous (who never joined), each bucket broadcast (who stopped
  reporting progress), the manifest wait (the sender), and the final acknowledgements.

The protocol of one sync (version v), coordinated through the group's TCPStore:
    sender:    set  sync/v/manifest (JSON: names, shapes, dtypes, bucket plan)
    all:       broadcast bucket 0..B-1 from rank 0; receivers set sync/v/progress/<rank> = b
    receivers: set  sync/v/done/<rank>
    sender:    wait for every sync/v/done/<rank>

GPU status: the NCCL path is written against torch's public ProcessGroupNCCL API and shares all
of its logic with the gloo path the tests exercise, but it has not been run on a GPU in this
repository (no GPU was available while it was written).
"""

from __future__ import annotations

import contextlib
import json
import math
import time
from collections.abc import Iterable, Iterator
from datetime import timedelta

import torch
from pydantic import BaseModel, ConfigDict, Field

from modeling.config_models import WeightSyncConfig

_DTYPES = {str(d): d for d in (torch.float32, torch.bfloat16, torch.float16, torch.float64, torch.int64, torch.int32,
                               torch.uint8, torch.int8, torch.bool)}


class WeightSyncError(RuntimeError):
    """A weight transfer failed or timed out; the message names the peer(s) concerned."""


# ----------------------------------------------------------------------------------------------
# Object store (CPU)
# ----------------------------------------------------------------------------------------------


def load_state_dict_into(module: torch.nn.Module, state: dict[str, torch.Tensor]) -> None:
    """Copy weights into a module in place (dtype/device follow the module); names must match exactly."""
    own = module.state_dict()
    missing, extra = sorted(set(own) - set(state)), sorted(set(state) - set(own))
    if missing or extra:
        raise WeightSyncError(f"weights do not match the receiver: missing {missing[:5]}, unexpected {extra[:5]}")
    load_named_tensors(module, state.items())


def load_named_tensors(module: torch.nn.Module, pairs: Iterable[tuple[str, torch.Tensor]]) -> int:
    """Copy `(name, tensor)` pairs into a module's parameters/buffers as they arrive; returns the count."""
    own = module.state_dict()
    n = 0
    with torch.no_grad():
        for name, tensor in pairs:
            if name not in own:
                raise WeightSyncError(f"received tensor {name!r} that the receiver's model does not have")
            target = own[name]
            if tuple(target.shape) != tuple(tensor.shape):
                raise WeightSyncError(f"tensor {name!r}: received shape {tuple(tensor.shape)}, "
                                      f"receiver has {tuple(target.shape)}")
            target.copy_(tensor.to(device=target.device, dtype=target.dtype))
            n += 1
    return n


# ----------------------------------------------------------------------------------------------
# Manifest and buckets
# ----------------------------------------------------------------------------------------------


class TensorSpec(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str
    shape: list[int]
    dtype: str

    @property
    def numel(self) -> int:
        return math.prod(self.shape) if self.shape else 1

    @property
    def nbytes(self) -> int:
        return self.numel * torch.empty((), dtype=_DTYPES[self.dtype]).element_size()


class WeightManifest(BaseModel):
    """What will be sent, in order, and how it is bucketed; both sides derive the same plan from it."""

    model_config = ConfigDict(extra="forbid")
    version: int
    tensors: list[TensorSpec]
    buckets: list[list[int]] = Field(default_factory=list)  # indices into `tensors`


def manifest_from_tensors(named: Iterable[tuple[str, torch.Size | list[int], torch.dtype]], version: int,
                          bucket_bytes: int) -> WeightManifest:
    """Build a manifest from `(name, shape, dtype)` metadata (no tensor data needed)."""
    specs = []
    for name, shape, dtype in named:
        if str(dtype) not in _DTYPES:
            raise WeightSyncError(f"tensor {name!r} has unsupported dtype {dtype}")
        specs.append(TensorSpec(name=name, shape=list(shape), dtype=str(dtype)))
    return WeightManifest(version=version, tensors=specs, buckets=plan_buckets(specs, bucket_bytes))


def plan_buckets(specs: list[TensorSpec], bucket_bytes: int) -> list[list[int]]:
    """Group consecutive tensors of one dtype into buckets of at most `bucket_bytes`.

    A tensor larger than the cap travels alone (it cannot be split without a second protocol).
    Order is preserved, so the sender can fill buckets while the gather walks the model.
    """
    if bucket_bytes <= 0:
        raise ValueError(f"bucket_bytes must be > 0, got {bucket_bytes}")
    buckets: list[list[int]] = []
    current: list[int] = []
    size = 0
    dtype = None
    for i, spec in enumerate(specs):
        nbytes = spec.nbytes
        if current and (spec.dtype != dtype or size + nbytes > bucket_bytes):
            buckets.append(current)
            current, size = [], 0
        current.append(i)
        size += nbytes
        dtype = spec.dtype
    if current:
        buckets.append(current)
    return buckets


# ----------------------------------------------------------------------------------------------
# The collective group
# ----------------------------------------------------------------------------------------------


class WeightSyncGroup:
    """A private process group: rank 0 is the learner's rank 0 (sender), ranks 1.. are receivers.

    Args:
        rank: This member's rank (0 = sender).
        world_size: 1 + number of receivers.
        config: Transport settings (backend, bucket size, timeout, rendezvous address/port).
        peer_names: A readable name per rank (e.g. ["learner-rank0", "generator-0", "teacher"]),
            used in error messages.
        device: Where buckets live ("cuda" for NCCL, "cpu" for gloo).
    """

    def __init__(self, rank: int, world_size: int, config: WeightSyncConfig, peer_names: list[str] | None = None,
                 device: str | None = None):
        import torch.distributed as dist

        if world_size < 2:
            raise ValueError(f"a weight-sync group needs a sender and at least one receiver; world_size={world_size}")
        if not 0 <= rank < world_size:
            raise ValueError(f"rank {rank} outside [0, {world_size})")
        if config.master_port is None:
            raise ValueError("weight_sync.master_port must be set (every member must use the same port)")
        self.rank, self.world_size, self.config = rank, world_size, config
        self.names = peer_names or [f"rank{r}" for r in range(world_size)]
        if len(self.names) != world_size:
            raise ValueError(f"peer_names has {len(self.names)} entries, world_size is {world_size}")
        self.device = torch.device(device or ("cuda" if config.backend == "nccl" else "cpu"))
        self.timeout = timedelta(seconds=config.timeout_s)
        self._version = 0
        try:
            self.store = dist.TCPStore(config.master_addr, config.master_port, world_size, is_master=rank == 0,
                                       timeout=self.timeout, wait_for_workers=False)
        except Exception as exc:
            raise WeightSyncError(f"{self.names[rank]}: cannot reach the weight-sync store at "
                                  f"{config.master_addr}:{config.master_port} ({self.names[0]}): {exc}") from exc
        self.store.set(f"joined/{rank}", self.names[rank])
        self._wait_keys([f"joined/{r}" for r in range(world_size)], "join the weight-sync group")
        if config.backend == "gloo":
            self.pg = dist.ProcessGroupGloo(self.store, rank, world_size, self.timeout)
        else:
            # Lazily resolved: CPU builds of torch have no ProcessGroupNCCL.
            nccl = getattr(dist, "ProcessGroupNCCL", None)
            if nccl is None:
                raise WeightSyncError("weight_sync.backend='nccl' but this torch build has no NCCL (CPU build?)")
            opts = nccl.Options()
            opts._timeout = self.timeout
            self.pg = nccl(self.store, rank, world_size, opts)

    # -- store helpers ---------------------------------------------------------------------------
    def _wait_keys(self, keys: list[str], what: str) -> None:
        """Wait for store keys with the timeout; on expiry name the ranks whose keys are missing."""
        deadline = time.monotonic() + self.config.timeout_s
        pending = list(keys)
        while pending:
            pending = [k for k in pending if not self.store.check([k])]
            if not pending:
                return
            if time.monotonic() > deadline:
                ranks = [int(k.rsplit("/", 1)[1]) for k in pending if k.rsplit("/", 1)[1].isdigit()]
                who = ", ".join(self.names[r] for r in ranks) or ", ".join(pending)
                raise WeightSyncError(f"{self.names[self.rank]}: timed out after {self.config.timeout_s:.0f}s waiting "
                                      f"for {who} to {what}")
            time.sleep(0.005)

    def _broadcast(self, flat: torch.Tensor, bucket: int, version: int) -> None:
        import torch.distributed as dist

        opts = dist.BroadcastOptions()
        opts.rootRank = 0
        work = self.pg.broadcast([flat], opts)
        try:
            work.wait(self.timeout)
        except Exception as exc:
            raise WeightSyncError(self._stall_message(version, bucket, exc)) from exc

    def _stall_message(self, version: int, bucket: int, exc: Exception) -> str:
        if self.rank != 0:
            return (f"{self.names[self.rank]}: bucket {bucket} of weight sync v{version} from {self.names[0]} "
                    f"did not complete within {self.config.timeout_s:.0f}s ({exc})")
        behind = []
        for r in range(1, self.world_size):
            key = f"sync/{version}/progress/{r}"
            done = int(self.store.get(key)) if self.store.check([key]) else -1
            if done < bucket - 1:
                behind.append(f"{self.names[r]} (last bucket {done})")
        who = ", ".join(behind) or "a receiver"
        return f"{self.names[0]}: bucket {bucket} of weight sync v{version} stalled waiting for {who} ({exc})"

    # -- sending and receiving -------------------------------------------------------------------
    def send(self, manifest: WeightManifest, pairs: Iterable[tuple[str, torch.Tensor]]) -> dict[str, float]:
        """Rank 0: stream `(name, tensor)` pairs (in manifest order) to every receiver.

        The pairs may come straight from a ZeRO-3 gather: each tensor is copied into the current
        bucket before the next module is gathered.

        Returns:
            {"bytes": ..., "buckets": ..., "seconds": ...}.
        """
        if self.rank != 0:
            raise WeightSyncError(f"{self.names[self.rank]} is a receiver; only rank 0 sends")
        t0 = time.perf_counter()
        v = manifest.version
        self.store.set(f"sync/{v}/manifest", manifest.model_dump_json())
        it = iter(pairs)
        sent = 0
        for b, bucket in enumerate(manifest.buckets):
            specs = [manifest.tensors[i] for i in bucket]
            dtype = _DTYPES[specs[0].dtype]
            flat = torch.empty(sum(s.numel for s in specs), dtype=dtype, device=self.device)
            offset = 0
            for spec in specs:
                try:
                    name, tensor = next(it)
                except StopIteration:
                    raise WeightSyncError(f"sender ran out of tensors at {spec.name!r} (manifest v{v})") from None
                if name != spec.name or list(tensor.shape) != spec.shape:
                    raise WeightSyncError(f"sender produced {name!r} {list(tensor.shape)} where the manifest "
                                          f"expects {spec.name!r} {spec.shape}")
                flat[offset:offset + spec.numel].copy_(tensor.reshape(-1).to(dtype))
                offset += spec.numel
            self._broadcast(flat, b, v)
            sent += flat.numel() * flat.element_size()
        self._wait_keys([f"sync/{v}/done/{r}" for r in range(1, self.world_size)], f"finish weight sync v{v}")
        return {"bytes": float(sent), "buckets": float(len(manifest.buckets)), "seconds": time.perf_counter() - t0}

    def receive(self, version: int) -> Iterator[tuple[str, torch.Tensor]]:
        """Receivers: yield `(name, tensor)` for sync `version`, one bucket at a time.

        Tensors are views into the current bucket: copy them (`load_named_tensors` does) before
        asking for the next one.
        """
        if self.rank == 0:
            raise WeightSyncError("rank 0 sends; it cannot receive")
        key = f"sync/{version}/manifest"
        try:
            self._wait_keys([key], f"publish weight sync v{version}")
        except WeightSyncError as exc:
            raise WeightSyncError(f"{exc} (sender: {self.names[0]})") from None
        manifest = WeightManifest.model_validate(json.loads(self.store.get(key)))
        for b, bucket in enumerate(manifest.buckets):
            specs = [manifest.tensors[i] for i in bucket]
            dtype = _DTYPES[specs[0].dtype]
            flat = torch.empty(sum(s.numel for s in specs), dtype=dtype, device=self.device)
            self._broadcast(flat, b, version)
            offset = 0
            for spec in specs:
                yield spec.name, flat[offset:offset + spec.numel].view(spec.shape)
                offset += spec.numel
            self.store.set(f"sync/{version}/progress/{self.rank}", str(b))
        self.store.set(f"sync/{version}/done/{self.rank}", "1")

    def receive_into(self, module: torch.nn.Module, version: int) -> int:
        """Receive sync `version` straight into a module's tensors; returns how many were loaded."""
        return load_named_tensors(module, self.receive(version))

    def close(self) -> None:
        """Tear the group down (after an error, NCCL communicators must be aborted, not reused)."""
        abort = getattr(self.pg, "abort", None)
        if callable(abort):
            with contextlib.suppress(Exception):  # best effort: the group is unusable either way
                abort()
        self.pg = None
