"""A KB built within a memory budget: sharded, resumable after a kill, and ranking exactly as the
index built in memory.

One seeded corpus is built twice in subprocesses (so that each build's peak RSS is its own,
read with wait4): once in memory (the single bm25 matrix) and once with
``memory_budget_mb`` (the budget below), the latter killed with SIGKILL at three commit points (a bm25
shard, a weighted shard, a tantivy commit: `kb_service.shards.kill_point`) and resumed each time;
and once more with 2 bm25 worker processes (`kb_service.parallel_build`) under a budget that
holds them, killed after its second unit's shard and resumed.
"""

from __future__ import annotations

import json
import os
import random
import re
import sqlite3
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from kb_service.shards import KILL_ENV

ROOT = Path(__file__).resolve().parents[2]
# The budget: 190 MB, or more where the build process alone already holds more (its interpreter and
# libraries differ between environments: 134 MB at the start of a build in a venv freshly built by uv),
# so that the working memory the budget leaves stays what this corpus was sized for.
BUDGET_FLOOR_MB = 190
WORKING_MB = 66
PROBE = """
import sys
sys.path.insert(0, sys.argv[1])
import tantivy
from bm25s.scoring import _select_idf_scorer
from kb_service.ingest import build_kb, file_input
from kb_service.shards import process_rss_bytes, release_memory
release_memory()
print(process_rss_bytes() >> 20)
"""


def _budget_mb() -> int:
    held = subprocess.run([sys.executable, "-c", PROBE, str(ROOT)], capture_output=True, text=True, timeout=120,
                          check=True)
    return max(BUDGET_FLOOR_MB, int(held.stdout.split()[-1]) + WORKING_MB)
N_DOCS = 8_000
SHARD_DOCS = 1_700

BUILD = """
import json, sys
sys.path.insert(0, sys.argv[1])
from kb_service.ingest import build_kb, file_input
budget = None if sys.argv[4] == "-" else int(sys.argv[4])
shard_docs = None if sys.argv[5] == "-" else int(sys.argv[5])
workers = int(sys.argv[6])
summary = build_kb([file_input(sys.argv[2])], sys.argv[3], progress=False, memory_budget_mb=budget,
                   shard_docs=shard_docs, echo=print, workers=workers)
print(json.dumps(summary))
"""


def _write_corpus(path: Path, seed: int = 7) -> list[str]:
    """Passages of 75-225 words drawn from a Zipf vocabulary of 40,000 words, plus one rare token
    each; 3 sources, 6 categories. Returns the vocabulary (for queries)."""
    rng = np.random.default_rng(seed)
    vocab = np.array([f"w{i:x}q" for i in range(40_000)], dtype=object)
    weights = 1.0 / (np.arange(len(vocab)) + 2.7)
    cdf = np.cumsum(weights / weights.sum())
    with open(path, "w", encoding="utf-8") as fh:
        for i in range(N_DOCS):
            words = vocab[np.searchsorted(cdf, rng.random(int(rng.integers(75, 226))))].tolist()
            fh.write(json.dumps({"doc_id": f"p{i}", "source": ("pubmed", "statpearls", "textbooks")[i % 3],
                                 "title": f"{words[0]} {words[-1]}", "content": " ".join(words) + f" r{i}z",
                                 "category": f"c{i % 6}", "dataset_name": "synthetic"}) + "\n")
    return vocab.tolist()


# Linux counts in a child's ru_maxrss the peak of the memory it was started from (exec records
# the old address space's high-water mark), which here is the whole test process. So each build
# is started by a small launcher and measured by it: the build's peak starts from the launcher's.
LAUNCH = """
import json, os, subprocess, sys
proc = subprocess.Popen(sys.argv[1:])
_pid, status, usage = os.wait4(proc.pid, 0)
print(json.dumps({"rc": os.waitstatus_to_exitcode(status), "peak_mb": usage.ru_maxrss / 1024}))
"""


def _start(corpus: Path, out: Path, budget: int | None, shard_docs: int | None,
           kill_at: str | None = None, workers: int = 1) -> subprocess.Popen:
    env = {k: v for k, v in os.environ.items() if k != KILL_ENV}
    if kill_at:
        env[KILL_ENV] = kill_at
    return subprocess.Popen([sys.executable, "-c", LAUNCH, sys.executable, "-c", BUILD, str(ROOT), str(corpus),
                             str(out), "-" if budget is None else str(budget),
                             "-" if shard_docs is None else str(shard_docs), str(workers)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env, text=True)


def _finish(proc: subprocess.Popen) -> tuple[int, float, str]:
    """(exit code, peak RSS in MB, output) of a build process, as its launcher measured it (wait4)."""
    output, _ = proc.communicate()
    assert proc.returncode == 0, output
    head, _, last = output.rstrip("\n").rpartition("\n")
    measured = json.loads(last)
    return measured["rc"], measured["peak_mb"], head


@pytest.fixture(scope="module")
def builds(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("bounded")
    corpus = tmp / "corpus.jsonl"
    vocab = _write_corpus(corpus)
    budget = _budget_mb()
    in_memory = _start(corpus, tmp / "memory", None, None)  # alongside the bounded builds (2 cores)
    runs = {}
    raw_left = {}
    for kill_at in ("bm25-shard:1", "bm25-final:2", "tantivy:3", None):
        runs[kill_at or "done"] = _finish(_start(corpus, tmp / "bounded", budget, SHARD_DOCS, kill_at))
        raw_left[kill_at or "done"] = sorted(p.name for p in (tmp / "bounded.building" / "bm25.raw").glob("shard-*"))
    runs["memory"] = _finish(in_memory)
    # 2 workers: the build process keeps what it holds, each worker gets half of the rest, its own
    # interpreter included (about what the build process holds); three times the budget leaves each
    # worker at least the working memory the single-process builds above had.
    budget2 = 3 * budget
    for kill_at in ("bm25-shard:1", None):
        runs["w2-" + (kill_at or "done")] = _finish(_start(corpus, tmp / "bounded2", budget2, SHARD_DOCS, kill_at,
                                                           workers=2))
    return {"tmp": tmp, "vocab": vocab, "runs": runs, "budget": budget, "budget2": budget2, "raw_left": raw_left}


def test_killed_build_resumes_at_its_last_commit_under_the_budget(builds):
    runs = builds["runs"]
    rc, peak_memory, out = runs["memory"]
    assert rc == 0, out
    # The corpus is one the in-memory build cannot build within the budget...
    assert peak_memory > builds["budget"], (peak_memory, builds["budget"], out)
    for kill_at in ("bm25-shard:1", "bm25-final:2", "tantivy:3"):
        rc, _peak, out = runs[kill_at]
        assert rc == -9, f"the build was to be killed at {kill_at}; exit {rc}:\n{out}"
    assert runs["done"][0] == 0, runs["done"][2]
    # ... and every process of the bounded build, the killed ones included, stayed within it.
    peaks = {k: round(v[1]) for k, v in runs.items() if k != "memory" and not k.startswith("w2-")}
    assert max(peaks.values()) < builds["budget"], (peaks, builds["budget"])
    # Each resumed at the commit its predecessor was killed after, and did not redo it.
    first = runs["bm25-shard:1"][2]
    assert "bm25 shard 1: passages 1,701-3,400 committed" in first and "bm25 shard 2" not in first
    # A shard's raw postings go once its weights are committed: killed after weighing shards 0-2,
    # the build held the raw files of shards 3 and 4 only (and the resumed run did not need them).
    assert builds["raw_left"]["bm25-shard:1"] == ["shard-00000", "shard-00001"]
    assert builds["raw_left"]["bm25-final:2"] == ["shard-00003", "shard-00004"]
    second = runs["bm25-final:2"][2]
    assert "bm25: resuming after 2 committed shard(s) (3,400 of 8,000 passages indexed)" in second
    assert "bm25 shard 1:" not in second and "bm25 shard 2: passages 3,401-5,100 committed" in second
    third = runs["tantivy:3"][2]
    assert "bm25 shard 0 weighted" not in third and "bm25 shard 2 weighted" not in third
    assert "bm25 shard 3 weighted" in third and "tantivy: passages 1-3,000 committed" in third
    last = runs["done"][2]
    assert "tantivy: resuming after 3,000 committed passages" in last and not re.search(r"bm25 shard \d", last)
    summary = json.loads(last.strip().splitlines()[-1])
    assert summary["n_passages"] == N_DOCS
    assert summary["bm25_shards"] == {"shard_docs": SHARD_DOCS, "shards": 5, "memory_budget_mb": builds["budget"]}


def test_parallel_build_resumes_its_units_under_the_budget(builds):
    runs = builds["runs"]
    rc, _peak, killed = runs["w2-bm25-shard:1"]
    assert rc == -9, f"the 2-worker build was to be killed after its second shard; exit {rc}:\n{killed}"
    assert "2 workers (bm25 units, the tantivy pass) with" in killed
    assert "5 unit(s) of passages and the tantivy pass on 2 worker process(es)" in killed
    first = set(re.findall(r"bm25 unit (\d) shard-00000: passages [\d,-]+ committed", killed))
    assert len(first) >= 2, killed
    rc, _peak, last = runs["w2-done"]
    assert rc == 0, last
    # Units committed before the kill are not rebuilt: each says where it resumes; the others commit now.
    resumed = set(re.findall(r"bm25 unit-0000(\d): resuming after 1 committed shard", last))
    built = set(re.findall(r"bm25 unit (\d) shard-00000: passages [\d,-]+ committed", last))
    assert resumed >= first and not resumed & built and resumed | built == set("01234"), last
    summary = json.loads(last.strip().splitlines()[-1])
    shards = summary["bm25_shards"]
    assert shards["workers"] == 2 and shards["shards"] == 5, shards
    # The build process and both workers together stayed within the budget (each process's own
    # peak, VmHWM, reported by the build; their sum bounds what they held at any one time).
    peak = shards["peak_rss_mb"]
    assert peak["main"] + sum(peak["workers"]) < builds["budget2"], (peak, builds["budget2"])
    assert len(peak["workers"]) == 2 and min(peak["workers"]) > 50, peak


def test_bounded_kb_ranks_exactly_as_the_in_memory_index(builds):
    from kb_service.kb import KnowledgeBase

    tmp = builds["tmp"]
    single = KnowledgeBase.open(tmp / "memory")
    for name in ("bounded", "bounded2"):  # one process; 2 worker processes
        _assert_same_kb(single, KnowledgeBase.open(tmp / name), tmp / name, builds["vocab"])


def _assert_same_kb(single, bounded, path: Path, vocab: list[str]) -> None:
    from kb_service.shards import ShardedBM25Searcher

    assert isinstance(bounded.bm25, ShardedBM25Searcher) and len(bounded.bm25.shards) == 5
    assert not path.with_name(path.name + ".building").exists()
    # Every passage once: in the store, in the bm25 shards and in tantivy (no duplicates from the resumes).
    with sqlite3.connect(f"file:{path / 'passages.sqlite'}?mode=ro", uri=True) as db:
        assert db.execute("SELECT count(*), count(DISTINCT doc_id) FROM passages").fetchone() == (N_DOCS, N_DOCS)
    assert bounded.bm25.num_docs == N_DOCS and bounded.tantivy.num_docs == N_DOCS
    assert bounded.bm25.meta["vocab"] == len(single.bm25.vocab)
    assert bounded.sources == single.sources and bounded.categories == single.categories
    assert (bounded._source_ids == single._source_ids).all()
    assert (bounded._category_ids == single._category_ids).all()

    rng = random.Random(3)
    hits = 0
    for trial in range(150):
        words = rng.sample(vocab[:200], rng.randint(0, 2)) + rng.sample(vocab, rng.randint(1, 5))
        if trial % 4 == 0:
            words.append(f"r{rng.randrange(N_DOCS)}z")  # a passage's own rare token
        query = " ".join(words)
        flt = [{}, {"source": "pubmed"}, {"category": "c2"}][trial % 3]
        a, b = single.rank(query, k=10, **flt), bounded.rank(query, k=10, **flt)
        assert [d for d, _ in a] == [d for d, _ in b], query
        assert np.array([s for _, s in a], np.float32).tobytes() == np.array([s for _, s in b], np.float32).tobytes()
        hits += len(a)
        if trial % 10 == 0:  # the tantivy index, resumed after a kill: query syntax ranks alike
            q = f'"{words[-1]}" OR {words[0]}'
            ta, tb = single.search(q, k=20), bounded.search(q, k=20)
            assert [p.score for p in ta] == [p.score for p in tb], q
            # Equal scores come in segment order, which the commits change: compare them as sets,
            # except the lowest score's group, which the cut at k may split differently.
            for score in {p.score for p in ta} - {ta[-1].score}:
                assert {p.doc_id for p in ta if p.score == score} == {p.doc_id for p in tb if p.score == score}, q
    assert hits > 1000


def test_budget_below_what_the_process_holds_is_refused(tmp_path, capsys):
    import argparse

    from kb_service.cli import register
    from kb_service.ingest import build_kb, file_input

    corpus = tmp_path / "c.jsonl"
    corpus.write_text(json.dumps({"doc_id": "a", "source": "s", "content": "aspirin"}) + "\n")
    with pytest.raises(ValueError, match=r"memory_budget_mb=20 is too small: this build process already holds \d+ MB"):
        build_kb([file_input(corpus)], tmp_path / "kb", progress=False, memory_budget_mb=20, echo=lambda s: None)
    assert not (tmp_path / "kb.building").exists()  # refused before ingesting
    with pytest.raises(ValueError, match="memory_budget_mb must be a positive integer"):
        build_kb([file_input(corpus)], tmp_path / "kb", memory_budget_mb=0)
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    args = parser.parse_args(["kb", "build", str(corpus), "--out", str(tmp_path / "kb"), "--memory-budget-mb", "20"])
    assert args.func(args) == 2
    assert "--memory-budget-mb: memory_budget_mb=20 is too small" in capsys.readouterr().err
    # Workers share the budget: each needs about what this process holds, so a budget just above what one
    # process needs cannot hold 2 (derived from what this process holds: in the full suite that is ~1.9 GB).
    from kb_service.ingest import INDEX_HEADROOM_BYTES, MIN_WORKING_BYTES
    from kb_service.shards import process_rss_bytes, release_memory

    release_memory()
    one = (-(-(process_rss_bytes() + INDEX_HEADROOM_BYTES + MIN_WORKING_BYTES) >> 20)) + 32
    with pytest.raises(ValueError, match=rf"memory_budget_mb={one} is too small for workers=2: each bm25 worker gets "
                                         r"an equal share .* give at least \d+ MB, or workers=1"):
        build_kb([file_input(corpus)], tmp_path / "kb", progress=False, memory_budget_mb=one, workers=2)
    args = parser.parse_args(["kb", "build", str(corpus), "--out", str(tmp_path / "kb"), "--memory-budget-mb", str(one),
                              "--workers", "2"])
    assert args.func(args) == 2
    assert f"--memory-budget-mb / --workers: memory_budget_mb={one} is too small for workers=2" in capsys.readouterr().err
    with pytest.raises(ValueError, match="workers=2 applies to the sharded build"):
        build_kb([file_input(corpus)], tmp_path / "kb", workers=2)
    assert not (tmp_path / "kb.building").exists()
    # `hcgym kb shard` takes the same budget, refused the same way (before it reads the KB).
    args = parser.parse_args(["kb", "shard", "--path", str(tmp_path / "kb"), "--shard-docs", "10",
                              "--memory-budget-mb", "20"])
    assert args.func(args) == 2
    assert "hcgym kb shard: --memory-budget-mb: memory_budget_mb=20 is too small" in capsys.readouterr().err
