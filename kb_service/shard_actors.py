"""A sharded KB's bm25 shards held by separate Ray actors, for a corpus one node cannot hold.

`kb_service.service.start_kb_service(shards=ShardActorsConfig(actors=N, ...))` splits the shards
of ``bm25/shards.json`` into N contiguous groups (`shard_groups`) and starts one `KBShardActor`
per group, placed by Ray (custom resources, a memory reservation, the SPREAD strategy). Each
actor memory-maps only its own shards, whose weights already carry the corpus-wide N, average
length and document frequencies (`kb_service.shards`), and its slice of the per-document source
and category ids. The service's replicas open the rest of the KB (passages, tantivy, docmeta)
with a `RemoteShardedBM25Searcher` in place of the local bm25 index: a free-text query fans out
to every shard actor, each returns its shards' merged top k (`shards.search_shards`), and the
replica merges those with `shards.merge_top_k`, the merge `ShardedBM25Searcher` uses, so the
ranking and the float32 scores are the single index's.

Filters travel as a `ShardFilter` (source and category ids), not as a mask of every document:
each actor builds the mask of its own range, as `KnowledgeBase._mask` builds the whole one.

A shard actor that dies is restarted by Ray (`max_restarts`) and the calls it had not answered
are sent again (`max_task_retries=-1`): a search waiting on it returns once the restarted actor
has reopened its shards.
"""

from __future__ import annotations

import json
import os
from collections import OrderedDict
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from kb_service.kb import KBCorruptError, KBError, KnowledgeBase
from kb_service.shards import (SHARDS_FILE, SHARDS_FORMAT, is_sharded, merge_top_k, search_shards, select_terms,
                               shards_df)

#: The files of one bm25s shard directory (`engines.save_bm25s`).
SHARD_FILES = ("params.index.json", "vocab.index.json", "data.csc.index.npy", "indices.csc.index.npy",
               "indptr.csc.index.npy")


class ShardLayoutError(ValueError):
    """The shard actors asked for do not fit the KB's shards (more actors than shards, no shards)."""


class ShardGroup(NamedTuple):
    """The shards one actor holds: their indices in shards.json and the documents they cover."""

    index: int
    shards: tuple[int, ...]
    start: int
    num_docs: int


class ShardFilter(NamedTuple):
    """A search filter as ids of docmeta's names: the sources kept (any of) and the category."""

    sources: tuple[int, ...] | None
    category: int | None


def read_shards_manifest(path: Path) -> dict:
    """``bm25/shards.json`` of the KB at `path`, checked for the fields the service reads."""
    file = Path(path) / "bm25" / SHARDS_FILE
    try:
        meta = json.loads(file.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise KBCorruptError(f"knowledge base at {path}: unreadable {file} ({exc})") from None
    if not isinstance(meta, dict) or meta.get("format") != SHARDS_FORMAT or not isinstance(meta.get("shards"), list):
        raise KBCorruptError(f"knowledge base at {path}: {file} is not a sharded BM25 manifest")
    return meta


def shard_groups(path: str | Path, actors: int) -> list[ShardGroup]:
    """The contiguous groups of shards `actors` shard actors hold (sizes differ by at most one shard).

    Raises:
        KBNotBuiltError / KBCorruptError: no KB at `path` (with the command that builds it), or
            a shard directory or file named in shards.json is missing.
        ShardLayoutError: the KB has one bm25 index (not shards), or fewer shards than `actors`.
    """
    path = Path(path)
    if isinstance(actors, bool) or not isinstance(actors, int) or actors < 1:
        raise ShardLayoutError(f"the number of shard actors must be a positive integer, got {actors!r}")
    if not (path / "manifest.json").is_file():
        KnowledgeBase.open(path, warmup=False)  # raises the KB's own error with the build command
    if not is_sharded(path / "bm25"):
        raise ShardLayoutError(
            f"kb.shards.actors is {actors}, but the knowledge base at {path} has a single bm25 index, not shards; "
            f"shard it with `hcgym kb shard --path {path} --shard-docs N` or set kb.shards.actors to 0")
    meta = read_shards_manifest(path)
    specs = meta["shards"]
    if actors > len(specs):
        raise ShardLayoutError(
            f"kb.shards.actors is {actors}, but the knowledge base at {path} has {len(specs)} bm25 shards; use at "
            f"most {len(specs)} shard actors or reshard it with smaller shards (`hcgym kb build --shard-docs N`)")
    for spec in specs:
        missing = [f for f in SHARD_FILES if not (path / "bm25" / str(spec.get("dir")) / f).is_file()]
        if missing:
            raise KBCorruptError(
                f"knowledge base at {path}: shard {spec.get('dir')!r} of bm25/{SHARDS_FILE} is missing "
                f"{', '.join('bm25/' + str(spec.get('dir')) + '/' + f for f in missing)}; rebuild it "
                f"(`hcgym kb build --force ...`) or reshard a built one (`hcgym kb shard`)")
    groups = []
    for g, members in enumerate(np.array_split(np.arange(len(specs)), actors)):
        first, last = specs[int(members[0])], specs[int(members[-1])]
        start = int(first["offset"])
        groups.append(ShardGroup(g, tuple(int(i) for i in members), start,
                                 int(last["offset"]) + int(last["num_docs"]) - start))
    return groups


class ShardSet:
    """The shards of one group, opened in this process (what a `KBShardActor` holds)."""

    def __init__(self, path: str | Path, group: ShardGroup) -> None:
        from kb_service.engines import BM25Searcher

        self.path = Path(path)
        self.group = group
        specs = read_shards_manifest(self.path)["shards"]
        self.shards, self.offsets = [], []
        expected = group.start
        for i in group.shards:
            spec = specs[i]
            where = self.path / "bm25" / spec["dir"]
            try:
                shard = BM25Searcher(where)
                shard.validate()
            except Exception as exc:
                raise KBCorruptError(f"knowledge base at {self.path}: shard {where} is unreadable "
                                     f"({type(exc).__name__}: {exc})") from None
            if int(spec["offset"]) != expected or shard.num_docs != int(spec["num_docs"]):
                raise KBCorruptError(f"knowledge base at {self.path}: shard {where} holds {shard.num_docs} documents "
                                     f"at offset {spec['offset']}; shards.json expects {spec['num_docs']} "
                                     f"at {expected}")
            self.shards.append(shard)
            self.offsets.append(expected)
            expected += shard.num_docs
        if expected - group.start != group.num_docs:
            raise KBCorruptError(f"knowledge base at {self.path}: shards {list(group.shards)} hold "
                                 f"{expected - group.start} documents, the service expected {group.num_docs}")
        end = group.start + group.num_docs
        self.source_ids = np.load(self.path / "docmeta/source_ids.npy", mmap_mode="r")[group.start:end]
        self.category_ids = np.load(self.path / "docmeta/category_ids.npy", mmap_mode="r")[group.start:end]
        self.scale = self.shards[0].scale
        self._masks: OrderedDict = OrderedDict()
        for shard in self.shards:
            shard.warmup()

    def df(self, terms: list[str]) -> list[int]:
        return shards_df(self.shards, terms)

    def mask(self, flt: ShardFilter | np.ndarray | None) -> np.ndarray | None:
        """This group's slice of the filter's mask: `KnowledgeBase._mask`'s rule over our documents."""
        if flt is None or isinstance(flt, np.ndarray):
            return flt
        mask = self._masks.get(flt)
        if mask is None:
            keep = np.ones(self.group.num_docs, dtype=bool)
            if flt.sources:
                keep &= np.isin(self.source_ids, list(flt.sources))
            if flt.category is not None:
                keep &= self.category_ids == flt.category
            mask = self._masks[flt] = keep.astype(np.float32)
            while len(self._masks) > 16:
                self._masks.popitem(last=False)
        else:
            self._masks.move_to_end(flt)
        return mask

    def search(self, terms: list[str], k: int, flt: ShardFilter | np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """This group's top k: (global document numbers, unscaled sums), see `shards.merge_top_k`."""
        return search_shards(self.shards, self.offsets, terms, k, self.mask(flt), self.group.start)


_ACTOR_CLASS = None


def shard_actor_class():
    """`KBShardActor`, the Ray actor class over a `ShardSet` (created on first use: Ray imported lazily)."""
    global _ACTOR_CLASS
    if _ACTOR_CLASS is None:
        import ray

        @ray.remote
        class KBShardActor:
            def __init__(self, path: str, group: ShardGroup) -> None:
                self.set = ShardSet(path, ShardGroup(*group))

            def info(self) -> dict:
                g = self.set.group
                return {"group": g.index, "shards": list(g.shards), "start": g.start, "num_docs": g.num_docs,
                        "scale": self.set.scale, "node_id": ray.get_runtime_context().get_node_id(), "pid": os.getpid()}

            def df(self, terms: list[str]) -> list[int]:
                return self.set.df(terms)

            def search(self, terms: list[str], k: int, flt: Any) -> tuple[np.ndarray, np.ndarray]:
                return self.set.search(terms, k, flt)

        _ACTOR_CLASS = KBShardActor
    return _ACTOR_CLASS


class RemoteShardedBM25Searcher:
    """The `BM25Searcher` interface (`term_ids`, `search`, `num_docs`, `validate`, `warmup`) over
    shard actors: what a KB service replica searches instead of a local bm25 index."""

    def __init__(self, path: str | Path, handles: list, groups: list[ShardGroup], timeout_s: float = 120.0) -> None:
        """`path`: the KB's directory; `handles`: the shard actors holding `groups`, in order."""
        if len(handles) != len(groups) or not handles:
            raise ValueError(f"{len(handles)} shard actor handles for {len(groups)} shard groups")
        self.path = Path(path)
        self.handles = list(handles)
        self.groups = [ShardGroup(*g) for g in groups]
        self.timeout_s = timeout_s  # a restarted actor reopens its shards within it
        meta = read_shards_manifest(self.path)
        self.num_docs = int(meta["num_docs"])
        self.n_shards = len(meta["shards"])
        self.scale = None

    def _gather(self, method: str, *args, per_group=None) -> list:
        """`method(*args)` (or `method(*per_group(group))`) on every shard actor, their answers in group order."""
        import ray
        from ray.exceptions import GetTimeoutError, RayActorError

        refs = [getattr(h, method).remote(*(per_group(g) if per_group else args))
                for h, g in zip(self.handles, self.groups)]
        out = []
        for group, ref in zip(self.groups, refs):
            try:
                out.append(ray.get(ref, timeout=self.timeout_s))
            except RayActorError as exc:
                raise KBError(f"KB shard actor {group.index} (shards {list(group.shards)} of {self.path}) is dead and "
                              f"was not restarted: {exc}") from None
            except GetTimeoutError:
                raise KBError(f"KB shard actor {group.index} (shards {list(group.shards)} of {self.path}) did not "
                              f"answer {method} within {self.timeout_s:.0f}s") from None
        return out

    def validate(self) -> None:
        infos = self._gather("info")
        held = sorted(i for info in infos for i in info["shards"])
        if held != list(range(self.n_shards)):
            raise ValueError(f"the shard actors hold shards {held}, shards.json lists {self.n_shards}")
        for group, info in zip(self.groups, infos):
            if (info["start"], info["num_docs"]) != (group.start, group.num_docs):
                raise ValueError(f"shard actor {group.index} holds documents {info['start']}.. ({info['num_docs']}), "
                                 f"expected {group.start}.. ({group.num_docs})")
        if sum(info["num_docs"] for info in infos) != self.num_docs:
            raise ValueError(f"the shard actors hold {sum(i['num_docs'] for i in infos)} documents, "
                             f"shards.json says {self.num_docs}")
        scales = {info["scale"] for info in infos}
        if len(scales) != 1:
            raise ValueError(f"the shards were built with different k1 ((k1 + 1) = {sorted(scales)})")
        self.scale = scales.pop()

    def warmup(self) -> None:
        if self.scale is None:
            self.validate()

    def term_ids(self, terms: list[str], max_terms: int) -> list[str]:
        """The query terms as `ShardedBM25Searcher.term_ids` selects them.

        With at most `max_terms` terms nothing is cut, and a term no shard knows changes no shard's
        search (each shard skips the terms it lacks), so the terms go out as they are, without
        asking the actors for document frequencies first.
        """
        if len(terms) <= max_terms:
            return list(terms)
        dfs = np.sum(self._gather("df", list(terms)), axis=0).tolist()
        return select_terms(terms, dfs, max_terms)

    def search(self, terms: list[str], k: int, weight_mask: ShardFilter | np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
        """Global top-k (document numbers, scores), best first, as `ShardedBM25Searcher.search`."""
        if not terms or k <= 0:
            return np.zeros(0, np.int64), np.zeros(0, np.float32)
        if self.scale is None:
            self.validate()
        terms = list(terms)
        if isinstance(weight_mask, np.ndarray):  # a whole-corpus mask: each actor gets its slice
            results = self._gather("search", per_group=lambda g: (terms, k, weight_mask[g.start:g.start + g.num_docs]))
        else:
            results = self._gather("search", terms, k, weight_mask)
        docs, raw = merge_top_k([d for d, _ in results], [r for _, r in results], k)
        return docs, raw * self.scale


class ShardServiceKB(KnowledgeBase):
    """A `KnowledgeBase` whose bm25 index is a `RemoteShardedBM25Searcher`: filters go to the
    shard actors as ids (`ShardFilter`) instead of a float32 mask of every document."""

    def _mask(self, sources: list[str] | None, category: str | None) -> ShardFilter | None:
        if sources is None and category is None:
            return None
        return ShardFilter(tuple(sorted(self._source_index[s] for s in sources)) if sources else None,
                           self._category_index[category] if category is not None else None)
