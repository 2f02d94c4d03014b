"""The KB service with a sharded KB's bm25 shards on shard actors, on the session's local Ray
(tests/conftest.py, `ray_cluster`).

The session KB (tests/kb/conftest.py, a seeded corpus of 414 passages) is resharded into 5 shards
of 100 documents and served by 2 shard actors (shards [0, 1, 2] and [3, 4]). Searches through them
must give the single index's and the in-process sharded index's ids, order and float32 scores; a
shard actor killed (SIGKILL) while queries run is restarted by Ray and every query is still
answered so. Placement settings are checked against Ray's scheduler on this one node (a memory
reservation or a custom resource no node has leaves the actor unplaced, with an error naming it).
Spreading over several nodes (Ray's SPREAD strategy and custom resources) is tested on the simulated
multi-node cluster of tests/training/test_placement.py, which starts one for its learner tests anyway.
"""

from __future__ import annotations

import os
import random
import shutil
import signal
import threading
import time

import numpy as np
import pytest

import kb_service  # noqa: F401  (CPU runtime defaults)
from kb_service.analysis import MAX_QUERY_TERMS

ray = pytest.importorskip("ray")
pytestmark = pytest.mark.ray

SHARD_DOCS = 100
SHARDS = {"actors": 2, "memory_gb": 0.05, "start_timeout_s": 60}


@pytest.fixture(scope="module")
def sharded_dir(kb_dir, tmp_path_factory):
    from kb_service.reshard import shard_kb

    copy = tmp_path_factory.mktemp("sharded") / "kb"
    shutil.copytree(kb_dir, copy)
    info = shard_kb(copy, SHARD_DOCS, echo=lambda s: None)
    assert info["shards"] == 5
    return copy


@pytest.fixture(scope="module")
def service(ray_cluster, sharded_dir):
    from kb_service.service import start_kb_service

    client = start_kb_service(replicas=1, path=sharded_dir, name="test-kb-shards", num_cpus=0.25, shards=SHARDS)
    yield client
    client.shutdown()


def queries(kb, n: int, seed: int) -> list[tuple[str, int, object, object]]:
    """Seeded free-text queries over the corpus's own words, with k and filters varied."""
    rng = random.Random(seed)
    words = sorted({w for p in (kb.get(f"f:{i}") for i in range(0, 400, 7)) for w in p.content.rstrip(".").split()}
                   | {"pheochromocytoma", "asthma", "corticosteroid", "warfarin", "zollinger", "ulcer", "failure"})
    out = []
    for i in range(n):
        text = " ".join(rng.choice(words) for _ in range(rng.choice([1, 2, 3, 6])))
        source = [None, "guidelines", ["wiki", "drugs"]][i % 3]
        category = "cardiology" if i % 5 == 0 else None
        out.append((text, rng.choice([1, 3, 10, 50]), source, category))
    return out


def answers(kb_like, qs) -> list[list[tuple[str, float]]]:
    return [[(p.doc_id, p.score) for p in kb_like.search(q, k=k, source=s, category=c)] for q, k, s, c in qs]


def test_shard_actors_answer_as_one_index(service, kb, kb_dir, sharded_dir):
    from kb_service.engines import BM25Searcher
    from kb_service.kb import KnowledgeBase
    from kb_service.shard_actors import RemoteShardedBM25Searcher, ShardFilter, shard_groups
    from kb_service.shards import ShardedBM25Searcher

    infos = ray.get([h.info.remote() for h in service.shard_handles])
    assert [i["shards"] for i in infos] == [[0, 1, 2], [3, 4]]
    assert len({i["pid"] for i in infos} | {os.getpid()}) == 3  # each group in its own process

    # The service's answers: the unsharded KB's and the in-process sharded KB's, scores included.
    sharded_local = KnowledgeBase.open(sharded_dir)
    qs = queries(kb, 60, seed=3)
    want = answers(kb, qs)
    assert sum(bool(a) for a in want) >= 50
    assert answers(service, qs) == want
    assert answers(sharded_local, qs) == want
    assert [p.doc_id for p in service.search('"heart failure"', k=3, source="guidelines")] == ["k:hf"]  # tantivy path

    # The searcher itself, bit for bit: random terms, k up to every document, masks and filters,
    # and queries over MAX_QUERY_TERMS (the df fan-out decides which terms are kept).
    single = BM25Searcher(kb_dir / "bm25")
    local = ShardedBM25Searcher(sharded_dir / "bm25")
    remote = RemoteShardedBM25Searcher(sharded_dir, service.shard_handles, shard_groups(sharded_dir, 2))
    remote.validate()
    vocab = sorted(single.vocab)
    rng = random.Random(7)
    mask = (np.arange(single.num_docs) % 3 != 1).astype(np.float32)
    flt_sources = ("guidelines", "drugs")
    flt = ShardFilter(tuple(sorted(kb._source_index[s] for s in flt_sources)), None)
    flt_mask = kb._mask(list(flt_sources), None)
    nonempty = 0
    for trial in range(80):
        terms = [rng.choice(vocab) for _ in range(rng.choice([1, 2, 4, MAX_QUERY_TERMS + 8]))] + ["unknown-term"]
        k = rng.choice([1, 7, 100, 1000])
        ids = single.term_ids(terms, MAX_QUERY_TERMS)
        kept = local.term_ids(terms, MAX_QUERY_TERMS)
        assert remote.term_ids(terms, MAX_QUERY_TERMS) == (kept if len(terms) > MAX_QUERY_TERMS else terms)
        want_mask, remote_mask = [(None, None), (mask, mask), (flt_mask, flt)][trial % 3]
        d1, s1 = single.search(ids, k, want_mask)
        d2, s2 = local.search(kept, k, want_mask)
        d3, s3 = remote.search(remote.term_ids(terms, MAX_QUERY_TERMS), k, remote_mask)
        assert d1.tolist() == d2.tolist() == d3.tolist()
        assert s3.dtype == np.float32 and s1.tolist() == s2.tolist() == s3.tolist()
        nonempty += len(d1) > 0
    assert nonempty >= 70


def test_killed_shard_actor_is_restarted_and_no_query_is_lost(service, kb):
    victim = service.shard_handles[1]
    before = ray.get(victim.info.remote())
    qs = queries(kb, 25, seed=11)
    want = answers(kb, qs)
    got: list[tuple[int, float, float, list]] = []
    restarted = threading.Event()
    failures: list[BaseException] = []

    def ask():
        i = 0
        try:  # until the restart is seen and a full round of queries has gone through after it
            while not restarted.is_set() or i % len(qs) or i < 2 * len(qs):
                q, k, s, c = qs[i % len(qs)]
                t0 = time.monotonic()
                res = [(p.doc_id, p.score) for p in service.search(q, k=k, source=s, category=c)]
                got.append((i % len(qs), t0, time.monotonic(), res))
                i += 1
        except BaseException as exc:  # noqa: BLE001 - reported by the test below
            failures.append(exc)

    thread = threading.Thread(target=ask, daemon=True)
    thread.start()
    deadline = time.monotonic() + 30
    while len(got) < 5 and thread.is_alive() and time.monotonic() < deadline:
        time.sleep(0.01)
    killed_at = time.monotonic()
    os.kill(before["pid"], signal.SIGKILL)
    after = ray.get(victim.info.remote(), timeout=60)  # answered by the restarted actor
    back_at = time.monotonic()
    restarted.set()
    thread.join(60)
    assert not failures and not thread.is_alive()
    assert after["pid"] != before["pid"] and after["shards"] == before["shards"]
    assert [res for i, _, _, res in got] == [want[i] for i, _, _, _ in got]
    # Some query was waiting on the dead actor: sent before the restart was seen, answered after the kill.
    assert any(t0 < back_at and t1 > killed_at for _, t0, t1, _ in got)


def test_bad_layouts_and_settings_fail_with_clear_errors(ray_cluster, kb_dir, sharded_dir, tmp_path):
    from pydantic import ValidationError

    from kb_service.kb import KBCorruptError, KBError, KBNotBuiltError
    from kb_service.service import ShardActorsConfig, start_kb_service
    from kb_service.shard_actors import ShardLayoutError

    def start(path, **shards):
        return start_kb_service(replicas=1, path=path, name="test-kb-bad", num_cpus=0.25, shards=shards)

    with pytest.raises(ShardLayoutError, match="kb.shards.actors is 6, but .* has 5 bm25 shards"):
        start(sharded_dir, actors=6)
    with pytest.raises(ShardLayoutError, match="single bm25 index.*hcgym kb shard --path"):
        start(kb_dir, actors=2)
    with pytest.raises(KBNotBuiltError, match="hcgym kb build"):
        start(tmp_path / "missing", actors=2)
    broken = tmp_path / "broken"
    shutil.copytree(sharded_dir, broken)
    shutil.rmtree(broken / "bm25" / "shard-00002")
    with pytest.raises(KBCorruptError, match="shard 'shard-00002' .* missing bm25/shard-00002/params.index.json"):
        start(broken, actors=2)
    # A resource no node has, more memory than the node has: the scheduler cannot place the actor
    # (so the settings reach it), and the error names what the actor asked for.
    with pytest.raises(KBError, match="not placed and ready within 1s; it needs .*'no_such_node': 1.0"):
        start(sharded_dir, actors=1, resources={"no_such_node": 1}, start_timeout_s=1)
    with pytest.raises(KBError, match=f"not placed .*'memory': {2**40}"):
        start(sharded_dir, actors=1, memory_gb=1024, start_timeout_s=1)
    assert not [a for a in ray.util.list_named_actors(all_namespaces=True) if a["name"].startswith("test-kb-bad")]

    # 2**20 GiB: Ray keeps resources as fixed-point int64 (1e-4 units), so 2**50 bytes wraps around and such
    # an actor was placed on this 2-CPU node in some runs; the setting is bounded below that.
    for bad in ({"actors": -1}, {"strategy": "PACK"}, {"resources": {"kb_shards": -1}}, {"memory_gb": 0},
                {"memory_gb": 2**20},
                {"max_restarts": -2}, {"shard_actors": 2}):
        with pytest.raises(ValidationError):
            ShardActorsConfig.model_validate(bad)
    # The run config: the same settings under kb.shards, checked against the KB when loaded.
    from learner.config import ConfigError, validate_config

    with pytest.raises(ConfigError, match="kb.shards.actors: needs kb.service: true"):
        validate_config({"kb": {"path": str(sharded_dir), "shards": {"actors": 2}}})
    with pytest.raises(ConfigError, match="kb.shards.actors is 6, but .* has 5 bm25 shards"):
        validate_config({"kb": {"service": True, "path": str(sharded_dir), "shards": {"actors": 6}}})
    cfg = validate_config({"kb": {"service": True, "path": str(sharded_dir), "shards": {"actors": 5, "strategy": "DEFAULT"}}})
    assert cfg.kb.shards.actors == 5 and cfg.kb.shards.ray_options()["scheduling_strategy"] == "DEFAULT"

    options = ShardActorsConfig(actors=2, memory_gb=1.5, resources={"kb_node": 1}).ray_options()
    assert options["memory"] == int(1.5 * 2**30) and options["resources"] == {"kb_node": 1.0}
    assert options["scheduling_strategy"] == "SPREAD" and options["max_task_retries"] == -1
