"""Moving the learner's weights to the generators (every step) and to the teacher (at EMA steps).

Two transports behind one idea: the learner produces `(name, full tensor)` pairs one module at a
time (ZeRO-3 gathers a module, the pair is consumed, the module is released), and receivers load
them by name.

* CPU / small models, `object_store`: the learner returns a CPU state dict, the caller passes the
  `ObjectRef` straight to the receivers (`load_state_dict_into`).
* GPUs, `collective`: a private torch.distributed group between the learner's rank 0 and the
  receivers. Tensors travel in dtype-homogeneous buckets capped at `bucket_mb`, so neither side
  ever materialises the whole model. Every blocking point has a timeout that raises
  `WeightSyncError` naming the peer(s) that did not arrive: the rendezvous (who never joined),
  the communicator's creation, each bucket broadcast (who stopped reporting progress), the
  manifest wait (the sender), and the final acknowledgements.

Which collective backend carries the buckets is decided by the members' devices, not by the config
alone: at join every member publishes a `DeviceIdentity` (machine, and the CUDA device's UUID / PCI
bus id, or "cpu") in the group's store, every member reads all of them and `choose_transport`
derives the same answer everywhere:
  * NCCL, buckets on the GPU: every member on a GPU of its own (`backend: nccl`);
  * gloo, buckets staged through CPU memory: a member on the CPU, `backend: gloo`, or two members
    on one GPU. The last case is the colocated learner + generator of a one-GPU node (fractional
    `num_gpus`): NCCL refuses two ranks of a communicator on one device ("Duplicate GPU detected").
    verl, OpenRLHF and vLLM's own RLHF example (`examples/offline_inference/rlhf_utils.py`,
    `ColocateWorkerExtension`) hand colocated engines CUDA IPC handles instead
    (`torch.multiprocessing.reductions.reduce_tensor`: no copy through the host); gloo is used here
    because it is the path the CPU tests run bit for bit, and IPC handles can only be tested on a GPU.
The choice and its reason are `group.transport` / `group.transport_reason`, logged by rank 0 (the
learner).

The protocol of one sync (version v), coordinated through the group's TCPStore:
    sender:    set  sync/v/manifest (JSON: names, shapes, dtypes, bucket plan)
    all:       broadcast bucket 0..B-1 from rank 0; receivers set sync/v/progress/<rank> = b
    receivers: set  sync/v/done/<rank>
    sender:    wait for every sync/v/done/<rank>

GPU status: the NCCL path is written against torch's public ProcessGroupNCCL API and shares all
of its logic with the gloo path the tests exercise, but it has not been run on a GPU in this
repository (no GPU was available while it was written); bench/gpu_check.py is the script that runs it.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import socket
import time
from collections.abc import Iterable, Iterator
from datetime import timedelta

from typing import Literal

import torch
from pydantic import BaseModel, ConfigDict, Field

from modeling.config_models import WeightSyncConfig

_DTYPES = {str(d): d for d in (torch.float32, torch.bfloat16, torch.float16, torch.float64, torch.int64, torch.int32,
                               torch.uint8, torch.int8, torch.bool)}


logger = logging.getLogger(__name__)


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
# Device identities and the transport decision
# ----------------------------------------------------------------------------------------------


class DeviceIdentity(BaseModel):
    """Where a group member's buckets would live: the machine and, on a GPU, which physical GPU.

    `index` is the process's own CUDA index, which means nothing across processes (Ray gives each
    actor its own CUDA_VISIBLE_DEVICES, so two actors on one GPU both see `cuda:0`); the GPU is
    identified by its UUID (unique across machines), else by the PCI bus id on that machine.
    """

    model_config = ConfigDict(extra="forbid")
    node: str = Field(min_length=1, description="the machine (host name)")
    device: Literal["cpu", "cuda"]
    uuid: str | None = None
    pci_bus_id: str | None = None
    index: int | None = None

    def gpu_key(self) -> str | None:
        """A key equal for two members exactly when they are on one physical GPU (None on the CPU)."""
        if self.device == "cpu":
            return None
        if self.uuid:
            return f"uuid {self.uuid}"
        if self.pci_bus_id:
            return f"{self.node} pci {self.pci_bus_id}"
        return f"{self.node} cuda:{self.index}"

    def describe(self) -> str:
        return "cpu" if self.device == "cpu" else (self.gpu_key() or "cuda")


def local_device_identity(device: str | torch.device) -> DeviceIdentity:
    """This process's identity for a member whose buckets would live on `device`."""
    device = torch.device(device)
    node = socket.gethostname()
    if device.type != "cuda":
        return DeviceIdentity(node=node, device="cpu")
    index = device.index if device.index is not None else torch.cuda.current_device()
    props = torch.cuda.get_device_properties(index)
    uuid = getattr(props, "uuid", None)
    pci = None
    if all(hasattr(props, a) for a in ("pci_domain_id", "pci_bus_id", "pci_device_id")):
        pci = f"{props.pci_domain_id:04x}:{props.pci_bus_id:02x}:{props.pci_device_id:02x}"
    return DeviceIdentity(node=node, device="cuda", uuid=str(uuid) if uuid is not None else None,
                          pci_bus_id=pci, index=index)


class TransportDecision(BaseModel):
    """The backend every member of a group uses, and why (identical on every member)."""

    model_config = ConfigDict(extra="forbid")
    backend: Literal["nccl", "gloo"]
    bucket_device: Literal["cuda", "cpu"]
    reason: str

    @property
    def name(self) -> str:
        return "nccl" if self.backend == "nccl" else "gloo-cpu-staged"


def choose_transport(identities: list[DeviceIdentity], names: list[str],
                     requested: Literal["nccl", "gloo"]) -> TransportDecision:
    """The one transport every member derives from the same identities (a pure function).

    NCCL only when `requested` is nccl and every member has a GPU of its own; otherwise gloo with
    the buckets in CPU memory, and the reason names the members that decided it.
    """
    if len(identities) != len(names):
        raise ValueError(f"{len(identities)} identities for {len(names)} members")
    if requested == "gloo":
        return TransportDecision(backend="gloo", bucket_device="cpu", reason="weight_sync.backend is gloo")
    on_cpu = [n for n, i in zip(names, identities) if i.device == "cpu"]
    if on_cpu:
        return TransportDecision(backend="gloo", bucket_device="cpu",
                                 reason=f"{', '.join(on_cpu)} on the CPU: NCCL needs every member on a GPU")
    by_gpu: dict[str, list[str]] = {}
    for n, i in zip(names, identities):
        by_gpu.setdefault(i.gpu_key() or "", []).append(n)
    shared = {k: v for k, v in by_gpu.items() if len(v) > 1}
    if shared:
        which = "; ".join(f"{' and '.join(v)} share GPU {k}" for k, v in shared.items())
        return TransportDecision(backend="gloo", bucket_device="cpu",
                                 reason=f"{which}: NCCL refuses two ranks on one device, so the buckets are "
                                        "staged through CPU memory over gloo")
    return TransportDecision(backend="nccl", bucket_device="cuda",
                             reason=f"every member on its own GPU ({len(by_gpu)} distinct devices)")


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
        device: The member's compute device ("cuda" or "cpu"; default from `config.backend`). Its
            identity decides the transport (module docstring); received tensors live on the
            bucket device (the GPU with NCCL, the CPU with gloo) and are copied by the receiver.
        identity: This member's `DeviceIdentity` (or its dict), replacing the one read from
            `device`. For tests and for callers that know better (e.g. a GPU shared under another
            name); on a real cluster leave it None.

    Attributes:
        transport: "nccl" or "gloo-cpu-staged", the same on every member.
        transport_reason: Why (names the members that decided it).
        identities: Every member's `DeviceIdentity`, by rank.
    """

    def __init__(self, rank: int, world_size: int, config: WeightSyncConfig, peer_names: list[str] | None = None,
                 device: str | None = None, identity: DeviceIdentity | dict | None = None):
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
        compute = device or ("cuda" if config.backend == "nccl" else "cpu")
        if identity is None:
            identity = local_device_identity(compute)
        self.identity = DeviceIdentity.model_validate(identity) if isinstance(identity, dict) else identity
        self.timeout = timedelta(seconds=config.timeout_s)
        self._version = 0
        self.pg = None
        try:
            self.store = dist.TCPStore(config.master_addr, config.master_port, world_size, is_master=rank == 0,
                                       timeout=self.timeout, wait_for_workers=False)
        except Exception as exc:
            raise WeightSyncError(f"{self.names[rank]}: cannot reach the weight-sync store at "
                                  f"{config.master_addr}:{config.master_port} ({self.names[0]}): {exc}") from exc
        self.store.set(f"identity/{rank}", self.identity.model_dump_json())
        self.store.set(f"joined/{rank}", self.names[rank])
        self._wait_keys([f"joined/{r}" for r in range(world_size)], "join the weight-sync group")
        self.identities = [DeviceIdentity.model_validate_json(self.store.get(f"identity/{r}"))
                           for r in range(world_size)]
        self.decision = choose_transport(self.identities, self.names, config.backend)
        self.transport, self.transport_reason = self.decision.name, self.decision.reason
        self.device = torch.device(self.decision.bucket_device)
        if rank == 0:
            logger.info("weight sync %s: transport %s (%s); members %s", " ".join(self.names), self.transport,
                        self.transport_reason,
                        ", ".join(f"{n}={i.describe()}" for n, i in zip(self.names, self.identities)))
        self.pg = self._create_group(dist)
        # NCCL creates its communicator at the first collective: do it now, inside the error
        # handling, so a refused communicator fails the join and names the group.
        self._collective(torch.zeros(1, device=self.device), "create the communicator")

    def _peers(self) -> str:
        return ", ".join(f"{n} ({i.describe()})" for n, i in zip(self.names, self.identities))

    def _create_group(self, dist):
        try:
            if self.decision.backend == "gloo":
                return dist.ProcessGroupGloo(self.store, self.rank, self.world_size, self.timeout)
            # Lazily resolved: CPU builds of torch have no ProcessGroupNCCL.
            nccl = getattr(dist, "ProcessGroupNCCL", None)
            if nccl is None:
                raise RuntimeError("this torch build has no NCCL (CPU build?)")
            opts = nccl.Options()
            opts._timeout = self.timeout
            return nccl(self.store, self.rank, self.world_size, opts)
        except Exception as exc:
            raise WeightSyncError(f"{self.names[self.rank]}: cannot create the {self.decision.backend} weight-sync "
                                  f"group with {self._peers()} (chosen because {self.transport_reason}): "
                                  f"{exc}") from exc

    def _collective(self, flat: torch.Tensor, what: str) -> None:
        """A broadcast from rank 0 outside a sync (the join's handshake); any failure names the group."""
        import torch.distributed as dist

        try:
            opts = dist.BroadcastOptions()
            opts.rootRank = 0
            self.pg.broadcast([flat], opts).wait(self.timeout)
        except Exception as exc:
            self.close()
            raise WeightSyncError(f"{self.names[self.rank]}: could not {what} of the {self.transport} weight-sync "
                                  f"group with {self._peers()}: {exc}") from exc

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

        if self.pg is None:
            raise WeightSyncError(f"{self.names[self.rank]}: the weight-sync group with {self._peers()} was closed "
                                  "after an error; join a new one")
        try:
            # Enqueueing can fail too (NCCL builds its communicator lazily), not only the wait.
            opts = dist.BroadcastOptions()
            opts.rootRank = 0
            self.pg.broadcast([flat], opts).wait(self.timeout)
        except Exception as exc:
            raise WeightSyncError(self._stall_message(version, bucket, exc)) from exc

    def _stall_message(self, version: int, bucket: int, exc: Exception) -> str:
        if self.rank != 0:
            return (f"{self.names[self.rank]}: {self.transport} bucket {bucket} of weight sync v{version} from "
                    f"{self.names[0]} did not complete within {self.config.timeout_s:.0f}s ({exc})")
        behind = []
        for r in range(1, self.world_size):
            key = f"sync/{version}/progress/{r}"
            done = int(self.store.get(key)) if self.store.check([key]) else -1
            if done < bucket - 1:
                behind.append(f"{self.names[r]} (last bucket {done})")
        who = ", ".join(behind) or f"one of {', '.join(self.names[1:])}"
        return (f"{self.names[0]}: {self.transport} bucket {bucket} of weight sync v{version} stalled waiting for "
                f"{who} ({exc})")

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
