"""Fixtures of the viewer tests: real run and evaluation folders, a served viewer, and Debian's
headless Chromium driven through ChromeDriver (no browser download at install time).

* `trained_run`: `learner.train.train` on the ward test domain with the tiny policy, TT-OPD, 3
  steps and a validation pass: the files `hcgym train` writes, teacher hints and log-probs included
  (the session fixture `ttopd_store_run` of tests/conftest.py, shared with the training tests).
* `gold_run`: gold-replay episodes (the real env executes the gold tool calls) written with the
  trainer's own `write_samples` / metrics format, so episode pages have tool calls to show (the
  tiny random policy rarely calls a tool).
* `eval_dirs`: two evaluations of the ward suite (scripted gold and random) written by `run_eval`.
"""

from __future__ import annotations

import asyncio
import json
import os
import shutil
from pathlib import Path

import pytest

from tests.evals.conftest import WARD
from tests.training.conftest import NO_EMBEDDINGS

CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"
#: Screenshots of every page land here (a CI artefact folder; not committed).
ARTIFACTS = Path(os.environ.get("HCGYM_TEST_ARTIFACTS", "build/test-artifacts")) / "viewer"


@pytest.fixture(scope="package")
def ward_registered():
    from actors.env_actor import register_domains

    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("HCGYM_EMBEDDINGS", "0")
        register_domains(WARD)
        yield


@pytest.fixture(scope="package")
def trained_run(ttopd_store_run):
    """The session's 3-step TT-OPD run (tests/conftest.py), which tests/training/test_train.py also checks."""
    return ttopd_store_run


@pytest.fixture(scope="package")
def gold_run(tmp_path_factory, ward_policy_dir, ward_registered):
    from actors.agent_loop import (
        AgentLoop,
        EpisodeSpec,
        GoldReplayPolicy,
        LocalEnv,
        RolloutLimits,
        gold_turn_actions,
    )
    from envs import registry
    from learner.metrics import rollout_metrics, write_samples
    from modeling.model import load_tokenizer

    run_dir = tmp_path_factory.mktemp("viewer") / "gold-run"
    tokenizer = load_tokenizer(ward_policy_dir)
    limits = RolloutLimits(max_turns=4, max_new_tokens_per_turn=400, max_response_tokens=3000)
    tasks = registry.get_tasks("ward", None)
    policy = GoldReplayPolicy(tokenizer, {t.id: gold_turn_actions(t, limits.max_turns) for t in tasks})
    loop = AgentLoop(tokenizer, limits)

    async def episodes():
        return [await loop.run(EpisodeSpec(sample_id=f"{t.id}:0:1", task_id=t.id, domain="ward", group_id=f"g:{t.id}",
                                           seed=1), LocalEnv(limits.max_turns), policy) for t in tasks]

    samples = asyncio.run(episodes())
    write_samples(samples, run_dir / "trajectories" / "step_000001.parquet", step=1)
    (run_dir / "metrics.jsonl").write_text(
        json.dumps({"step": 1, **rollout_metrics(samples, limits.max_response_tokens)}) + "\n", encoding="utf-8")
    return run_dir


@pytest.fixture(scope="package")
def eval_dirs(tmp_path_factory, ward_registered):
    from evals.conditions import ConditionSettings
    from evals.policies import ScriptedPolicy
    from evals.runner import EvalOptions, run_eval
    from evals.types import EvalItem

    root = tmp_path_factory.mktemp("viewer-evals")
    items = [EvalItem(benchmark="ward", domain="ward", task_id=t) for t in ("ward_choice", "ward_dose", "ward_record")]
    options = EvalOptions(condition="agent", seeds=(0, 1, 2), use_ray=False, progress=False, domain_modules=WARD,
                          settings=ConditionSettings(max_turns=3), flush_every_s=0.0, env_vars=NO_EMBEDDINGS)
    out = []
    for kind in ("gold", "random"):
        run_eval(ScriptedPolicy(kind), items, root / kind, options, suite="ward")
        out.append(root / kind)
    return out


@pytest.fixture(scope="package")
def served(trained_run, gold_run, eval_dirs):
    from viewer.data import discover
    from viewer.server import ViewerServer

    server = ViewerServer(discover([trained_run, gold_run, *eval_dirs])).start()
    yield server
    server.stop()


@pytest.fixture(scope="package")
def browser(tmp_path_factory):
    """Headless Chromium from Debian's packages (`make test` installs chromium and chromium-driver)."""
    if not (shutil.which(CHROMIUM) and shutil.which(CHROMEDRIVER)):
        pytest.fail(f"{CHROMIUM} and {CHROMEDRIVER} are needed (Debian packages chromium, chromium-driver; "
                    "`make browser` installs them)")
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    # The flags that keep Chromium off the network and quiet on a machine with no outside access.
    for flag in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--disable-dev-shm-usage", "--window-size=1400,1000",
                 f"--user-data-dir={tmp_path_factory.mktemp('chromium-profile')}"):
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    driver.set_page_load_timeout(60)
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    yield driver
    driver.quit()
