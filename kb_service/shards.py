"""A BM25 index built as shards, searched with an exact global top-k.

Each shard is an ordinary bm25s index (the CSC matrix `BM25Searcher` memory-maps) over a
contiguous slice of the passages: shard ``s`` holds documents ``offset_s .. offset_s + n_s - 1``
(the store's rows ``offset_s + 1 ..``), with its own vocabulary of the terms that slice contains.

Exactness. A BM25 weight depends on corpus-wide statistics: the number of documents N, the
average document length and each term's document frequency. A shard scored with its own slice's
statistics would rank differently from one index over the whole corpus. So the build is two
steps: every shard first keeps its raw postings (document, term, tf) and document lengths on
disk; `finalize` then sums the document frequencies over all shards, takes N and the average
length over the whole corpus (the same float32 mean of the same lengths as `BM25Builder`), and
writes each shard's weights with those global statistics and bm25s's own scoring functions. A
shard's weight for (term, document) is therefore bit-for-bit the single index's weight.

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

import json
import shutil
from pathlib import Path

import numpy as np

from kb_service.engines import B, K1, METHOD, BM25Builder, BM25Searcher, save_bm25s, write_json

SHARDS_FILE = "shards.json"
SHARDS_FORMAT = "hcgym-bm25-shards"
DEFAULT_SHARD_DOCS = 2_000_000


class ShardedBM25Builder:
    """Same interface as `BM25Builder` (`add(tokens)` per document in row order, then `save`)."""

    def __init__(self, work_dir: Path, shard_docs: int = DEFAULT_SHARD_DOCS, k1: float = K1, b: float = B, method: str = METHOD) -> None:
        if isinstance(shard_docs, bool) or not isinstance(shard_docs, int) or shard_docs < 1:
            raise ValueError(f"shard_docs must be a positive integer (documents per shard), got {shard_docs!r}")
        self.shard_docs = shard_docs
        self.k1, self.b, self.method = k1, b, method
        self._work = Path(work_dir)  # the shards' raw postings until `save`
        self._raw: list[Path] = []
        self._current: BM25Builder | None = None
        self.n_docs = 0

    def _raw_dir(self) -> Path:
        self._work.mkdir(parents=True, exist_ok=True)
        return self._work

    def add(self, tokens: list[str]) -> None:
        if self._current is None:
            self._current = BM25Builder(self.k1, self.b, self.method)
        self._current.add(tokens)
        self.n_docs += 1
        if self._current.n_docs >= self.shard_docs:
            self._spill()

    def _spill(self) -> None:
        """Write the current shard's raw postings to disk and free them."""
        bm = self._current
        self._current = None
        if bm is None or bm.n_docs == 0:
            return
        bm._flush()
        d = self._raw_dir() / f"shard-{len(self._raw):05d}"
        d.mkdir(parents=True, exist_ok=True)
        for name, parts, dtype in (("doc", bm._docs, np.int32), ("term", bm._terms, np.int32),
                                   ("tf", bm._tfs, np.float32), ("lens", bm._lens, np.float32)):
            np.save(d / f"{name}.npy", np.concatenate(parts) if parts else np.zeros(0, dtype))
        # Term ids are numbered in order of appearance, so the list's order is the id order.
        (d / "vocab.json").write_text(json.dumps(list(bm.vocab), ensure_ascii=False), encoding="utf-8")
        self._raw.append(d)

    def save(self, out_dir: Path) -> dict:
        """Finish the last shard, compute the global statistics, write every shard's weights."""
        out_dir = Path(out_dir)
        self._spill()
        if not self._raw:
            raise ValueError("cannot build a BM25 index over zero documents")
        from bm25s.scoring import _select_idf_scorer, _select_tfc_scorer

        # Global statistics: N, the average length (the float32 mean over all lengths in row
        # order, exactly as BM25Builder computes it) and the document frequency of every term.
        lens_all = np.concatenate([np.load(d / "lens.npy") for d in self._raw])
        n_docs = len(lens_all)
        avg_len = float(lens_all.mean())
        del lens_all
        gdf: dict[str, int] = {}
        for d in self._raw:
            vocab = json.loads((d / "vocab.json").read_text(encoding="utf-8"))
            df = np.bincount(np.load(d / "term.npy"), minlength=len(vocab))
            for t, c in zip(vocab, df.tolist()):
                if c:
                    gdf[t] = gdf.get(t, 0) + c
        idf_fn = _select_idf_scorer(self.method)
        tfc_fn = _select_tfc_scorer(self.method)

        if (out_dir / SHARDS_FILE).exists():
            raise ValueError(f"{out_dir} already holds a sharded index ({SHARDS_FILE})")
        out_dir.mkdir(parents=True, exist_ok=True)
        for stale in out_dir.glob("shard-*"):  # from an interrupted run (no shards.json yet)
            shutil.rmtree(stale)
        shards, offset, postings = [], 0, 0
        for i, d in enumerate(self._raw):
            vocab_list = json.loads((d / "vocab.json").read_text(encoding="utf-8"))
            doc, term = np.load(d / "doc.npy"), np.load(d / "term.npy")
            tf, lens = np.load(d / "tf.npy"), np.load(d / "lens.npy")
            df = np.bincount(term, minlength=len(vocab_list))
            idf = np.zeros(len(vocab_list), dtype=np.float32)
            for t in np.flatnonzero(df):
                idf[t] = idf_fn(gdf[vocab_list[t]], N=n_docs)
            tfc = tfc_fn(tf_array=tf, l_d=lens[doc], l_avg=avg_len, k1=self.k1, b=self.b)
            data = (idf[term] * tfc).astype(np.float32)
            order = np.argsort(term, kind="stable")
            indptr = np.zeros(len(vocab_list) + 1, dtype=np.int64)
            np.cumsum(df, out=indptr[1:])
            scores = {"data": data[order], "indices": doc[order].astype(np.int32), "indptr": indptr,
                      "num_docs": int(len(lens))}
            name = f"shard-{i:05d}"
            save_bm25s(out_dir / name, scores, {t: j for j, t in enumerate(vocab_list)}, self.k1, self.b, self.method)
            shards.append({"dir": name, "offset": offset, "num_docs": int(len(lens)), "vocab": len(vocab_list),
                           "postings": int(len(data))})
            offset += int(len(lens))
            postings += int(len(data))
        write_json(out_dir / SHARDS_FILE, {
            "format": SHARDS_FORMAT, "num_docs": n_docs, "avg_len": avg_len, "vocab": len(gdf),
            "bm25": {"k1": self.k1, "b": self.b, "method": self.method}, "shard_docs": self.shard_docs,
            "shards": shards,
        })
        shutil.rmtree(self._work, ignore_errors=True)
        return {"num_docs": n_docs, "vocab": len(gdf), "postings": postings, "shards": len(shards)}


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
        ids = [shard.vocab[t] for t in terms if t in shard.vocab]
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
        total = 0
        for shard in self.shards:
            j = shard.vocab.get(term)
            if j is not None:
                total += int(shard.indptr[j + 1] - shard.indptr[j])
        return total

    def term_ids(self, terms: list[str], max_terms: int) -> list[str]:
        """The query terms any shard knows, cut to `max_terms` by global df (as `BM25Searcher`)."""
        return select_terms(terms, [self.df(t) for t in terms], max_terms)

    def search(self, terms: list[str], k: int, weight_mask: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Global top-k (document numbers, scores), best first; ties go to the lower document."""
        docs, raw = search_shards(self.shards, self.offsets, terms, k, weight_mask)
        return docs, raw * self.scale

    def warmup(self) -> None:
        for shard in self.shards:
            shard.warmup()
