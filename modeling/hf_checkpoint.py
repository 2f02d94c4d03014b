"""The one way this project reads and writes Hugging Face checkpoints.

Every component that holds policy weights loads them here: SFT, both learner backends (the torch
backend whole, the DeepSpeed backend one module at a time into ZeRO-3 partitions), the teacher and
the HF generator. The vLLM generator loads through vLLM itself from the same directory.

What it handles:
- `model.path` as a local folder or a hub id (`org/name`) resolved through the Hugging Face cache,
  offline: `resolve_model_path` never downloads; `hcgym model fetch ID` does (`fetch_model`).
- sharded safetensors with `model.safetensors.index.json`, or one `model.safetensors`.
- the checkpoint's own architecture class (`config.architectures[0]`), so parameter names are the
  checkpoint's names: `model.layers.*` for Qwen3 / Llama, `model.language_model.*` + `model.visual.*`
  for Qwen3.5 / Qwen2.5-VL style multimodal wrappers. Older multimodal checkpoints that store the
  language model as `model.layers.*` and the vision tower as `visual.*` are read through a fallback
  (`checkpoint_key_candidates`).
- tied embeddings: a tied `lm_head.weight` is not stored (transformers does not store it either);
  it is loaded through the embedding it shares, and published weight dicts still carry it.
- bf16 / fp32: tensors are cast to the dtype the model was built in.

Weights leave the learner keyed by these same names; `save_sharded_checkpoint` writes them back as a
checkpoint that `transformers.AutoModel*.from_pretrained` (and vLLM) load unchanged.

Example:
    >>> path = resolve_model_path("Qwen/Qwen3.5-9B")          # the cached snapshot folder
    >>> model = load_model(path, torch.bfloat16)              # Qwen3_5ForConditionalGeneration
    >>> freeze_vision_tower(model, train_vision_tower=False)
    >>> save_sharded_checkpoint(out_dir, model.state_dict(), source_dir=path)
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
from collections.abc import Callable, Iterable
from pathlib import Path

import torch

from modeling.transformers_setup import prepare_transformers

INDEX_FILE = "model.safetensors.index.json"
SINGLE_FILE = "model.safetensors"
# Hugging Face's own default shard limit for save_pretrained.
DEFAULT_MAX_SHARD_SIZE = "5GB"
# `org/name`: what the hub accepts as a model id (a relative path with one slash that does not exist
# locally is taken as one).
HUB_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*/[A-Za-z0-9][A-Za-z0-9._-]*$")
# Files of a checkpoint folder that are weights (not copied next to a newly saved checkpoint).
_WEIGHT_FILE = re.compile(r"(\.safetensors|\.bin|\.pt|\.pth|\.ckpt|\.h5|\.msgpack|\.gguf|\.safetensors\.index\.json"
                          r"|\.bin\.index\.json)$")
# Submodule names of the vision towers of multimodal wrappers (Qwen2-VL, Qwen2.5-VL, Qwen3-VL, Qwen3.5).
VISION_TOWER_NAMES = ("visual", "vision_tower", "vision_model")


# ----------------------------------------------------------------------------------------------
# Where a checkpoint is
# ----------------------------------------------------------------------------------------------


def hf_hub_cache_dir() -> Path:
    """The Hugging Face hub cache, read from the environment at call time (HF_HUB_CACHE, else HF_HOME/hub)."""
    if os.environ.get("HF_HUB_CACHE"):
        return Path(os.environ["HF_HUB_CACHE"]).expanduser()
    home = os.environ.get("HF_HOME") or os.path.join(os.environ.get("XDG_CACHE_HOME", "~/.cache"), "huggingface")
    return Path(home).expanduser() / "hub"


def is_hub_id(text: str) -> bool:
    """True for an `org/name` hub model id (the caller checks first that no such local folder exists)."""
    return bool(HUB_ID.match(text))


def resolve_model_path(path_or_id: str | os.PathLike, *, revision: str | None = None) -> Path:
    """A local checkpoint folder for `path_or_id`: the folder itself, or the cached hub snapshot.

    Never downloads: a hub id must already be in the cache (`hcgym model fetch ID`).

    Args:
        path_or_id: A local folder holding `config.json`, or a hub id such as `Qwen/Qwen3.5-9B`.
        revision: For a hub id: a branch, tag or commit (default `main`).

    Raises:
        FileNotFoundError: The folder has no config.json, or the hub id (at that revision) is not in
            the cache; the message names the id and the cache path.
        ValueError: `path_or_id` is neither an existing folder nor a hub id.
    """
    text = str(path_or_id)
    local = Path(text).expanduser()
    if local.exists():
        if not (local / "config.json").is_file():
            raise FileNotFoundError(f"model path {local} has no config.json (not a Hugging Face checkpoint folder)")
        return local.resolve()
    if not is_hub_id(text):
        raise ValueError(f"model path {text!r} does not exist and is not a hub id of the form 'org/name'")
    from huggingface_hub import snapshot_download
    from huggingface_hub.errors import LocalEntryNotFoundError

    cache = hf_hub_cache_dir()
    try:
        snapshot = snapshot_download(text, revision=revision, cache_dir=str(cache), local_files_only=True)
    except (LocalEntryNotFoundError, FileNotFoundError) as exc:
        at = f" at revision {revision!r}" if revision else ""
        raise FileNotFoundError(
            f"model {text!r}{at} is not in the Hugging Face cache {cache} (HF_HUB_CACHE / HF_HOME); "
            f"download it on a machine with hub access: hcgym model fetch {text}"
            + (f" --revision {revision}" if revision else "")
        ) from exc
    path = Path(snapshot)
    if not (path / "config.json").is_file():
        raise FileNotFoundError(f"cached snapshot of {text!r} at {path} has no config.json")
    return path


def fetch_model(model_id: str, *, revision: str | None = None, cache_dir: str | os.PathLike | None = None) -> Path:
    """Download a hub model into the Hugging Face cache (config, tokenizer, safetensors weights).

    Raises:
        ValueError: `model_id` is not of the form `org/name`.
        RuntimeError: The hub cannot be reached (offline machine, HF_HUB_OFFLINE=1) or refused the id.
    """
    if not is_hub_id(model_id):
        raise ValueError(f"model id {model_id!r} is not of the form 'org/name'")
    from envs._runtime import APPLIED_DEFAULTS

    if "HF_HUB_OFFLINE" in APPLIED_DEFAULTS:
        # Importing the project set HF_HUB_OFFLINE=1 (run time never reaches the hub); this command is
        # the one meant to. A value the user set is respected.
        os.environ["HF_HUB_OFFLINE"] = "0"
        import huggingface_hub.constants

        huggingface_hub.constants.HF_HUB_OFFLINE = False
    from huggingface_hub import snapshot_download

    cache = Path(cache_dir) if cache_dir else hf_hub_cache_dir()
    # Weights as safetensors only: .bin / .pt would need unpickling, which nothing here does.
    patterns = ["*.json", "*.safetensors", "*.jinja", "*.txt", "*.model", "*.tiktoken"]  # no remote code
    try:
        path = snapshot_download(model_id, revision=revision, cache_dir=str(cache), allow_patterns=patterns)
    except Exception as exc:  # huggingface_hub raises several unrelated types for "no network"
        offline = os.environ.get("HF_HUB_OFFLINE", "0") not in ("", "0", "false", "False")
        hint = " (HF_HUB_OFFLINE is set: unset it on a machine with hub access)" if offline else ""
        raise RuntimeError(f"could not download {model_id!r} into {cache}{hint}: {type(exc).__name__}: {exc}") from exc
    return Path(path)


# ----------------------------------------------------------------------------------------------
# Reading weights
# ----------------------------------------------------------------------------------------------


def checkpoint_weight_map(model_dir: str | os.PathLike) -> dict[str, Path]:
    """Tensor name -> safetensors file holding it, from the index (sharded) or the single file.

    Raises:
        FileNotFoundError: No `model.safetensors.index.json` and no `model.safetensors` in the folder
            (pickled `.bin` checkpoints are not read), or the index names a shard that is missing.
        ValueError: The index has no `weight_map`.
    """
    root = Path(model_dir)
    index = root / INDEX_FILE
    if index.is_file():
        from modeling.checkpoint import read_json  # names the file of a truncated / non-UTF-8 index

        data = read_json(index)
        if not isinstance(data, dict) or not isinstance(data.get("weight_map"), dict):
            raise ValueError(f"{index} has no 'weight_map' object")
        out = {name: root / shard for name, shard in data["weight_map"].items()}
        for shard in sorted(set(out.values())):
            if not shard.is_file():
                raise FileNotFoundError(f"{index} names shard {shard.name}, which is missing from {root}")
        return out
    single = root / SINGLE_FILE
    if single.is_file():
        with _open_safetensors(single) as f:
            return dict.fromkeys(f.keys(), single)
    present = sorted(p.name for p in root.iterdir()) if root.is_dir() else []
    raise FileNotFoundError(f"no {INDEX_FILE} or {SINGLE_FILE} in {root} (found: {present[:12]}); "
                            "only safetensors checkpoints are read")


def checkpoint_key_candidates(name: str) -> list[str]:
    """Names under which parameter `name` may be stored: itself, then the older multimodal layout.

    Qwen2-VL / Qwen2.5-VL checkpoints published before transformers 4.52 store the language model as
    `model.*` and the vision tower as `visual.*`; transformers now nests them as
    `model.language_model.*` and `model.visual.*`.
    """
    out = [name]
    if name.startswith("model.language_model."):
        out.append("model." + name[len("model.language_model."):])
    elif name.startswith("model.visual."):
        out.append(name[len("model."):])
    return out


def _open_safetensors(path: Path):
    """`safe_open(path)`; a corrupt or truncated file raises `CheckpointError` naming it."""
    from safetensors import safe_open

    from modeling.checkpoint import CheckpointError

    try:
        return safe_open(str(path), framework="pt", device="cpu")
    except Exception as exc:  # SafetensorError / OSError, which do not name the file
        raise CheckpointError(f"{path}: not a readable safetensors file ({type(exc).__name__}: {exc})") from None


class CheckpointReader:
    """Reads tensors by name from a (sharded) safetensors checkpoint, opening each shard once.

    Use as a context manager; `get(name)` returns a CPU tensor in the stored dtype.
    """

    def __init__(self, model_dir: str | os.PathLike):
        self.model_dir = Path(model_dir)
        self.weight_map = checkpoint_weight_map(self.model_dir)
        self._handles: dict[Path, object] = {}
        self._stack = contextlib.ExitStack()

    def __enter__(self) -> CheckpointReader:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self._stack.close()
        self._handles.clear()

    def stored_name(self, name: str) -> str | None:
        """The name `name` is stored under (see `checkpoint_key_candidates`), or None."""
        for candidate in checkpoint_key_candidates(name):
            if candidate in self.weight_map:
                return candidate
        return None

    def get(self, name: str) -> torch.Tensor:
        """The tensor of parameter `name`.

        Raises:
            KeyError: The checkpoint holds no tensor under `name` (or its older-layout name).
        """
        stored = self.stored_name(name)
        if stored is None:
            raise KeyError(f"checkpoint {self.model_dir} has no tensor {name!r}")
        shard = self.weight_map[stored]
        handle = self._handles.get(shard)
        if handle is None:
            handle = self._stack.enter_context(_open_safetensors(shard))
            self._handles[shard] = handle
        try:
            return handle.get_tensor(stored)
        except Exception as exc:  # a shard cut short after its header: safetensors names no file
            from modeling.checkpoint import CheckpointError

            raise CheckpointError(f"{shard}: cannot read tensor {stored!r} ({type(exc).__name__}: {exc})") from None


def read_checkpoint_tensors(model_dir: str | os.PathLike) -> dict[str, torch.Tensor]:
    """Every tensor of a (sharded) safetensors checkpoint, by stored name, on CPU."""
    with CheckpointReader(model_dir) as reader:
        return {name: reader.get(name) for name in reader.weight_map}


# ----------------------------------------------------------------------------------------------
# Building and filling models
# ----------------------------------------------------------------------------------------------


def load_hf_config(model_dir: str | os.PathLike):
    prepare_transformers()
    from transformers import AutoConfig

    return AutoConfig.from_pretrained(str(model_dir), local_files_only=True)


def architecture_class(config):
    """The transformers class named by `config.architectures[0]` (AutoModelForCausalLM's choice if unnamed).

    Raises:
        ValueError: The named class is not in this transformers version, or is not a generative LM
            (it has no output embeddings, so there are no token log-probs to compute).
    """
    prepare_transformers()
    import transformers

    names = getattr(config, "architectures", None) or []
    if not names:
        from transformers import AutoModelForCausalLM

        return AutoModelForCausalLM._model_mapping[type(config)]
    cls = getattr(transformers, names[0], None)
    if cls is None:
        raise ValueError(f"config.architectures[0] = {names[0]!r} is not a class of transformers "
                         f"{transformers.__version__}")
    if not hasattr(cls, "get_output_embeddings") or not any(
            names[0].endswith(s) for s in ("ForCausalLM", "ForConditionalGeneration", "LMHeadModel")):
        raise ValueError(f"config.architectures[0] = {names[0]!r} is not a generative language model class")
    return cls


def build_empty_model(config, dtype: torch.dtype) -> torch.nn.Module:
    """The architecture class built from `config` without random initialisation (every tensor is loaded after)."""
    prepare_transformers()
    from transformers.initialization import no_init_weights

    cls = architecture_class(config)
    with no_init_weights():
        model = cls._from_config(config, dtype=dtype)
    # Tie before loading (a tied lm_head.weight is not stored; it is filled through the embedding).
    model.tie_weights()
    return model


def load_weights_by_module(
    model: torch.nn.Module,
    model_dir: str | os.PathLike,
    *,
    gather: Callable[[list[torch.nn.Parameter]], contextlib.AbstractContextManager] | None = None,
    write: bool = True,
) -> int:
    """Fill `model`'s parameters (and persistent buffers stored in the checkpoint) module by module.

    Args:
        model: A model of the checkpoint's architecture class (names must match the checkpoint).
        model_dir: The checkpoint folder.
        gather: Context manager factory around each module's parameters (ZeRO-3: `GatheredParameters`
            with `modifier_rank=0`, so only one module is ever whole); None for an ordinary model.
        write: Whether this process copies (ZeRO-3: rank 0 only; the others just join the gather).

    Returns:
        How many tensors were copied.

    Raises:
        KeyError: The checkpoint lacks a parameter of the model (named with the checkpoint folder).
    """
    seen: set[int] = set()  # a tied parameter (lm_head.weight = embed_tokens.weight) is loaded once
    copied = 0
    with CheckpointReader(model_dir) as reader:
        for mod_name, module in model.named_modules():
            params = [(n, p) for n, p in module.named_parameters(recurse=False) if id(p) not in seen]
            seen.update(id(p) for _, p in params)
            if params:
                ctx = gather([p for _, p in params]) if gather is not None else contextlib.nullcontext()
                with ctx:
                    if write:
                        with torch.no_grad():
                            for pname, param in params:
                                key = f"{mod_name}.{pname}" if mod_name else pname
                                param.copy_(reader.get(key).to(param.dtype))
                                copied += 1
            # Persistent buffers stored in the checkpoint (rare) are never partitioned: every
            # process fills its own copy.
            for bname, buf in module.named_buffers(recurse=False):
                key = f"{mod_name}.{bname}" if mod_name else bname
                if bname in module._non_persistent_buffers_set or reader.stored_name(key) is None:
                    continue
                with torch.no_grad():
                    buf.copy_(reader.get(key).to(buf.dtype))
                copied += 1
    return copied


def load_model(model_dir: str | os.PathLike, dtype: torch.dtype = torch.float32, device: str | torch.device = "cpu",
               *, revision: str | None = None) -> torch.nn.Module:
    """The checkpoint's architecture class with its weights, in eval mode, on `device`.

    Args:
        model_dir: A local checkpoint folder or a cached hub id (see `resolve_model_path`).
        dtype: Parameter dtype (tensors are cast from the stored dtype).
        device: Where the model goes after loading.
        revision: Hub revision when `model_dir` is a hub id.
    """
    prepare_transformers()
    path = resolve_model_path(model_dir, revision=revision)
    config = load_hf_config(path)
    model = build_empty_model(config, dtype)
    load_weights_by_module(model, path)
    model.eval()
    return model.to(device)


def vision_tower_prefixes(model: torch.nn.Module) -> list[str]:
    """Module-name prefixes of the vision tower(s) of a multimodal wrapper (empty for a text-only LM)."""
    out = []
    for name, _ in model.named_modules():
        leaf = name.rsplit(".", 1)[-1]
        if leaf in VISION_TOWER_NAMES and not any(name.startswith(p) for p in out):
            out.append(name + ".")
    return out


def freeze_vision_tower(model: torch.nn.Module, *, train_vision_tower: bool) -> list[str]:
    """Freeze (or leave trainable) the vision tower; the language model always trains.

    Returns:
        The names of the vision-tower parameters (empty for a text-only model).
    """
    prefixes = vision_tower_prefixes(model)
    names = []
    for name, param in model.named_parameters():
        if any(name.startswith(p) for p in prefixes):
            param.requires_grad_(train_vision_tower)
            names.append(name)
    return names


def tied_parameter_aliases(model: torch.nn.Module) -> dict[str, str]:
    """alias -> canonical name for parameters registered under two names (tied embeddings)."""
    first: dict[int, str] = {}
    aliases: dict[str, str] = {}
    for mod_name, module in model.named_modules():
        for pname, p in module.named_parameters(recurse=False):
            key = f"{mod_name}.{pname}" if mod_name else pname
            if id(p) in first:
                aliases[key] = first[id(p)]
            else:
                first[id(p)] = key
    return aliases


def config_tied_aliases(config) -> dict[str, str]:
    """`tied_parameter_aliases` of the architecture built from `config` on the meta device (no memory)."""
    with torch.device("meta"):
        model = build_empty_model(config, torch.float32)
    return tied_parameter_aliases(model)


# ----------------------------------------------------------------------------------------------
# Writing checkpoints
# ----------------------------------------------------------------------------------------------


def parse_size(size: str | int) -> int:
    """'5GB' / '400KB' / '2MiB' / 1024 -> bytes (decimal units as transformers uses them, binary with 'i')."""
    if isinstance(size, int):
        return size
    m = re.fullmatch(r"(\d+(?:\.\d+)?)\s*([KMGT]?)(I?)B", size.strip().upper())
    if not m:
        raise ValueError(f"max_shard_size={size!r}: expected e.g. '5GB', '400KB', '2MiB' or a number of bytes")
    base = 1024 if m.group(3) else 1000
    return int(float(m.group(1)) * base ** " KMGT".index(m.group(2) or " "))


def save_sharded_checkpoint(
    out_dir: str | os.PathLike,
    tensors: dict[str, torch.Tensor] | Iterable[tuple[str, torch.Tensor]],
    *,
    source_dir: str | os.PathLike,
    max_shard_size: str | int = DEFAULT_MAX_SHARD_SIZE,
    dtype: torch.dtype | None = None,
    metadata: dict[str, str] | None = None,
) -> Path:
    """Write weights as a Hugging Face checkpoint: `model-0000i-of-0000n.safetensors` + index + config + tokenizer.

    Tied aliases (a tied `lm_head.weight`) are left out, as `save_pretrained` does; every other
    file of `source_dir` that is not weights (config.json, generation_config.json, tokenizer and
    processor files, chat template) is copied, so `from_pretrained(out_dir)` and vLLM load it as is.

    Args:
        out_dir: Folder to write (created; existing shards of an earlier save are replaced).
        tensors: name -> tensor (checkpoint names) or an iterable of pairs; copied to CPU.
        source_dir: The checkpoint these weights came from (config and tokenizer source).
        max_shard_size: Shard limit ('5GB', '400KB', bytes); a tensor larger than it gets its own shard.
        dtype: Cast floating tensors to this dtype (None: keep).
        metadata: Extra string metadata stored in every shard and the index.

    Raises:
        ValueError: The names do not match the architecture of `source_dir` (unknown or missing names).
    """
    from safetensors.torch import save_file

    from modeling.checkpoint import replace_atomic

    source = resolve_model_path(source_dir)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    config = load_hf_config(source)
    aliases = config_tied_aliases(config)
    items = tensors.items() if isinstance(tensors, dict) else tensors
    clean: dict[str, torch.Tensor] = {}
    pointers: set[int] = set()
    for name, t in items:
        if name in aliases:
            continue
        t = t.detach().to("cpu")
        if dtype is not None and t.is_floating_point():
            t = t.to(dtype)
        t = t.contiguous()
        if t.data_ptr() in pointers:  # safetensors refuses tensors that share memory
            t = t.clone()
        pointers.add(t.data_ptr())
        clean[name] = t
    with torch.device("meta"):
        expected_model = build_empty_model(config, torch.float32)
    expected = {k for k in expected_model.state_dict() if k not in aliases}
    unknown, missing = sorted(set(clean) - expected), sorted(expected - set(clean))
    if unknown or missing:
        raise ValueError(f"save_sharded_checkpoint({out}): weights do not match {type(expected_model).__name__} of "
                         f"{source}: unknown {unknown[:5]}, missing {missing[:5]}")
    limit = parse_size(max_shard_size)
    shards: list[list[str]] = [[]]
    size = 0
    for name in clean:  # in model order, as save_pretrained keeps layers together
        nbytes = clean[name].numel() * clean[name].element_size()
        if shards[-1] and size + nbytes > limit:
            shards.append([])
            size = 0
        shards[-1].append(name)
        size += nbytes
    for old in list(out.glob("model-*-of-*.safetensors")) + [out / SINGLE_FILE]:
        old.unlink(missing_ok=True)
    meta = {"format": "pt", **(metadata or {})}
    weight_map: dict[str, str] = {}
    total = 0
    for i, names in enumerate(shards, start=1):
        filename = f"model-{i:05d}-of-{len(shards):05d}.safetensors"
        shard = {n: clean[n] for n in names}
        replace_atomic(out / filename, lambda tmp, shard=shard: save_file(shard, str(tmp), metadata=meta))
        weight_map.update(dict.fromkeys(names, filename))
        total += sum(clean[n].numel() * clean[n].element_size() for n in names)
    index = {"metadata": {"total_size": total, **(metadata or {})}, "weight_map": weight_map}
    replace_atomic(out / INDEX_FILE, lambda tmp: tmp.write_text(json.dumps(index, indent=2, sort_keys=True)))
    if source != out.resolve():
        for f in source.iterdir():
            if f.is_file() and not f.name.startswith(".") and not _WEIGHT_FILE.search(f.name):
                shutil.copy2(f, out / f.name)
    if dtype is not None:
        cfg_path = out / "config.json"
        cfg = json.loads(cfg_path.read_text())
        cfg["dtype"] = str(dtype).removeprefix("torch.")
        cfg_path.write_text(json.dumps(cfg, indent=2, sort_keys=True))
    return out


def checkpoint_metadata(model_dir: str | os.PathLike) -> dict[str, str]:
    """The `metadata` of a checkpoint's index (sharded) or its single file (e.g. `policy_version`)."""
    root = Path(model_dir)
    if (root / INDEX_FILE).is_file():
        meta = json.loads((root / INDEX_FILE).read_text()).get("metadata", {})
        return {k: str(v) for k, v in meta.items()}
    from safetensors import safe_open

    with safe_open(str(root / SINGLE_FILE), framework="pt", device="cpu") as f:
        return dict(f.metadata() or {})
