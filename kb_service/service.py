"""Ray service: `KBActor` replicas answering knowledge-base calls for env actors.

Every replica opens the same on-disk KB read-only (SQLite immutable, bm25s memory-mapped,
tantivy mmap), so N replicas on a node share one copy of the index in the page cache; a replica
costs its Python process plus the bm25s vocabulary (~100 MB at 828K passages).

    client = start_kb_service(replicas=2)            # after ray.init(); fails loudly if no KB
    KnowledgeTools(client)                           # or: os.environ["HCGYM_KB_SERVICE"] = "hcgym-kb"
    client = connect("hcgym-kb")                     # from any actor/driver of the same cluster

The client is picklable (it holds actor handles), so it can be passed to env actors; it has the
`KnowledgeBase` methods (`search`, `get`, `stats`, `article`) and spreads calls over replicas
round-robin. Without a service, tools use the in-process KB (`kb_service.kb.open_shared`).
"""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any

from kb_service.schema import Passage

DEFAULT_NAME = "hcgym-kb"
NAMESPACE = "hcgym"

_ACTOR_CLASS = None


def _actor_class():
    global _ACTOR_CLASS
    if _ACTOR_CLASS is None:
        import ray

        @ray.remote
        class KBActor:
            """One replica: an opened KnowledgeBase serving search/get/stats/article."""

            def __init__(self, path: str | None) -> None:
                from kb_service.kb import KnowledgeBase

                self.kb = KnowledgeBase.open(path)

            def ping(self) -> dict:
                return {"path": str(self.kb.path), "n_passages": self.kb.n_passages}

            def search(self, query: Any, k: int = 10, source: Any = None, category: Any = None) -> list[dict]:
                return [p.model_dump() for p in self.kb.search(query, k=k, source=source, category=category)]

            def get(self, doc_id: str) -> dict | None:
                from kb_service.kb import UnknownDocError

                try:
                    return self.kb.get(doc_id).model_dump()
                except UnknownDocError:
                    return None

            def stats(self) -> dict:
                return self.kb.stats()

            def article(self, title: str) -> dict | str:
                from kb_service.kb import ArticleNotFoundError

                try:
                    art = self.kb.article(title)
                except ArticleNotFoundError as exc:
                    return str(exc)
                return {"title": art.title, "url": art.url, "text": art.text}

        _ACTOR_CLASS = KBActor
    return _ACTOR_CLASS


class KBServiceClient:
    """`KnowledgeBase`-like facade over KBActor replicas (round-robin)."""

    def __init__(self, handles: list, name: str = DEFAULT_NAME, timeout_s: float = 30.0) -> None:
        if not handles:
            raise ValueError("a KB service needs at least one replica")
        self.handles = list(handles)
        self.name = name
        self.timeout_s = timeout_s
        self._rr = itertools.count()

    def __reduce__(self):  # itertools.count does not pickle; a fresh counter is fine
        return (KBServiceClient, (self.handles, self.name, self.timeout_s))

    def _next(self):
        return self.handles[next(self._rr) % len(self.handles)]

    def _call(self, method: str, *args, **kwargs):
        import ray

        return ray.get(getattr(self._next(), method).remote(*args, **kwargs), timeout=self.timeout_s)

    def search(self, query: Any, k: int = 10, source: Any = None, category: Any = None) -> list[Passage]:
        return [Passage(**d) for d in self._call("search", query, k, source, category)]

    def get(self, doc_id: str) -> Passage:
        from kb_service.kb import UnknownDocError

        d = self._call("get", doc_id)
        if d is None:
            raise UnknownDocError(f"no passage with doc_id {str(doc_id)[:200]!r} in the knowledge base")
        return Passage(**d)

    def stats(self) -> dict:
        return self._call("stats")

    def article(self, title: str):
        from kb_service.kb import ArticleNotFoundError
        from kb_service.pages import Article

        d = self._call("article", title)
        if isinstance(d, str):
            raise ArticleNotFoundError(d)
        return Article(**d)

    def shutdown(self) -> None:
        import ray

        for h in self.handles:
            ray.kill(h)


def start_kb_service(replicas: int = 2, path: str | Path | None = None, name: str = DEFAULT_NAME,
                     num_cpus: float = 0.5, timeout_s: float = 120.0) -> KBServiceClient:
    """Start `replicas` named KBActor replicas over the KB at `path` and wait until all are ready.

    Raises the KB's own error (missing/corrupt, with the build command) if a replica cannot open it.
    """
    import ray

    from kb_service.kb import KnowledgeBase, default_kb_path

    path = str(Path(path) if path is not None else default_kb_path())
    KnowledgeBase.open(path, warmup=False).close()  # fail here, with the clear message, not inside Ray
    cls = _actor_class()
    handles = [
        cls.options(name=f"{name}-{i}", namespace=NAMESPACE, num_cpus=num_cpus, lifetime=None).remote(path)
        for i in range(replicas)
    ]
    ray.get([h.ping.remote() for h in handles], timeout=timeout_s)
    return KBServiceClient(handles, name)


def connect(name: str = DEFAULT_NAME, max_replicas: int = 64) -> KBServiceClient:
    """A client for the replicas `start_kb_service(name=...)` started in this Ray cluster."""
    import ray

    handles = []
    for i in range(max_replicas):
        try:
            handles.append(ray.get_actor(f"{name}-{i}", namespace=NAMESPACE))
        except ValueError:
            break
    if not handles:
        raise RuntimeError(f"no knowledge-base service named {name!r} is running in this Ray cluster; "
                           f"start one with kb_service.service.start_kb_service(name={name!r})")
    return KBServiceClient(handles, name)
