"""Starting a run's Ray cluster connection and actors (generators, learner, teacher, KB service)
from the run config. The driver calls these once; placement of actors on nodes is decided here."""

from __future__ import annotations

from typing import Any

from actors.generator import generator_actor_class
from learner.config import RunConfig


def init_ray(cfg: RunConfig) -> None:
    """Connect to `ray.address`, or start a local cluster with `ray.num_cpus` (no-op if connected)."""
    import ray

    if ray.is_initialized():
        return
    rc = cfg.ray
    kwargs: dict[str, Any] = {"namespace": rc.namespace, "include_dashboard": rc.include_dashboard,
                              "log_to_driver": True}
    if rc.address:
        kwargs["address"] = rc.address
    else:
        kwargs["num_cpus"] = rc.num_cpus
    ray.init(**kwargs)


def start_generators(cfg: RunConfig, policy_dir: str, stop_ids: list[int]) -> list:
    g = cfg.generator
    gen_cls = generator_actor_class().options(num_cpus=g.num_cpus, num_gpus=g.num_gpus, max_restarts=g.max_restarts,
                                              max_task_retries=0, max_concurrency=1000)
    return [gen_cls.remote(g.backend, policy_dir, g.sampling.model_dump(), stop_ids, 0, g.options,
                           g.max_batch_size, g.batch_wait_s)
            for _ in range(g.num_generators)]


def start_learner(cfg: RunConfig, policy_dir: str):
    from learner.learner_actor import LearnerActor

    return LearnerActor.options(num_cpus=cfg.ray.learner_num_cpus, num_gpus=cfg.ray.learner_num_gpus) \
        .remote(cfg.learner.model_dump(), policy_dir, cfg.seed)


def start_teacher(cfg: RunConfig, policy_dir: str):
    from actors.teacher import TeacherActor

    rc = cfg.ray
    return TeacherActor.options(num_cpus=rc.teacher_num_cpus, num_gpus=rc.teacher_num_gpus,
                                max_restarts=rc.teacher_max_restarts, max_task_retries=0) \
        .remote(cfg.teacher.model_dump(), policy_dir, cfg.seed)


def start_kb_service(cfg: RunConfig):
    """The shared knowledge-base service, or None when `kb.service` is off."""
    if not cfg.kb.service:
        return None
    from kb_service.service import start_kb_service as start

    return start(cfg.kb.replicas, cfg.kb.path, cfg.kb.name, cfg.kb.num_cpus)
