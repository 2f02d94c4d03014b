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

A sharded KB too large for one node: `start_kb_service(shards={"actors": N, ...})` places its
bm25 shards on N shard actors (`kb_service.shard_actors`) that Ray schedules by the
`ShardActorsConfig` (custom resources, memory, SPREAD); the replicas fan each query out to them
and merge the top k exactly as the in-process sharded index does.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from kb_service.schema import Passage

DEFAULT_NAME = "hcgym-kb"
NAMESPACE = "hcgym"

_ACTOR_CLASS = None


class ShardActorsConfig(BaseModel):
    """Where a sharded KB's bm25 shards live: in every replica (`actors: 0`) or on shard actors."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True)

    actors: int = Field(default=0, ge=0, description=(
        "shard actors holding a sharded KB's bm25 shards, each a contiguous group of them (at most the number "
        "of shards); the replicas send every free-text query to all of them and merge the top k exactly; "
        "0 = every replica opens all shards itself"))
    num_cpus: float = Field(default=0.0, ge=0, description="CPUs Ray reserves per shard actor")
    # At most 64 TiB: Ray counts resources in fixed-point int64 (1e-4 units), so past ~850 TiB a reservation
    # wraps around and an actor is placed where it does not fit.
    memory_gb: float | None = Field(default=None, gt=0, le=65536, description=(
        "memory Ray reserves per shard actor (GiB, at most 65536; its shards' matrices and vocabularies), so a "
        "node only gets the shard actors whose reservations fit; null = no reservation"))
    resources: dict[str, float] = Field(default_factory=dict, description=(
        "custom resources per shard actor, e.g. {kb_node: 1} with the nodes meant for shards started as "
        "`ray start --resources='{\"kb_node\": 1}'` (one shard actor per such node)"))
    strategy: Literal["SPREAD", "DEFAULT"] = Field(default="SPREAD", description=(
        "Ray scheduling strategy of the shard actors: SPREAD puts them on different nodes while nodes last, "
        "DEFAULT packs them where resources are"))
    max_restarts: int = Field(default=-1, ge=-1, description=(
        "Ray restarts of a shard actor that died (the searches waiting on it are sent again once it is back); "
        "-1 = unlimited"))
    start_timeout_s: float = Field(default=300.0, gt=0, description=(
        "wait for the shard actors to be placed and open their shards (also the longest a search waits for a "
        "restarted one)"))

    @field_validator("resources")
    @classmethod
    def _positive(cls, value: dict[str, float]) -> dict[str, float]:
        for key, amount in value.items():
            if not key or not math.isfinite(amount) or amount <= 0:
                raise ValueError(f"resource {key!r} must be a named positive finite amount, got {amount!r}")
        return value

    def ray_options(self) -> dict:
        """The shard actor's `.options(...)` for Ray (without its name)."""
        options: dict[str, Any] = {"num_cpus": self.num_cpus, "scheduling_strategy": self.strategy,
                                   "max_restarts": self.max_restarts, "max_task_retries": -1}
        if self.resources:
            options["resources"] = dict(self.resources)
        if self.memory_gb is not None:
            options["memory"] = int(self.memory_gb * 2**30)
        return options


def _actor_class():
    global _ACTOR_CLASS
    if _ACTOR_CLASS is None:
        import ray

        @ray.remote
        class KBActor:
            """One replica: an opened KnowledgeBase serving search/get/stats/article."""

            def __init__(self, path: str | None, shards: tuple | None = None) -> None:
                """`shards`: (shard actor handles, their `ShardGroup`s, timeout) when the bm25 shards
                live on shard actors; None = open the whole KB here."""
                from kb_service.kb import KnowledgeBase

                if shards is None:
                    self.kb = KnowledgeBase.open(path)
                else:
                    from kb_service.shard_actors import RemoteShardedBM25Searcher, ShardServiceKB

                    handles, groups, timeout_s = shards
                    bm25 = RemoteShardedBM25Searcher(path, handles, groups, timeout_s)
                    self.kb = ShardServiceKB.open(path, bm25=bm25)

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

    def __init__(self, handles: list, name: str = DEFAULT_NAME, timeout_s: float = 30.0,
                 shard_handles: list | None = None) -> None:
        if not handles:
            raise ValueError("a KB service needs at least one replica")
        self.handles = list(handles)
        self.name = name
        self.timeout_s = timeout_s
        self.shard_handles = list(shard_handles or [])  # the shard actors, if any (for shutdown)
        self._rr = itertools.count()

    def __reduce__(self):  # itertools.count does not pickle; a fresh counter is fine
        return (KBServiceClient, (self.handles, self.name, self.timeout_s, self.shard_handles))

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

        for h in [*self.handles, *self.shard_handles]:
            ray.kill(h)


def start_kb_service(replicas: int = 2, path: str | Path | None = None, name: str = DEFAULT_NAME,
                     num_cpus: float = 0.5, timeout_s: float = 120.0,
                     shards: ShardActorsConfig | dict | None = None) -> KBServiceClient:
    """Start `replicas` named KBActor replicas over the KB at `path` and wait until all are ready.

    `shards` (a `ShardActorsConfig` or its dict) with `actors` > 0 first starts that many shard
    actors (`{name}-shard-0`, ...) over the KB's bm25 shards; the replicas then search through them.

    Raises the KB's own error (missing/corrupt, with the build command) if a replica cannot open it;
    `shard_actors.ShardLayoutError` for more shard actors than shards or an unsharded KB,
    `KBCorruptError` naming a missing shard, `KBError` when a shard actor cannot be placed in time.
    """
    import ray

    from kb_service.kb import KnowledgeBase, default_kb_path

    path = str(Path(path) if path is not None else default_kb_path())
    shards = ShardActorsConfig.model_validate(shards if shards is not None else {})
    shard_handles, shard_arg = [], None
    if shards.actors == 0:
        KnowledgeBase.open(path, warmup=False).close()  # fail here, with the clear message, not inside Ray
    else:
        from kb_service.shard_actors import shard_actor_class, shard_groups

        groups = shard_groups(path, shards.actors)  # layout errors before anything starts
        shard_handles = [shard_actor_class().options(name=f"{name}-shard-{g.index}", namespace=NAMESPACE, lifetime=None,
                                                     **shards.ray_options()).remote(path, g) for g in groups]
        shard_arg = (shard_handles, groups, shards.start_timeout_s)
    cls = _actor_class()
    handles = []
    try:
        # The replicas start while the shard actors open their shards (they wait for them).
        handles = [
            cls.options(name=f"{name}-{i}", namespace=NAMESPACE, num_cpus=num_cpus, lifetime=None)
            .remote(path, shard_arg)
            for i in range(replicas)
        ]
        if shard_handles:
            _check_shard_actors(path, name, shards, shard_arg[1], shard_handles)
        ray.get([h.ping.remote() for h in handles], timeout=timeout_s)
    except BaseException:
        for h in [*handles, *shard_handles]:
            ray.kill(h)
        raise
    return KBServiceClient(handles, name, shard_handles=shard_handles)


def _check_shard_actors(path: str, name: str, cfg: ShardActorsConfig, groups: list, handles: list) -> None:
    """Wait for the shard actors; errors name the actor, its shards and what it asked Ray for."""
    import ray
    from ray.exceptions import GetTimeoutError, RayActorError

    from kb_service.kb import KBError, KnowledgeBase
    from kb_service.shard_actors import RemoteShardedBM25Searcher

    for g, h in zip(groups, handles):
        try:
            ray.get(h.info.remote(), timeout=cfg.start_timeout_s)
        except GetTimeoutError:
            raise KBError(f"KB shard actor {name}-shard-{g.index} (shards {list(g.shards)}) was not placed and "
                          f"ready within {cfg.start_timeout_s:.0f}s; it needs {cfg.ray_options()} and the "
                          f"cluster has {ray.available_resources()} available") from None
        except RayActorError as exc:
            cause = getattr(exc, "error_msg", None) or str(exc)
            raise KBError(f"KB shard actor {name}-shard-{g.index} could not open shards {list(g.shards)} of "
                          f"{path}: {cause}") from None
    # The rest of the KB (passages, tantivy, docmeta) checked here, with the shard actors' index.
    bm25 = RemoteShardedBM25Searcher(path, handles, groups, cfg.start_timeout_s)
    KnowledgeBase.open(path, warmup=False, bm25=bm25).close()


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
    shard_handles = []
    for i in itertools.count():
        try:
            shard_handles.append(ray.get_actor(f"{name}-shard-{i}", namespace=NAMESPACE))
        except ValueError:
            break
    return KBServiceClient(handles, name, shard_handles=shard_handles)
