"""Ray KB service: replicas over one read-only index, used by env actors and tools."""

from __future__ import annotations

import pytest

import kb_service  # noqa: F401  (CPU runtime defaults)
from envs._runtime import init_ray

ray = pytest.importorskip("ray")
pytestmark = pytest.mark.ray


@pytest.fixture(scope="module")
def cluster():
    started = not ray.is_initialized()  # reuse a session cluster if another conftest started one
    if started:
        # "local": never attach to a head another test or user left running (it rejects num_cpus);
        # on loopback, with Ray's default auth (token) unless RAY_AUTH_MODE says otherwise
        init_ray("local", num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    if started:
        ray.shutdown()


def test_service_end_to_end(cluster, kb_dir, kb, tmp_path):
    from kb_service.kb import KBNotBuiltError, UnknownDocError
    from kb_service.service import connect, start_kb_service
    from kb_service.tools import KnowledgeTools

    with pytest.raises(KBNotBuiltError, match="hcgym kb build"):
        start_kb_service(replicas=1, path=tmp_path / "missing", name="missing-kb")

    client = start_kb_service(replicas=2, path=kb_dir, name="test-kb", num_cpus=0.25)
    try:
        local = [p.doc_id for p in kb.search("asthma corticosteroid", k=5)]
        for _ in range(4):  # both replicas answer identically
            assert [p.doc_id for p in client.search("asthma corticosteroid", k=5)] == local
        assert [p.doc_id for p in client.search('"heart failure"', k=3, source="guidelines")] == ["k:hf"]
        assert client.search("", k=5) == []
        assert client.get("k:warfarin").content.startswith("Warfarin")
        with pytest.raises(UnknownDocError):
            client.get("nope")
        assert client.article("Heart failure").title == "Heart failure"

        # env actors find the service by name and use it through the tools
        @ray.remote(num_cpus=0.25)
        def env_actor_search(name: str) -> list[str]:
            from kb_service.service import connect as c
            from kb_service.tools import KnowledgeTools as T

            out = T(c(name)).call("search", {"query": "pheochromocytoma", "k": 2})
            return [r["doc_id"] for r in out.result["results"]]

        assert ray.get(env_actor_search.remote("test-kb")) == ["k:pheo3", "k:pheo1"]
        again = connect("test-kb")
        assert len(again.handles) == 2
        tools = KnowledgeTools(again)
        assert tools.call("get_passage", {"doc_id": "nope"}).error
        assert ray.get(ray.remote(lambda c: len(c.search("asthma", k=2))).remote(client)) == 2  # picklable
    finally:
        client.shutdown()
    with pytest.raises(RuntimeError, match="no knowledge-base service"):
        connect("never-started")


def test_service_serves_a_sharded_kb(cluster, kb_dir, kb, tmp_path):
    """A replica opens a sharded KB like any other (all shards in one actor) and answers exactly
    as the single-index KB in process."""
    import shutil

    from kb_service.service import start_kb_service
    from kb_service.reshard import shard_kb

    copy = tmp_path / "kb"
    shutil.copytree(kb_dir, copy)
    shard_kb(copy, 100, echo=lambda s: None)
    client = start_kb_service(replicas=1, path=copy, name="test-kb-sharded", num_cpus=0.25)
    try:
        for query in ("asthma corticosteroid", "pheochromocytoma headache", "fever rash"):
            got = [(p.doc_id, p.score) for p in client.search(query, k=10, source=["guidelines", "wiki"])]
            want = [(p.doc_id, p.score) for p in kb.search(query, k=10, source=["guidelines", "wiki"])]
            assert got == want and got
    finally:
        client.shutdown()
