"""The two search engines behind a knowledge base.

* Free text (almost every agent query): **bm25s** with its numba backend. bm25s precomputes
  every (term, document) BM25 weight into a CSC sparse matrix, so a query is a sum of a few
  columns plus a top-k selection, the fastest of the engines compared (docs/kb.md; docs/benchmarks.md,
  "Knowledge base").
  Loaded with ``mmap=True``, so every process on a machine shares one copy in the page cache.
  Queried with our own numba kernel over that matrix (`_topk_kernel`: the same weights, a
  top-k over only the documents the query touches), faster than bm25s's `retrieve` because it skips
  the dense score array of all documents (docs/benchmarks.md, "Knowledge base").
* Query syntax (phrases, AND/OR/NOT, +/-): **tantivy**, which has positions, phrase queries,
  boolean queries and block-max WAND. Same analyzer, same BM25 parameters (k1=1.2, b=0.75,
  Lucene idf), so the two engines score a plain term identically up to tantivy's one-byte
  field-norm quantisation.

Building: bm25s's own ``BM25.index`` holds every document as a Python list of token strings
(5.8 GB at 828K passages). `BM25Builder` streams instead: it maps tokens to ids as documents
arrive, keeps compact numpy (doc, term, tf) arrays, then computes the matrix with bm25s's own
idf/tf scoring functions and writes bm25s's on-disk format (`BM25.save`), which `BM25.load`
reads back. A test checks the result is identical to ``bm25s.BM25.index`` on a corpus.
"""

from __future__ import annotations

import functools
import json
import os
import threading
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from envs.core.files import write_text_atomic

K1 = 1.2
B = 0.75
METHOD = "lucene"  # idf = log(1 + (N - df + 0.5) / (df + 0.5)): always > 0, as tantivy/Lucene


# --------------------------------------------------------------------------------------------
# bm25s
# --------------------------------------------------------------------------------------------


class BM25Builder:
    """Streaming construction of a bm25s index from analysed token lists."""

    def __init__(self, k1: float = K1, b: float = B, method: str = METHOD, flush_tokens: int = 4_000_000) -> None:
        self.k1, self.b, self.method = k1, b, method
        self.vocab: dict[str, int] = {}
        self.n_docs = 0
        self._flushed_docs = 0
        self._buf_ids: list[int] = []
        self._buf_lens: list[int] = []
        self._docs: list[np.ndarray] = []
        self._terms: list[np.ndarray] = []
        self._tfs: list[np.ndarray] = []
        self._lens: list[np.ndarray] = []
        self.flush_tokens = flush_tokens

    def add(self, tokens: list[str]) -> None:
        vocab = self.vocab
        if not vocab.keys() >= set(tokens):  # new terms: number them in order of appearance
            for t in tokens:
                if t not in vocab:
                    vocab[t] = len(vocab)
        self._buf_ids.extend(map(vocab.__getitem__, tokens))  # C-level loop
        self._buf_lens.append(len(tokens))
        self.n_docs += 1
        if len(self._buf_ids) >= self.flush_tokens:
            self._flush()

    def _flush(self) -> None:
        if not self._buf_lens:
            return
        lens = np.asarray(self._buf_lens, dtype=np.int64)
        ids = np.asarray(self._buf_ids, dtype=np.int64)
        docs = np.repeat(np.arange(self._flushed_docs, self._flushed_docs + len(lens), dtype=np.int64), lens)
        keys, tf = np.unique((docs << 32) | ids, return_counts=True)  # sorted by (doc, term)
        self._docs.append((keys >> 32).astype(np.int32))
        self._terms.append((keys & 0xFFFFFFFF).astype(np.int32))
        self._tfs.append(tf.astype(np.float32))
        self._lens.append(lens.astype(np.float32))
        self._flushed_docs += len(lens)
        self._buf_ids, self._buf_lens = [], []

    def build(self) -> dict:
        """Return bm25s's `scores` dict (data, indices, indptr, num_docs)."""
        from bm25s.scoring import _select_idf_scorer, _select_tfc_scorer

        self._flush()
        n_docs, n_vocab = self.n_docs, len(self.vocab)
        if n_docs == 0:
            raise ValueError("cannot build a BM25 index over zero documents")
        doc = np.concatenate(self._docs) if self._docs else np.zeros(0, np.int32)
        term = np.concatenate(self._terms) if self._terms else np.zeros(0, np.int32)
        tf = np.concatenate(self._tfs) if self._tfs else np.zeros(0, np.float32)
        lens = np.concatenate(self._lens)
        self._docs, self._terms, self._tfs, self._lens = [], [], [], []

        df = np.bincount(term, minlength=n_vocab)
        idf_fn = _select_idf_scorer(self.method)
        idf = np.zeros(n_vocab, dtype=np.float32)
        for t in np.flatnonzero(df):
            idf[t] = idf_fn(int(df[t]), N=n_docs)
        avg_len = float(lens.mean())
        tfc = _select_tfc_scorer(self.method)(tf_array=tf, l_d=lens[doc], l_avg=avg_len, k1=self.k1, b=self.b)
        del tf
        data = (idf[term] * tfc).astype(np.float32)
        del tfc
        order = np.argsort(term, kind="stable")  # column-major; rows stay ascending within a column
        indices = doc[order]
        del doc
        data = data[order]
        del order, term
        indptr = np.zeros(n_vocab + 1, dtype=np.int64)
        np.cumsum(df, out=indptr[1:])
        self.avg_len = avg_len
        return {"data": data, "indices": indices.astype(np.int32), "indptr": indptr, "num_docs": n_docs}

    def save(self, out_dir: Path) -> dict:
        scores = self.build()
        save_bm25s(out_dir, scores, self.vocab, self.k1, self.b, self.method)
        return {"num_docs": scores["num_docs"], "vocab": len(self.vocab), "postings": int(len(scores["data"]))}


def save_bm25s(out_dir: Path, scores: dict, vocab: dict[str, int], k1: float, b: float, method: str) -> None:
    """Write a precomputed weight matrix (bm25s's `scores` dict) in bm25s's on-disk format."""
    import bm25s

    retriever = bm25s.BM25(k1=k1, b=b, method=method, backend="numba", auto_compile=False)
    retriever.scores = scores
    retriever.vocab_dict = vocab
    retriever.unique_token_ids_set = set(vocab.values())
    retriever.nonoccurrence_array = None
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    retriever.save(str(out_dir), show_progress=False)


@functools.cache
def _topk_kernel():
    """The query-time kernel over bm25s's matrix, compiled once with numba's on-disk cache.

    bm25s's own kernel (`bm25s.numba.retrieve_utils`) allocates a zeroed score array of every
    document per query (3.3 MB at 828K passages, page faults included) and runs its top-k heap over
    all of them, although a query touches a fraction of the documents (median 15% on the benchmark
    corpus). This kernel sums the same precomputed BM25 weights (``data[j]`` of bm25s's CSC matrix,
    so scores are identical) into a score buffer that is kept between queries, records which
    documents it touches, selects the top k among those alone and resets only them: the scan is
    proportional to the query's postings, not to the corpus. Measured in docs/benchmarks.md.

    Compiled with ``cache=True`` (bm25s compiles without it, ~6 s in every new process; the cache
    loads in ~0.5 s). ``nogil``: concurrent threads each use their own buffers.
    """
    from numba import njit

    @njit(nogil=True, cache=True)
    def topk(ids, data, indptr, indices, k, scores, touched, mask, use_mask):  # pragma: no cover - numba
        n_touched = 0
        for t in ids:
            for j in range(indptr[t], indptr[t + 1]):
                d = indices[j]
                # Branch-free "append d if untouched" (a mispredicted branch here cost more
                # than the rest of the loop): BM25 weights are > 0 (Lucene idf), so 0 means
                # untouched; the slot is overwritten when d was already there.
                touched[n_touched] = d
                n_touched += scores[d] == 0.0
                scores[d] += data[j]
        best_s = np.full(k, -1.0, dtype=np.float32)
        best_d = np.full(k, -1, dtype=np.int64)
        floor, floor_at, filled = np.float32(-1.0), 0, 0
        for i in range(n_touched):
            d = touched[i]
            s = scores[d]
            scores[d] = 0.0  # leave the buffer zeroed for the next query
            if use_mask:
                s = s * mask[d]
                if s <= 0.0:
                    continue
            # Ties go to the lower document number, whatever order documents were touched in.
            if filled < k:
                best_s[filled] = s
                best_d[filled] = d
                filled += 1
                if filled < k:
                    continue
            elif s < floor or (s == floor and d > best_d[floor_at]):
                continue
            else:
                best_s[floor_at] = s
                best_d[floor_at] = d
            floor_at = 0  # find the new weakest of the k
            for m in range(1, k):
                if best_s[m] < best_s[floor_at] or (best_s[m] == best_s[floor_at] and best_d[m] > best_d[floor_at]):
                    floor_at = m
            floor = best_s[floor_at]
        # Sort the kept ones: score descending, then document number ascending.
        order = np.argsort(best_d[:filled], kind="mergesort")
        order = order[np.argsort(-best_s[:filled][order], kind="mergesort")]
        return best_d[:filled][order], best_s[:filled][order]

    return topk


class TermLookup(Mapping):
    """A bm25s vocabulary (term -> matrix column) held in ~30 bytes a term: the columns' terms as
    one UTF-8 blob with offsets, and their hashes sorted beside the columns.

    bm25s loads the vocabulary as a dict, ~190 bytes a term; a 10M-passage KB's 25 shards hold
    35M terms, 6.3 GB a process, which crowds the index's postings out of the page cache
    (docs/benchmarks.md, "10M passages"). `columns` looks many terms up with one `searchsorted`;
    a hash match is confirmed against the term's bytes, so a collision never maps a term to
    another's column. The hashes are this process's own `hash(str)` (built at load, never stored).
    """

    def __init__(self, vocab: dict[str, int]) -> None:
        n = len(vocab)
        by_column: list[str | None] = [None] * n
        for term, column in vocab.items():
            if not 0 <= column < n or by_column[column] is not None:
                raise ValueError(f"bm25s vocabulary columns are not 0..{n - 1} (term {term!r} has {column})")
            by_column[column] = term
        encoded = [t.encode("utf-8") for t in by_column]
        self._offsets = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(np.fromiter(map(len, encoded), dtype=np.int64, count=n), out=self._offsets[1:])
        self._blob = b"".join(encoded)
        del encoded
        hashes = np.fromiter(map(hash, by_column), dtype=np.int64, count=n)
        order = np.argsort(hashes, kind="stable")
        self._hashes = hashes[order]
        self._columns = order.astype(np.int32 if n < 2 ** 31 else np.int64)

    def __len__(self) -> int:
        return len(self._hashes)

    def term(self, column: int) -> str:
        return self._blob[self._offsets[column]:self._offsets[column + 1]].decode("utf-8")

    def __iter__(self):  # terms in column order, as the dict bm25s wrote
        return (self.term(j) for j in range(len(self)))

    def __getitem__(self, term: str) -> int:
        column = self.columns([term])[0]
        if column is None:
            raise KeyError(term)
        return column

    def __contains__(self, term: object) -> bool:
        return isinstance(term, str) and self.columns([term])[0] is not None

    def columns(self, terms: list[str]) -> list[int | None]:
        """Each term's column, or None for a term this vocabulary lacks."""
        if not terms or not len(self._hashes):
            return [None] * len(terms)
        wanted = np.fromiter(map(hash, terms), dtype=np.int64, count=len(terms))
        starts = np.searchsorted(self._hashes, wanted).tolist()
        hashes, columns, offsets, blob = self._hashes, self._columns, self._offsets, self._blob
        out: list[int | None] = []
        for term, h, i in zip(terms, wanted.tolist(), starts):
            found = None
            if i < len(hashes) and hashes[i] == h:  # candidates: the run of equal hashes from i
                raw = term.encode("utf-8")
                while i < len(hashes) and hashes[i] == h:
                    j = int(columns[i])
                    if blob[offsets[j]:offsets[j + 1]] == raw:
                        found = j
                        break
                    i += 1
            out.append(found)
        return out


class BM25Searcher:
    """A loaded (memory-mapped) bm25s index."""

    def __init__(self, path: Path) -> None:
        import bm25s

        self.path = Path(path)
        # The vocabulary is read here, not by bm25s, which would keep it as a dict and a set of its
        # column ids (~250 bytes a term together); `TermLookup` holds it in ~30.
        self.retriever = bm25s.BM25.load(str(self.path), mmap=True, load_corpus=False, load_vocab=False,
                                         show_progress=False)
        from bm25s.utils import json_functions

        with open(self.path / "vocab.index.json", encoding="utf-8") as fh:
            self.vocab = TermLookup(json_functions.loads(fh.read()))
        s = self.retriever.scores
        self.data, self.indptr, self.indices = s["data"], s["indptr"], s["indices"]
        self.num_docs = int(s["num_docs"])
        self.scale = float(self.retriever.k1) + 1.0
        self._buffers = threading.local()  # per-thread score/touched buffers for the kernel
        self._no_mask = np.zeros(1, dtype=np.float32)

    def validate(self) -> None:
        n_post = int(self.indptr[-1])
        if len(self.indptr) != len(self.vocab) + 1 or n_post != len(self.data) or n_post != len(self.indices):
            raise ValueError("bm25s arrays are inconsistent (truncated or mismatched files)")

    def term_ids(self, terms: list[str], max_terms: int) -> list[int]:
        ids = [j for j in self.vocab.columns(terms) if j is not None]
        if len(ids) > max_terms:  # keep the most selective terms (smallest document frequency)
            df = [int(self.indptr[i + 1] - self.indptr[i]) for i in ids]
            keep = sorted(range(len(ids)), key=lambda j: (df[j], j))[:max_terms]
            ids = [ids[j] for j in sorted(keep)]
        return ids

    def _thread_buffers(self) -> tuple[np.ndarray, np.ndarray]:
        buf = getattr(self._buffers, "pair", None)
        if buf is None:
            # `touched` has one slot more than there are documents: the kernel writes a document
            # into the next slot before knowing whether it is new, so once a query has touched
            # every document the next posting writes one past the last (a heap overrun otherwise).
            buf = self._buffers.pair = (np.zeros(self.num_docs, dtype=np.float32),
                                        np.zeros(self.num_docs + 1, dtype=np.int64))
        return buf

    def search(self, ids: list[int], k: int, weight_mask: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Top-k (doc indices, scores) with score > 0, best first (ties: lower document first)."""
        docs, top = self.search_unscaled(ids, k, weight_mask)
        # bm25s's Lucene variant leaves out BM25's constant (k1 + 1) numerator; tantivy keeps it.
        # Multiply it back so both engines report scores on one scale (ranking is unchanged).
        return docs, top * self.scale

    def search_unscaled(self, ids: list[int], k: int, weight_mask: np.ndarray | None = None
                        ) -> tuple[np.ndarray, np.ndarray]:
        """`search` before the (k1 + 1) factor: the kernel's float32 sums, in the order it ranked
        them. Two different sums can round to the same value once multiplied, so whoever merges
        rankings (the sharded index) must compare these, not the scaled scores."""
        if not ids or k <= 0:
            return np.zeros(0, np.int64), np.zeros(0, np.float32)
        k = min(k, self.num_docs)
        scores, touched = self._thread_buffers()
        mask = self._no_mask if weight_mask is None else weight_mask
        return _topk_kernel()(np.asarray(ids, dtype=np.int64), self.data, self.indptr, self.indices, k,
                              scores, touched, mask, weight_mask is not None)

    def warmup(self) -> None:
        """Load (or compile) the numba kernel now (the first call otherwise pays for it)."""
        if len(self.vocab):
            self.search([0], 1)


# --------------------------------------------------------------------------------------------
# tantivy
# --------------------------------------------------------------------------------------------

TOKENIZER = "kb"


def tantivy_schema():
    import tantivy

    sb = tantivy.SchemaBuilder()
    sb.add_text_field("text", stored=False, tokenizer_name=TOKENIZER, index_option="position")
    sb.add_text_field("source", stored=False, tokenizer_name="raw", index_option="basic")
    sb.add_text_field("category", stored=False, tokenizer_name="raw", index_option="basic")
    sb.add_unsigned_field("row", stored=False, indexed=False, fast=True)
    return sb.build()


class TantivyBuilder:
    def __init__(self, path: Path, heap_bytes: int = 256_000_000, threads: int | None = None,
                 reuse: bool = False) -> None:
        """`reuse`: add to the index committed at `path` (a resumed build) instead of a new one."""
        import tantivy

        from kb_service.analysis import build_analyzer

        path.mkdir(parents=True, exist_ok=True)
        self.index = tantivy.Index(tantivy_schema(), path=str(path), reuse=reuse)
        self.index.register_tokenizer(TOKENIZER, build_analyzer())
        threads = threads or max(1, min(2, os.cpu_count() or 1))
        self.writer = self.index.writer(heap_size=heap_bytes, num_threads=threads)
        self._doc = tantivy.Document

    def add(self, row: int, text: str, source: str, category: str) -> None:
        doc = self._doc()
        doc.add_text("text", text)
        doc.add_text("source", source)
        doc.add_text("category", category)
        doc.add_unsigned("row", row)
        self.writer.add_document(doc)

    def close(self) -> None:
        self.writer.commit()
        self.writer.wait_merging_threads()


class TantivySearcher:
    def __init__(self, path: Path) -> None:
        import tantivy

        from kb_service.analysis import build_analyzer

        self.path = Path(path)
        self._t = tantivy
        self.index = tantivy.Index.open(str(self.path))
        self.index.register_tokenizer(TOKENIZER, build_analyzer())
        self.schema = self.index.schema
        self.num_docs = int(self.index.searcher().num_docs)

    def to_query(self, node, source: list[str] | None = None, category: str | None = None):
        """Translate an analysis.Node tree into a tantivy Query (None when nothing can match)."""
        q = self._node(node)
        if q is None:
            return None
        t = self._t
        filters = []
        if source:
            filters.append(t.Query.term_set_query(self.schema, "source", list(source)))
        if category is not None:
            filters.append(t.Query.term_query(self.schema, "category", category))
        if filters:
            clauses = [(t.Occur.Must, q)] + [(t.Occur.Must, t.Query.const_score_query(f, 0.0)) for f in filters]
            q = t.Query.boolean_query(clauses)
        return q

    def _node(self, node):
        t = self._t
        if node.op == "TERM":
            return t.Query.term_query(self.schema, "text", node.tokens[0][1])
        if node.op == "PHRASE":
            return t.Query.phrase_query(self.schema, "text", [(p, w) for p, w in node.tokens])
        if node.op in ("NOT", "MUST"):
            # Only meaningful inside a boolean; on its own, NOT x matches nothing, +x is x.
            return None if node.op == "NOT" else self._node(node.children[0])
        positive, clauses = False, []
        for child in node.children:
            if child.op == "NOT":
                q = self._node(child.children[0])
                if q is not None:
                    clauses.append((t.Occur.MustNot, q))
                continue
            if child.op == "MUST":
                q = self._node(child.children[0])
                occur = t.Occur.Must
            else:
                q = self._node(child)
                occur = t.Occur.Must if node.op == "AND" else t.Occur.Should
            if q is not None:
                clauses.append((occur, q))
                positive = True
        if not positive:
            return None
        return t.Query.boolean_query(clauses)

    def search(self, query, k: int) -> tuple[list[int], list[float]]:
        if query is None or k <= 0:
            return [], []
        searcher = self.index.searcher()
        hits = searcher.search(query, limit=min(k, max(1, self.num_docs)), count=False).hits
        if not hits:
            return [], []
        rows = searcher.fast_field_values("row", [addr for _, addr in hits])
        return [int(r) for r in rows], [float(s) for s, _ in hits]


def write_json(path: Path, obj: dict) -> None:
    write_text_atomic(path, json.dumps(obj, indent=2, ensure_ascii=False, sort_keys=False))
