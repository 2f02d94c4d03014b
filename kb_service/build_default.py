"""`hcgym data build` builder for the default knowledge base (``data_dir()/kb``).

Reads real public medical data out of pinned registry packages (kb_service/sources/) and builds
the KB with `kb_service.ingest.build_kb`. Idempotent: when the built KB's manifest records the
same source packages and generator versions and the KB opens cleanly, nothing is done (well
under a second). `force=True` rebuilds from scratch; an interrupted build resumes.
"""

from __future__ import annotations

import sys
import time

from envs.data.registry import open_package

from kb_service.ingest import build_kb, iterable_input
from kb_service.kb import KBError, KnowledgeBase, default_kb_path
from kb_service.sources import default_sources

MIN_PASSAGES = 100_000


def expected_spec() -> dict:
    return {src.name: src.spec() for src in default_sources()}


def _current(path) -> KnowledgeBase | None:
    try:
        return KnowledgeBase.open(path, warmup=False)
    except KBError:
        return None


def build(offline: bool = False, force: bool = False, echo=print) -> dict:
    out = default_kb_path()
    spec = expected_spec()
    if not force:
        kb = _current(out)
        if kb is not None and kb.manifest.get("default_build") == spec:
            summary = {"status": "up to date", "path": str(out), "passages": kb.n_passages,
                       "sources": kb.manifest.get("sources", {}), "articles": kb.manifest.get("articles", 0)}
            kb.close()
            return summary
        if kb is not None:
            kb.close()
    t0 = time.perf_counter()
    sources = default_sources()
    archives = {}
    for src in sources:
        for pkg in src.packages:
            if pkg.name not in archives:
                archives[pkg.name] = open_package(pkg, offline=offline)
    inputs = [
        iterable_input(f"default:{src.name}", fingerprint=repr(sorted(src.spec().items())),
                       factory=lambda src=src: src.passages(archives))
        for src in sources
    ]

    def articles():
        for src in sources:
            if src.articles is not None:
                yield from src.articles(archives)

    summary = build_kb(inputs, out, article_iter=articles, resume=not force, progress=sys.stderr.isatty(),
                       manifest_extra={"default_build": spec}, echo=echo)
    for arch in archives.values():
        arch.close()
    if summary["n_passages"] < MIN_PASSAGES:
        raise RuntimeError(f"default knowledge base at {out} has only {summary['n_passages']} passages "
                           f"(expected at least {MIN_PASSAGES}); the source packages changed?")
    return {"status": "built", "path": str(out), "passages": summary["n_passages"], "sources": summary["sources"],
            "articles": summary["articles"], "seconds": round(time.perf_counter() - t0, 1)}


if __name__ == "__main__":
    print(build(force="--force" in sys.argv))
