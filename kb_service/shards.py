"""A BM25 index built as shards, searched with an exact global top-k, built in bounded memory.

Each shard is an ordinary bm25s index (the CSC matrix `BM25Searcher` memory-maps) over a
contiguous slice of the passages: shard ``s`` holds documents ``offset_s .. offset_s + n_s - 1``
(the store's rows ``offset_s + 1 ..``), with its own vocabulary of the terms that slice contains.

Exactness. A BM25 weight depends on corpus-wide statistics: the number of documents N, the
average document length and each term's document frequency. A shard scored with its own slice's
statistics would rank differently from one index over the whole corpus. So the build is two
steps: every shard first keeps its raw postings (document, term, tf) and document lengths on
disk; `save` then takes N and the average length over the whole corpus (the same float32 mean of
the same lengths as `BM25Builder`, computed from the shards' files a chunk at a time by
`float32_mean`), sums each term's document frequency over all shards (a merge of the shards'
sorted term lists, `_merge_df`, so no table of the whole vocabulary is ever held), and writes
each shard's weights with those global statistics and bm25s's own scoring functions. A shard's
weight for (term, document) is therefore bit-for-bit the single index's weight.

Bounded memory. With ``memory_bytes`` the builder also cuts a shard when its estimated working
set (the larger of what `add` holds and what weighting the shard needs, `BYTES_PER_POSTING` and
`BYTES_PER_TERM`) reaches that many bytes, and flushes its token buffer in proportion; nothing
else it holds grows with the corpus. Resumable: a shard's raw files are renamed into place and
then recorded in ``progress.json`` (the commit); the global statistics and each weighted shard
are committed the same way, so a builder opened with ``resume=True`` on the same ``work_dir``
continues after the last commit (its `n_docs` says how many documents to skip).

Searching: the query's terms are selected with their global document frequency (the sum of the
shards' column lengths, the same `MAX_QUERY_TERMS` rule as `BM25Searcher.term_ids`), each shard
returns its own top k with the same kernel (scores summed in the same term order, so equal to
the single index's float32 sums), and the k best of those (score descending, then global
document number ascending, the kernel's tie rule, on the kernel's float32 sums before the
(k1 + 1) factor, which can round two different sums to one value) are the global top k: any document of the
global top k is in its own shard's top k.

Layout under the KB's ``bm25/``: ``shards.json`` (written last, so a reader sees the sharded
index only once it is complete) and ``shard-00000/`` ... (each a bm25s directory). The raw
postings live in the builder's ``work_dir`` during the build and are removed by `save`.
`kb_service.reshard.shard_kb` turns a built KB's single index into shards in place.
"""

from __future__ import annotations

import heapq
import json
import os
import resource
import shutil
import signal
import time
from array import array
from pathlib import Path
from typing import Callable, Iterator, Protocol

import numpy as np

from kb_service.engines import B, K1, METHOD, BM25Builder, BM25Searcher, save_bm25s, write_json

SHARDS_FILE = "shards.json"
SHARDS_FORMAT = "hcgym-bm25-shards"
DEFAULT_SHARD_DOCS = 2_000_000
PROGRESS_FILE = "progress.json"
BUILD_FORMAT = "hcgym-bm25-shard-build"

# Working-set model of one shard, in bytes (the constants behind `memory_bytes`). Weighting a
# shard holds, per posting, its document, term and tf, the document's length, the idf, the
# tf component, the weight and the int64 column order at once (~40 bytes, see `_weigh`); per
# term, the vocabulary as a list and as a dict, and the set and JSON text bm25s makes of it on
# save. `add` holds less: 12 bytes a posting and the vocabulary dict. Checked against a measured
# peak RSS by tests/kb/test_bounded_build.py.
BYTES_PER_POSTING = 40
BYTES_PER_TERM = 250
# BM25Builder's flush of its token buffer: the list of ids, its int64 copy, the document ids,
# the packed keys and np.unique's sorted copy and counts.
BYTES_PER_BUFFERED_TOKEN = 72
DEFAULT_FLUSH_TOKENS = 4_000_000
MIN_MEMORY_BYTES = 8 << 20

KILL_ENV = "HCGYM_KB_TEST_KILL_AT"


def kill_point(stage: str, index: int) -> None:
    """SIGKILL this process right after commit `index` of `stage` when $HCGYM_KB_TEST_KILL_AT is
    ``"stage:index"``: how the tests interrupt a build at a known point (no timing involved)."""
    if os.environ.get(KILL_ENV) == f"{stage}:{index}":
        os.kill(os.getpid(), signal.SIGKILL)


def process_rss_bytes() -> int:
    """This process's resident set now (/proc/self/statm); its peak so far where /proc is absent."""
    try:
        with open("/proc/self/statm") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def peak_rss_bytes() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def release_memory() -> None:
    """Hand freed heap memory back to the system (glibc's malloc_trim). Without it, memory a
    finished shard freed stays resident as fragmented heap: 100 MB after a 12M-posting shard."""
    global _malloc_trim
    if _malloc_trim is None:
        try:
            import ctypes

            _malloc_trim = ctypes.CDLL("libc.so.6").malloc_trim
        except (OSError, AttributeError):
            _malloc_trim = False
    if _malloc_trim:
        _malloc_trim(0)


_malloc_trim = None


def _read_npy_range(path: Path, start: int, count: int) -> np.ndarray:
    """Elements ``start .. start + count - 1`` of a 1-D .npy file, read without mapping the file."""
    with open(path, "rb") as fh:
        version = np.lib.format.read_magic(fh)
        if version == (1, 0):
            shape, _fortran, dtype = np.lib.format.read_array_header_1_0(fh)
        else:
            shape, _fortran, dtype = np.lib.format.read_array_header_2_0(fh)
        if len(shape) != 1 or start + count > shape[0]:
            raise ValueError(f"{path}: cannot read elements {start}..{start + count - 1} of an array of shape {shape}")
        fh.seek(start * dtype.itemsize, os.SEEK_CUR)
        return np.fromfile(fh, dtype=dtype, count=count)


def float32_mean(parts: list[tuple[Path, int]], chunk: int = 1 << 20) -> float:
    """The mean of the float32 arrays in `parts` ((.npy path, length), in order) taken as one array,
    equal bit for bit to ``np.concatenate(arrays).mean()``, reading at most `chunk` values at a time:
    `float32_sum`, then the same division as `np.mean` (tests/kb/test_shards.py compares them)."""
    total = float32_sum(parts, chunk)
    return float(total.dtype.type(total / np.intp(sum(n for _, n in parts))))  # np.mean's own division


def float32_sum(parts: list[tuple[Path, int]], chunk: int = 1 << 20) -> np.float32:
    """``np.add.reduce(np.concatenate(arrays))`` of the float32 arrays in `parts`, bit for bit,
    reading at most `chunk` values at a time.

    numpy sums a contiguous float32 array pairwise: halves cut at a multiple of 8 below the
    middle, recursively, down to blocks it adds itself. This follows the same cuts and lets numpy
    add every piece of at most `chunk` values, so the float32 sum is numpy's own."""
    if chunk < 8:
        raise ValueError(f"chunk must be at least 8 values, got {chunk}")
    starts = np.cumsum([0] + [n for _, n in parts])
    total_n = int(starts[-1])
    if total_n == 0:
        raise ValueError("no values to sum: the parts are empty")

    def read(lo: int, n: int) -> np.ndarray:
        out = []
        i = int(np.searchsorted(starts, lo, side="right")) - 1
        while n > 0:
            path, size = parts[i]
            at = lo - int(starts[i])
            take = min(n, size - at)
            if take > 0:
                out.append(_read_npy_range(path, at, take))
                lo, n = lo + take, n - take
            i += 1
        return out[0] if len(out) == 1 else np.concatenate(out)

    def pairwise(lo: int, n: int) -> np.float32:
        if n <= chunk:
            return np.add.reduce(read(lo, n).astype(np.float32, copy=False))
        half = n // 2
        half -= half % 8
        return np.float32(pairwise(lo, half) + pairwise(lo + half, n - half))

    return pairwise(0, total_n)


def _escape(term: str) -> str:
    """A term as one field of a tab-separated line (the shards' sorted term lists)."""
    return term.replace("\\", "\\\\").replace("\t", "\\t").replace("\n", "\\n").replace("\r", "\\r")


def _merge_df(dirs: list[Path], flush: int = 1 << 16) -> int:
    """Each term's document frequency summed over the shards in `dirs`, written as every shard's
    ``gdf.npy`` (the global df of its local term ids); returns the number of distinct terms.

    Each shard's ``terms.tsv`` lists its terms sorted (escaped term, tab, local df), so one merge
    of the sorted lists meets every term's entries one after another: the merge holds one line
    per shard and a write buffer per shard, whatever the size of the vocabulary."""
    readers = [open(d / "terms.tsv", encoding="utf-8", newline="\n") for d in dirs]
    outs = [open(d / "gdf.sorted.bin", "wb") for d in dirs]
    bufs = [array("q") for _ in dirs]

    def entries(s: int, fh):
        for line in fh:
            term, _, df = line[:-1].rpartition("\t")
            yield term, s, int(df)

    distinct = 0
    try:
        current, members, total = None, [], 0
        for term, s, df in heapq.merge(*(entries(s, fh) for s, fh in enumerate(readers))):
            if term != current:
                if members:
                    distinct += 1
                    for m in members:
                        bufs[m].append(total)
                        if len(bufs[m]) >= flush:
                            bufs[m].tofile(outs[m])
                            del bufs[m][:]
                current, members, total = term, [], 0
            members.append(s)
            total += df
        if members:
            distinct += 1
            for m in members:
                bufs[m].append(total)
        for buf, out in zip(bufs, outs):
            buf.tofile(out)
    finally:
        for fh in (*readers, *outs):
            fh.close()
    for d in dirs:
        order = np.load(d / "sorted.npy")
        gdf_sorted = np.fromfile(d / "gdf.sorted.bin", dtype=np.int64)
        if len(gdf_sorted) != len(order):
            raise ValueError(f"{d}: the df merge gave {len(gdf_sorted)} terms, the shard has {len(order)}")
        gdf = np.empty(len(order), dtype=np.int64)
        gdf[order] = gdf_sorted
        np.save(d / "gdf.npy", gdf)
        (d / "gdf.sorted.bin").unlink()
    return distinct


class ShardedBM25Builder:
    """Same interface as `BM25Builder` (`add(tokens)` per document in row order, then `save`).

    Args:
        work_dir: the shards' raw postings until `save` (and the build's progress).
        shard_docs: at most this many documents a shard.
        memory_bytes: also cut a shard when its estimated working set reaches this many bytes
            (the build's memory budget less what the process holds already); None: no limit.
        resume: continue the build committed in `work_dir` (when its settings and `context`
            match; otherwise start afresh). `n_docs` is then the number of documents already
            committed: feed the documents after them.
        context: what else must match for a resume (e.g. the number of passages in the store).
        on_commit: called as ``on_commit(shard, offset, num_docs)`` after a shard's raw files are
            in place and before the shard is committed: the caller's per-shard data is written
            there, so that it commits with the shard.
        after_commit: called as ``after_commit(shard, spec)`` once the shard is committed (spec: its
            dir, offset, num_docs, postings, vocab): how a parallel build's worker reports it.
        echo: progress lines (one per committed shard); None: silent.
    """

    def __init__(self, work_dir: Path, shard_docs: int = DEFAULT_SHARD_DOCS, k1: float = K1, b: float = B,
                 method: str = METHOD, *, memory_bytes: int | None = None, resume: bool = False,
                 context: dict | None = None, on_commit: Callable[[int, int, int], None] | None = None,
                 after_commit: Callable[[int, dict], None] | None = None,
                 echo: Callable[[str], None] | None = None) -> None:
        if isinstance(shard_docs, bool) or not isinstance(shard_docs, int) or shard_docs < 1:
            raise ValueError(f"shard_docs must be a positive integer (documents per shard), got {shard_docs!r}")
        if memory_bytes is not None and (isinstance(memory_bytes, bool) or not isinstance(memory_bytes, int)
                                         or memory_bytes < MIN_MEMORY_BYTES):
            raise ValueError(f"memory_bytes must be an integer of at least {MIN_MEMORY_BYTES} (bytes a shard may "
                             f"use), got {memory_bytes!r}")
        self.shard_docs = shard_docs
        self.k1, self.b, self.method = k1, b, method
        self.memory_bytes = memory_bytes
        self.flush_tokens = DEFAULT_FLUSH_TOKENS if memory_bytes is None else max(
            10_000, min(DEFAULT_FLUSH_TOKENS, memory_bytes // (2 * BYTES_PER_BUFFERED_TOKEN)))
        self._work = Path(work_dir)
        self._on_commit = on_commit
        self._after_commit = after_commit
        self._echo = echo or (lambda _s: None)
        # `memory_bytes` is left out: it is the budget less what the process holds, which varies a
        # little from run to run; shards committed under the same budget stay valid.
        params = {"k1": k1, "b": b, "method": method, "shard_docs": shard_docs, "context": context or {}}
        progress = self._read_progress() if resume else None
        if progress is not None and progress.get("params") != params:
            self._echo(f"[kb] {self._work}: the interrupted bm25 build had other settings "
                       f"({progress.get('params')}); starting it afresh")
            progress = None
        self.fresh = progress is None
        if progress is None:
            shutil.rmtree(self._work, ignore_errors=True)
            progress = {"format": BUILD_FORMAT, "params": params, "shards": [], "stats": None, "final": []}
        self._progress = progress
        committed = {s["dir"] for s in progress["shards"]}
        if self._work.exists():  # a shard whose spill was interrupted is rebuilt
            for d in self._work.glob("shard-*"):
                if d.name not in committed:
                    shutil.rmtree(d)
        self.n_docs = sum(int(s["num_docs"]) for s in progress["shards"])
        self.resumed_docs = self.n_docs
        self._current: BM25Builder | None = None
        self._chunks = 0
        self._postings = 0

    # ------------------------------------------------------------------ progress (the commits)
    def _read_progress(self) -> dict | None:
        try:
            progress = json.loads((self._work / PROGRESS_FILE).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None
        if not isinstance(progress, dict) or progress.get("format") != BUILD_FORMAT:
            return None
        weighted = set(progress.get("final", []))  # their raw files are dropped once weighted
        if any(not (self._work / s.get("raw", s["dir"])).is_dir() for s in progress.get("shards", [])
               if s["dir"] not in weighted):
            return None  # a committed shard's files are gone: nothing to trust
        return progress

    def _commit(self) -> None:
        self._work.mkdir(parents=True, exist_ok=True)
        write_json(self._work / PROGRESS_FILE, self._progress)

    @property
    def committed_shards(self) -> int:
        return len(self._progress["shards"])

    def commit_start(self) -> None:
        """Commit the build's settings before any shard, so that a resume keeps what other
        builders (the parallel build's units, under `work_dir`) committed meanwhile."""
        self._commit()

    def finish_raw(self) -> list[dict]:
        """Spill the last shard and return the committed shards (dir, offset, num_docs, postings,
        vocab; offsets from this builder's first document): a unit of the parallel build, whose
        shards another builder adopts (`adopt`) and weighs."""
        self._spill()
        return [dict(s) for s in self._progress["shards"]]

    def adopt(self, shards: list[dict]) -> None:
        """Take over raw shards other builders committed under `work_dir`, in document order: each
        {"raw": its directory relative to `work_dir`, "offset", "num_docs", "postings", "vocab"}.
        They are named shard-00000... in the weighted index and committed here at once."""
        if self._progress["shards"] or self._current is not None:
            raise ValueError(f"{self._work}: this builder already holds shards; adopt needs a fresh one")
        expected = 0
        adopted = []
        for i, spec in enumerate(shards):
            if int(spec["offset"]) != expected:
                raise ValueError(f"{self._work / spec['raw']}: starts at document {spec['offset']}, "
                                 f"expected {expected}")
            if not (self._work / spec["raw"]).is_dir():
                raise ValueError(f"{self._work / spec['raw']}: raw shard missing")
            expected += int(spec["num_docs"])
            adopted.append({"dir": f"shard-{i:05d}", "raw": spec["raw"], "offset": int(spec["offset"]),
                            "num_docs": int(spec["num_docs"]), "postings": int(spec["postings"]),
                            "vocab": int(spec["vocab"])})
        self._progress["shards"] = adopted
        self.n_docs = expected
        self._commit()

    # ------------------------------------------------------------------ adding documents
    def add(self, tokens: list[str]) -> None:
        cur = self._current
        if cur is None:
            cur = self._current = BM25Builder(self.k1, self.b, self.method, flush_tokens=self.flush_tokens)
            self._chunks = self._postings = 0
        cur.add(tokens)
        self.n_docs += 1
        if cur.n_docs >= self.shard_docs or (self.memory_bytes is not None and self._over_budget(cur)):
            self._spill()

    def _over_budget(self, cur: BM25Builder) -> bool:
        if len(cur._docs) != self._chunks:  # a flush happened: count the postings it kept
            self._chunks = len(cur._docs)
            self._postings = sum(len(d) for d in cur._docs)
        # Buffered tokens count as postings (at most one each): the estimate stays an upper bound.
        postings = self._postings + len(cur._buf_ids)
        return BYTES_PER_POSTING * postings + BYTES_PER_TERM * len(cur.vocab) >= self.memory_bytes

    def _spill(self) -> None:
        """Write the current shard's raw postings, sorted term list and lengths; commit the shard."""
        bm = self._current
        self._current = None
        if bm is None or bm.n_docs == 0:
            return
        t0 = time.perf_counter()
        bm._flush()
        i = len(self._progress["shards"])
        name = f"shard-{i:05d}"
        tmp = self._work / f"{name}.tmp"
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir(parents=True)
        num_docs = bm.n_docs
        offset = self.n_docs - num_docs
        vocab_list = list(bm.vocab)
        bm.vocab = {}
        term = np.concatenate(bm._terms) if bm._terms else np.zeros(0, np.int32)
        bm._terms = []
        np.save(tmp / "term.npy", term)
        df = np.bincount(term, minlength=len(vocab_list))
        postings = int(len(term))
        del term
        for fname, attr, dtype in (("doc", "_docs", np.int32), ("tf", "_tfs", np.float32),
                                   ("lens", "_lens", np.float32)):
            parts = getattr(bm, attr)
            setattr(bm, attr, [])
            np.save(tmp / f"{fname}.npy", np.concatenate(parts) if parts else np.zeros(0, dtype))
            del parts
        del bm
        # Term ids are numbered in order of appearance, so the list's order is the id order.
        (tmp / "vocab.json").write_text(json.dumps(vocab_list, ensure_ascii=False), encoding="utf-8")
        escaped = [_escape(t) for t in vocab_list]
        del vocab_list
        order = sorted(range(len(escaped)), key=escaped.__getitem__)
        with open(tmp / "terms.tsv", "w", encoding="utf-8", newline="\n") as fh:
            fh.writelines(f"{escaped[j]}\t{df[j]}\n" for j in order)
        np.save(tmp / "sorted.npy", np.asarray(order, dtype=np.int64))
        vocab = len(escaped)
        del escaped, order
        os.replace(tmp, self._work / name)
        release_memory()
        if self._on_commit is not None:
            self._on_commit(i, offset, num_docs)
        self._progress["shards"].append({"dir": name, "offset": offset, "num_docs": num_docs, "postings": postings,
                                         "vocab": vocab})
        self._commit()
        self._echo(f"[kb] bm25 shard {i}: passages {offset + 1:,}-{offset + num_docs:,} committed "
                   f"({postings:,} postings, {vocab:,} terms, {time.perf_counter() - t0:.1f}s to write; "
                   f"RSS {process_rss_bytes() >> 20} MB)")
        if self._after_commit is not None:
            self._after_commit(i, dict(self._progress["shards"][-1]))
        kill_point("bm25-shard", i)

    # ------------------------------------------------------------------ finishing
    def save(self, out_dir: Path, pool: "WeighPool | None" = None) -> dict:
        """Finish the last shard, compute the global statistics, write every shard's weights
        (in `pool`'s worker processes when given, several shards at once; the weights are the same)."""
        out_dir = Path(out_dir)
        self._spill()
        shards = self._progress["shards"]
        if not shards:
            raise ValueError("cannot build a BM25 index over zero documents")
        final = self._progress["final"]
        if (out_dir / SHARDS_FILE).exists() and len(final) < len(shards):
            raise ValueError(f"{out_dir} already holds a sharded index ({SHARDS_FILE})")
        dirs = [self._work / s.get("raw", s["dir"]) for s in shards]
        stats = self._progress["stats"]
        if stats is None:
            t0 = time.perf_counter()
            n_docs = sum(int(s["num_docs"]) for s in shards)
            avg_len = float32_mean([(d / "lens.npy", int(s["num_docs"])) for d, s in zip(dirs, shards)])
            vocab = _merge_df(dirs)
            stats = self._progress["stats"] = {"num_docs": n_docs, "avg_len": avg_len, "vocab": vocab}
            self._commit()
            self._echo(f"[kb] bm25 global statistics: {n_docs:,} passages, average length {avg_len:.2f}, "
                       f"{vocab:,} distinct terms over {len(shards)} shards ({time.perf_counter() - t0:.1f}s)")
            kill_point("bm25-stats", 0)
        from bm25s.scoring import _select_idf_scorer, _select_tfc_scorer

        idf_fn = _select_idf_scorer(self.method)
        tfc_fn = _select_tfc_scorer(self.method)
        out_dir.mkdir(parents=True, exist_ok=True)
        for stale in out_dir.glob("shard-*"):  # from an interrupted run: not committed
            if stale.name not in final:
                shutil.rmtree(stale)
        todo = [(i, spec, d) for i, (spec, d) in enumerate(zip(shards, dirs)) if spec["dir"] not in final]

        def weighed(i: int, spec: dict, seconds: float, rss: int) -> None:
            final.append(spec["dir"])
            self._commit()
            # Committed: a resumed build neither weighs this shard again nor reads its raw postings
            # (the global statistics are in the progress file), and dropping them as they are
            # replaced keeps the build's disk peak at the raw shards' size instead of raw + weighted.
            shutil.rmtree(dirs[i], ignore_errors=True)
            self._echo(f"[kb] bm25 shard {i} weighted ({seconds:.1f}s; RSS {rss >> 20} MB)")
            kill_point("bm25-final", i)

        if pool is not None and len(todo) > 1:
            tasks = [(i, (str(d), str(out_dir / spec["dir"]), stats, self.k1, self.b, self.method))
                     for i, spec, d in todo]
            by_index = {i: spec for i, spec, _d in todo}
            for i, (seconds, rss) in pool.weigh(tasks):
                weighed(i, by_index[i], seconds, rss)
        else:
            for i, spec, d in todo:
                t0 = time.perf_counter()
                self._weigh(d, out_dir / spec["dir"], stats, idf_fn, tfc_fn)
                release_memory()
                weighed(i, spec, time.perf_counter() - t0, process_rss_bytes())
        postings = sum(int(s["postings"]) for s in shards)
        write_json(out_dir / SHARDS_FILE, {
            "format": SHARDS_FORMAT, "num_docs": stats["num_docs"], "avg_len": stats["avg_len"],
            "vocab": stats["vocab"], "bm25": {"k1": self.k1, "b": self.b, "method": self.method},
            "shard_docs": self.shard_docs, "memory_bytes": self.memory_bytes,
            "shards": [{k: s[k] for k in ("dir", "offset", "num_docs", "vocab", "postings")} for s in shards],
        })
        shutil.rmtree(self._work, ignore_errors=True)
        return {"num_docs": stats["num_docs"], "vocab": stats["vocab"], "postings": postings, "shards": len(shards)}

    def _weigh(self, raw: Path, dest: Path, stats: dict, idf_fn, tfc_fn) -> None:
        weigh_shard(raw, dest, stats, self.k1, self.b, self.method, idf_fn, tfc_fn)


class WeighPool(Protocol):
    """What `ShardedBM25Builder.save` needs of a pool of worker processes (kb_service.parallel_build.WorkerPool)."""

    def weigh(self, tasks: list[tuple[int, tuple]]) -> Iterator[tuple[int, tuple[float, int]]]:
        """Run ``weigh_shard(*args)`` for each (index, args) task; yield (index, (seconds, the
        worker's RSS)) as each finishes."""
        ...


def weigh_shard(raw: Path, dest: Path, stats: dict, k1: float, b: float, method: str, idf_fn=None,
                tfc_fn=None) -> None:
    """One shard's bm25s matrix with the global N, average length and df; written to
    ``dest.tmp`` and renamed. Arrays are dropped as soon as they are used (the working set
    `BYTES_PER_POSTING` describes)."""
    if idf_fn is None or tfc_fn is None:
        from bm25s.scoring import _select_idf_scorer, _select_tfc_scorer

        idf_fn, tfc_fn = _select_idf_scorer(method), _select_tfc_scorer(method)
    raw, dest = Path(raw), Path(dest)
    n_docs, avg_len = stats["num_docs"], stats["avg_len"]
    vocab_list = json.loads((raw / "vocab.json").read_text(encoding="utf-8"))
    gdf = np.load(raw / "gdf.npy")
    # The idf of each distinct df value, with bm25s's own function (as BM25Builder, term by term).
    values, inverse = np.unique(gdf, return_inverse=True)
    idf = np.array([idf_fn(int(v), N=n_docs) for v in values], dtype=np.float32)[inverse]
    del gdf, values, inverse
    term = np.load(raw / "term.npy")
    df = np.bincount(term, minlength=len(vocab_list))
    order = np.argsort(term, kind="stable")  # column-major; rows stay ascending within a column
    w = idf[term]
    del term, idf
    doc, lens, tf = np.load(raw / "doc.npy"), np.load(raw / "lens.npy"), np.load(raw / "tf.npy")
    l_d = lens[doc]
    tfc = tfc_fn(tf_array=tf, l_d=l_d, l_avg=avg_len, k1=k1, b=b)
    del tf, l_d
    data = (w * tfc).astype(np.float32)
    del w, tfc
    data = data[order]
    indices = doc[order].astype(np.int32, copy=False)
    del doc, order
    indptr = np.zeros(len(vocab_list) + 1, dtype=np.int64)
    np.cumsum(df, out=indptr[1:])
    scores = {"data": data, "indices": indices, "indptr": indptr, "num_docs": int(len(lens))}
    tmp = dest.with_name(dest.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    save_bm25s(tmp, scores, {t: j for j, t in enumerate(vocab_list)}, k1, b, method)
    os.replace(tmp, dest)


def is_sharded(bm25_dir: Path) -> bool:
    return (Path(bm25_dir) / SHARDS_FILE).is_file()


def select_terms(terms: list[str], dfs: list[int], max_terms: int) -> list[str]:
    """The terms with a global document frequency `dfs[i]` > 0, in query order (repeats kept),
    cut to the `max_terms` most selective (smallest df, ties to the earlier term) as
    `BM25Searcher.term_ids` cuts them."""
    kept = [(t, df) for t, df in zip(terms, dfs) if df > 0]
    if len(kept) > max_terms:
        keep = sorted(range(len(kept)), key=lambda j: (kept[j][1], j))[:max_terms]
        kept = [kept[j] for j in sorted(keep)]
    return [t for t, _ in kept]


def merge_top_k(docs: list[np.ndarray], raw: list[np.ndarray], k: int) -> tuple[np.ndarray, np.ndarray]:
    """The k best of several top-k lists: (global document numbers, unscaled float32 sums).

    Each list is a shard's (or a group of shards') own top k, documents already offset to global
    numbers. Merged on the kernel's own sums, score descending then document ascending (the
    kernel's tie rule): after the (k1 + 1) factor two different sums can round to one value, and
    ordering those by document would differ from the single index. Merging merged lists again
    gives the same result, so shard actors can merge their shards before the service merges them.
    """
    if not docs:
        return np.zeros(0, np.int64), np.zeros(0, np.float32)
    all_docs, all_raw = np.concatenate(docs), np.concatenate(raw)
    order = np.lexsort((all_docs, -all_raw))[:k]
    return all_docs[order], all_raw[order]


def shards_df(shards: list[BM25Searcher], terms: list[str]) -> list[int]:
    """Each term's document frequency summed over `shards` (the lengths of its columns)."""
    totals = [0] * len(terms)
    for shard in shards:
        for i, j in enumerate(shard.vocab.columns(terms)):
            if j is not None:
                totals[i] += int(shard.indptr[j + 1] - shard.indptr[j])
    return totals


def search_shards(shards: list[BM25Searcher], offsets: list[int], terms: list[str], k: int,
                  weight_mask: np.ndarray | None = None, mask_start: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The merged top k of `shards` (shard i holds global documents from `offsets[i]`) for the
    query `terms`: (global document numbers, unscaled sums; see `merge_top_k`). `weight_mask`
    covers the documents from `mask_start` on (the whole corpus for `ShardedBM25Searcher`, a
    shard actor's own range in the KB service)."""
    if not terms or k <= 0:
        return np.zeros(0, np.int64), np.zeros(0, np.float32)
    all_docs, all_scores = [], []
    for offset, shard in zip(offsets, shards):
        ids = [j for j in shard.vocab.columns(terms) if j is not None]
        if not ids:
            continue
        start = offset - mask_start
        mask = None if weight_mask is None else weight_mask[start:start + shard.num_docs]
        docs, raw = shard.search_unscaled(ids, k, mask)
        all_docs.append(docs + offset)
        all_scores.append(raw)
    return merge_top_k(all_docs, all_scores, k)


class ShardedBM25Searcher:
    """The `BM25Searcher` interface over a sharded index (`term_ids`, `search`, `num_docs`...).

    `term_ids` returns the selected query terms themselves (each shard maps them to its own ids).
    """

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        meta = json.loads((self.path / SHARDS_FILE).read_text(encoding="utf-8"))
        if not isinstance(meta, dict) or meta.get("format") != SHARDS_FORMAT:
            raise ValueError(f"{self.path / SHARDS_FILE} is not a sharded BM25 manifest")
        self.meta = meta
        self.num_docs = int(meta["num_docs"])
        self.offsets = [int(s["offset"]) for s in meta["shards"]]
        self.shards = [BM25Searcher(self.path / s["dir"]) for s in meta["shards"]]
        self.scale = self.shards[0].scale

    def validate(self) -> None:
        expected = 0
        for spec, shard in zip(self.meta["shards"], self.shards):
            shard.validate()
            if int(spec["offset"]) != expected or shard.num_docs != int(spec["num_docs"]):
                raise ValueError(f"shard {spec['dir']} holds {shard.num_docs} documents at offset {spec['offset']}; "
                                 f"shards.json expects {spec['num_docs']} at offset {expected}")
            expected += shard.num_docs
        if expected != self.num_docs:
            raise ValueError(f"the shards hold {expected} documents, shards.json says {self.num_docs}")

    def df(self, term: str) -> int:
        """The term's document frequency over the whole corpus (the sum of its shards' columns)."""
        return self.dfs([term])[0]

    def dfs(self, terms: list[str]) -> list[int]:
        """Each term's document frequency over the whole corpus."""
        return shards_df(self.shards, terms)

    def term_ids(self, terms: list[str], max_terms: int) -> list[str]:
        """The query terms any shard knows, cut to `max_terms` by global df (as `BM25Searcher`)."""
        return select_terms(terms, self.dfs(terms), max_terms)

    def search(self, terms: list[str], k: int, weight_mask: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Global top-k (document numbers, scores), best first; ties go to the lower document."""
        docs, raw = search_shards(self.shards, self.offsets, terms, k, weight_mask)
        return docs, raw * self.scale

    def warmup(self) -> None:
        for shard in self.shards:
            shard.warmup()
