"""Multi-node placement on a simulated cluster: several Ray nodes on this machine (ray.cluster_utils).

The nodes carry custom resources that name them, so the tests can say where actors must land:

    head      CPU 1                                    the learner actor (it only fans calls out)
    train_a   CPU 1, learner_node 1, flaky_pair 1      DeepSpeed ranks
    train_b   CPU 1, learner_node 1
    rollout   CPU 1, rollout_node 1                    the generator
    broken    CPU 1, flaky_pair 1, GLOO_SOCKET_IFNAME=nosuchif0 in its environment: gloo cannot
              start there, the way a node with a wrong interface setting fails for real

All nodes share this host's IP, so "across nodes" means separate raylets and worker pools, and
the rendezvous address is the node IP Ray reports (not 127.0.0.1). Ray does not enforce CPU counts
against real cores; the model is tiny and the steps few.

This module runs its own cluster: if the session-wide `ray_cluster` (conftest) is up, it is shut
down first and started again, with the same arguments, when the module ends, so modules that run
after this one still find it.
"""

from __future__ import annotations

import time

import pytest
import torch

from learner.config import RunConfig
from modeling.config_models import LearnerConfig
from learner.learner_actor import Learner, LearnerActor
from learner.placement import (
    ActorDemand,
    PlacementError,
    StartupError,
    check_cluster_fits,
    missing_resources,
    run_demands,
)
from tests.training.conftest import SESSION_RAY_INIT
from tests.training.learner_fixtures import make_batch, tiny_model_dir
from tests.training.test_train import tiny_config

pytestmark = pytest.mark.ray

NODES = {
    "train_a": {"num_cpus": 1, "resources": {"learner_node": 1, "flaky_pair": 1}},
    "train_b": {"num_cpus": 1, "resources": {"learner_node": 1}},
    "rollout": {"num_cpus": 1, "resources": {"rollout_node": 1}},
    "broken": {"num_cpus": 1, "resources": {"flaky_pair": 1}, "env_vars": {"GLOO_SOCKET_IFNAME": "nosuchif0"}},
}


@pytest.fixture(scope="module")
def cluster():
    """The simulated cluster; yields {node name: Ray node id}."""
    import ray
    from ray.cluster_utils import Cluster

    session_was_up = ray.is_initialized()
    if session_was_up:
        ray.shutdown()
    from envs._runtime import later_session_system_config

    sim = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False,
                                                        "_system_config": later_session_system_config()})
    try:
        ids = {"head": sim.head_node.node_id}
        for name, args in NODES.items():
            ids[name] = sim.add_node(**args).node_id
        ray.init(address=sim.address, namespace="hcgym-placement-tests", log_to_driver=False)
        yield ids
    finally:
        ray.shutdown()
        sim.shutdown()
        if session_was_up:
            from envs._runtime import init_ray

            init_ray(**SESSION_RAY_INIT)


def _ds_config(lr: float = 1e-2) -> LearnerConfig:
    return LearnerConfig(backend="deepspeed", optim={"lr": lr, "micro_batch_size": 2},
                         loss={"grpo": {"kl_beta": 0.0}},
                         deepspeed={"world_size": 2, "num_cpus_per_rank": 1, "timeout_s": 120})


def _actor_node(handle) -> str:
    import ray

    return ray._private.state.actors(handle._actor_id.hex())["Address"]["NodeID"]


def _node_ip(node_id: str) -> str:
    import ray

    return next(n["NodeManagerAddress"] for n in ray.nodes() if n["NodeID"] == node_id)


def _logprobs_under(state: dict[str, torch.Tensor], model_dir: str, prompt: list[int],
                    tokens: list[int]) -> torch.Tensor:
    """Log-probs of `tokens` after `prompt` under a model holding `state` (what the generator must report)."""
    from modeling.model import load_policy, per_token_logprobs

    model, _ = load_policy(model_dir)
    model.load_state_dict(state)
    ids = torch.tensor([prompt + tokens])
    with torch.no_grad():
        lp = per_token_logprobs(model, ids, torch.ones_like(ids))
    return lp[0, len(prompt):]


def test_ranks_land_where_placed_train_and_sync_weights_across_nodes(cluster):
    import ray

    from actors.generator import GenerationRequest, generator_actor_class

    model_dir = tiny_model_dir()
    learner = LearnerActor.options(num_cpus=1).remote(
        _ds_config().model_dump(), model_dir, 0, {"resources": {"learner_node": 1}, "startup_timeout_s": 300})
    generator = generator_actor_class().options(num_cpus=1, resources={"rollout_node": 1}, max_concurrency=16) \
        .remote("hf", model_dir, {"temperature": 1.0}, [0], 0, {}, 4, 0.0)
    try:
        ray.get([learner.policy_version.remote(), generator.version.remote()], timeout=300)
        report = ray.get(learner.placement_report.remote())
        # Each rank reports the node it runs on; it is the node its bundle was placed on, and the
        # PACK group of 1-CPU bundles needed both training nodes.
        assert report["rank_nodes"] == report["bundle_nodes"]
        assert sorted(report["rank_nodes"]) == sorted([cluster["train_a"], cluster["train_b"]])
        assert _actor_node(learner) == cluster["head"]
        assert _actor_node(generator) == cluster["rollout"]

        # The weight-sync group meets at learner rank 0's node, whatever node the generator is on.
        address = ray.get(learner.rendezvous_address.remote())
        assert address["node_id"] == report["rank_nodes"][0]
        assert address["ip"] == _node_ip(report["rank_nodes"][0])
        sync = {"transport": "collective", "backend": "gloo", "bucket_mb": 0.05, "timeout_s": 60,
                "master_addr": address["ip"], "master_port": address["port"]}
        names = ["learner-rank0", "generator-0"]
        ray.get([learner.join_weight_sync.remote(sync, 2, names), generator.join_weight_sync.remote(sync, 1, 2, names)],
                timeout=120)

        request = GenerationRequest(request_id="probe", prompt_ids=[5, 17, 33, 61, 90], max_new_tokens=6, seed=1,
                                    greedy=True)
        before = ray.get(generator.generate.remote(request), timeout=60)
        initial = ray.get(learner.get_state_dict.remote())
        for step in (1, 2):
            metrics = ray.get(learner.train_step.remote(make_batch(seed=step, model_dir=model_dir), None, step))
            assert torch.isfinite(torch.tensor([metrics["loss"], metrics["grad_norm"]])).all(), metrics
            assert metrics["grad_norm"] > 0 and metrics["policy_version"] == step
        sent, version = ray.get([learner.broadcast_weights.remote(), generator.receive_weights.remote(2)], timeout=120)
        assert version == 2 and sent["version"] == 2.0

        after = ray.get(generator.generate.remote(request.model_copy(update={"min_version": 2})), timeout=60)
        trained = ray.get(learner.get_state_dict.remote())
        expected = _logprobs_under(trained, model_dir, request.prompt_ids, after.token_ids)
        stale = _logprobs_under(initial, model_dir, request.prompt_ids, after.token_ids)
        got = torch.tensor(after.logprobs)
        # The generator scores with the learner's new weights (float32 on both sides) ...
        assert torch.allclose(got, expected, atol=1e-4), (got, expected)
        # ... which is a visible change from the weights it started with.
        assert float((got - stale).abs().max()) > 1e-3
        assert before.policy_version == 0 and after.policy_version == 2
    finally:
        ray.get(learner.shutdown.remote())
        ray.kill(learner)
        ray.kill(generator)


def test_a_config_the_cluster_cannot_hold_fails_at_start_naming_the_missing_resource(cluster):
    import ray

    model_dir = tiny_model_dir()
    started = time.monotonic()
    with pytest.raises(PlacementError, match=r"tpu_slice: the run needs 2 .*the cluster has 0"):
        Learner(_ds_config(), model_dir, placement={"resources": {"tpu_slice": 1}})
    # Each node has one learner_node: STRICT_PACK cannot put both ranks on one node.
    with pytest.raises(PlacementError, match="STRICT_PACK: no node can hold all 2 learner ranks"):
        Learner(_ds_config(), model_dir, placement={"resources": {"learner_node": 1}, "strategy": "STRICT_PACK"})
    assert time.monotonic() - started < 10

    # Without the up-front check, the placement group's own wait names what was not placed.
    started = time.monotonic()
    with pytest.raises(PlacementError, match=r"not placed within 2s \(bundles not placed: .*learner_node"):
        Learner(_ds_config(), model_dir, placement={"resources": {"learner_node": 1}, "strategy": "STRICT_PACK",
                                                    "check_resources": False, "placement_timeout_s": 2})
    assert time.monotonic() - started < 15
    assert ray.available_resources().get("learner_node") == 2  # the half-placed group was released

    # The whole run: two generators that each want the only rollout node, and a GPU teacher.
    cfg = RunConfig.model_validate({
        "generator": {"num_generators": 2}, "learner": {"loss": {"distill": {"enabled": True}}},
        "teacher": {"enabled": True},
        "ray": {"generator_resources": {"rollout_node": 1}, "teacher_num_gpus": 1},
    })
    with pytest.raises(PlacementError) as info:
        check_cluster_fits(run_demands(cfg))
    message = str(info.value)
    assert "rollout_node: the run needs 2 (2 x generator at 1 each), the cluster has 1" in message
    assert "GPU: the run needs 1 (1 x teacher at 1 each), the cluster has 0" in message


def test_missing_resources_checks_totals_and_single_nodes():
    demands = [ActorDemand(name="learner rank", count=2, resources={"CPU": 1, "GPU": 1}),
               ActorDemand(name="generator", count=1, resources={"CPU": 2})]
    # Enough in total, but no node holds a 2-CPU generator.
    nodes = [{"CPU": 1, "GPU": 1}, {"CPU": 1, "GPU": 1}, {"CPU": 1}]
    problems = missing_resources(demands, {"CPU": 3, "GPU": 2, "node:10.0.0.1": 1}, nodes)
    assert problems == ["CPU: the run needs 4 (2 x learner rank at 1 each, 1 x generator at 2 each), the cluster has 3",
                        "no node can hold one generator (CPU 2); nodes have: CPU 1, GPU 1; CPU 1, GPU 1; CPU 1"]
    assert missing_resources(demands, {"CPU": 4, "GPU": 2}, [{"CPU": 2, "GPU": 2}, {"CPU": 2}]) == []
    # The same cluster, but the ranks must each have a node of their own.
    assert missing_resources(demands, {"CPU": 4, "GPU": 2}, [{"CPU": 2, "GPU": 2}, {"CPU": 2}],
                             {"learner rank": "STRICT_SPREAD"}) == [
        "STRICT_SPREAD: 2 learner ranks need 2 nodes that can each hold one (CPU 1, GPU 1), the cluster has 1"]


def test_a_rank_that_fails_while_starting_fails_the_learner_within_seconds_with_its_error(cluster):
    import ray

    model_dir = tiny_model_dir()
    started = time.monotonic()
    # One of the two flaky_pair nodes cannot start gloo: its rank raises; the other rank, already
    # waiting in the rendezvous, would wait out the 120 s collective timeout if the learner waited for it.
    with pytest.raises(StartupError, match=r"DeepSpeed rank [01] failed after .*nosuchif0") as info:
        Learner(_ds_config(), model_dir, placement={"resources": {"flaky_pair": 1}})
    elapsed = time.monotonic() - started
    assert elapsed < 60, elapsed
    assert "rendezvous" in str(info.value)
    # The ranks and their placement group are gone: the resources are free again.
    deadline = time.monotonic() + 10
    while ray.available_resources().get("flaky_pair") != 2 and time.monotonic() < deadline:
        time.sleep(0.2)
    assert ray.available_resources().get("flaky_pair") == 2


def _multinode_run(tmp_path, policy_dir, **ray_section):
    return tiny_config(
        tmp_path / "run", policy_dir,
        learner={"backend": "deepspeed", "optim": {"lr": 1e-3, "micro_batch_size": 2},
                 "loss": {"entropy_coef": 0.01, "grpo": {"kl_beta": 0.0}},
                 "deepspeed": {"world_size": 2, "num_cpus_per_rank": 1, "timeout_s": 120}},
        weight_sync={"transport": "collective", "backend": "gloo", "bucket_mb": 0.05, "timeout_s": 60},
        trainer={"max_steps": 2, "checkpoint_interval": 0},
        ray={"learner_num_cpus": 0, "learner_resources": {"learner_node": 1},
             "generator_resources": {"rollout_node": 1}, **ray_section},
    )


def test_the_driver_refuses_a_run_the_cluster_cannot_hold_before_creating_actors(cluster, ward_policy_dir, tmp_path):
    import ray

    from learner.train import train

    cfg = _multinode_run(tmp_path, ward_policy_dir, generator_resources={"rollout_node": 1, "gpu_box": 1})
    existing = set(ray._private.state.actors())
    started = time.monotonic()
    with pytest.raises(PlacementError, match="gpu_box: the run needs 1 .*the cluster has 0"):
        train(cfg, log=lambda line: None)
    assert time.monotonic() - started < 30
    # The check ran before the driver created any actor.
    assert set(ray._private.state.actors()) == existing


def test_the_driver_trains_across_nodes_with_ranks_placed_and_the_sync_group_at_rank0(cluster, ward_policy_dir,
                                                                                     tmp_path):
    import ray

    from learner.metrics import read_metrics
    from learner.train import train

    lines: list[str] = []
    summary = train(_multinode_run(tmp_path, ward_policy_dir), log=lines.append)
    assert summary["steps"] == 2
    records = read_metrics(tmp_path / "run")
    assert [r["step"] for r in records] == [1, 2]
    assert all(r["policy_version"] == r["step"] for r in records)
    placed = next(line for line in lines if "learner rank nodes" in line)
    assert sorted(placed.split("learner rank nodes ")[1].strip("[]").replace("'", "").split(", ")) == \
        sorted([cluster["train_a"][:8], cluster["train_b"][:8]])
    # The run's learner (and with it its ranks and their placement group) is gone: resources are free.
    deadline = time.monotonic() + 15
    while ray.available_resources().get("learner_node") != 2 and time.monotonic() < deadline:
        time.sleep(0.2)
    assert ray.available_resources().get("learner_node") == 2


def test_kb_shard_actors_spread_over_the_nodes_that_hold_their_resource_and_rank_as_one_index(cluster, tmp_path):
    """A sharded KB served by 2 shard actors that ask for a resource only the two training nodes have
    (`kb.shards.resources`, SPREAD): one actor lands on each of those nodes, and a search fanned out to
    them returns the single index's ids, order and float32 scores."""
    import shutil

    from kb_service.ingest import build_kb, file_input
    from kb_service.kb import KnowledgeBase
    from kb_service.reshard import shard_kb
    from kb_service.service import start_kb_service
    from tests.kb.conftest import make_corpus, write_jsonl

    docs = make_corpus(n_filler=200, seed=3)
    single = tmp_path / "single"
    build_kb([file_input(write_jsonl(tmp_path / "passages.jsonl", docs))], single, progress=False,
             echo=lambda s: None)
    sharded = tmp_path / "sharded"
    shutil.copytree(single, sharded)
    assert shard_kb(sharded, 60, echo=lambda s: None)["shards"] == 4
    client = start_kb_service(replicas=1, path=sharded, name="placement-kb", num_cpus=0,
                              shards={"actors": 2, "resources": {"learner_node": 1}, "start_timeout_s": 120})
    try:
        assert sorted(_actor_node(h) for h in client.shard_handles) == sorted([cluster["train_a"], cluster["train_b"]])
        reference = KnowledgeBase.open(single)
        words = sorted({w for d in docs[::9] for w in d["content"].rstrip(".").lower().split() if len(w) >= 5})
        for query in ["pheochromocytoma metanephrines", "secondary hypertension", *words[:12]]:
            got = [(p.doc_id, p.score) for p in client.search(query, k=8)]
            assert got == [(p.doc_id, p.score) for p in reference.search(query, k=8)], query
            assert got, query
    finally:
        client.shutdown()
