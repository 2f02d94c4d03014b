"""cluster.yaml against Ray's own schema and the checks `ray up` runs before it touches a cloud,
and the promises docs/cluster.md makes about it: Python >= 3.11 from uv, the `gpu` extra, data and
model on every node, token auth on, the dashboard on loopback."""

from __future__ import annotations

import copy
import json
import re
import shlex
from pathlib import Path

import jsonschema
import pytest
import yaml

REPO_ROOT = Path(__file__).resolve().parents[2]
CLUSTER_YAML = REPO_ROOT / "cluster.yaml"
SUBMITTED_CONFIG = REPO_ROOT / "configs" / "qwen35_9b_ttopd.yaml"  # the config docs/cluster.md submits
VENV = "~/hcgym-venv"  # the project: driver, learner, teacher, env actors
VLLM_VENV = "~/hcgym-vllm"  # the vLLM generators


@pytest.fixture(scope="module")
def cluster() -> dict:
    return yaml.safe_load(CLUSTER_YAML.read_text(encoding="utf-8"))


def ray_schema() -> dict:
    import ray.autoscaler

    return json.loads((Path(ray.autoscaler.__file__).parent / "ray-schema.json").read_text(encoding="utf-8"))


def test_cluster_yaml_passes_rays_schema_and_ray_up_validation(cluster):
    from ray.autoscaler._private.commands import prepare_config
    from ray.autoscaler._private.util import validate_config

    jsonschema.validate(cluster, ray_schema())
    # What `ray up` does first (offline: node resources are given, so no cloud call).
    prepared = prepare_config(copy.deepcopy(cluster))
    validate_config(prepared)
    assert prepared["head_node_type"] in prepared["available_node_types"]


@pytest.mark.parametrize("mutation, error", [
    (lambda c: c.update(setup_command=c.pop("setup_commands")), jsonschema.ValidationError),  # misspelt key
    (lambda c: c["provider"].pop("type"), jsonschema.ValidationError),
    (lambda c: c.update(head_node_type="head_h100x8"), ValueError),  # not among available_node_types
])
def test_the_validation_rejects_a_broken_cluster_file(cluster, mutation, error):
    from ray.autoscaler._private.commands import prepare_config
    from ray.autoscaler._private.util import validate_config

    broken = copy.deepcopy(cluster)
    mutation(broken)
    with pytest.raises(error):
        jsonschema.validate(broken, ray_schema())
        validate_config(prepare_config(broken))


def commands(cluster: dict, key: str) -> list[str]:
    return [" ".join(c.split()) for c in cluster[key]]


def test_every_node_gets_python_311_from_uv_the_project_vllm_data_and_the_submitted_model(cluster):
    import tomllib

    from envs.cli import build_parser
    from learner.config import load_config

    setup = commands(cluster, "setup_commands")
    submitted = load_config(SUBMITTED_CONFIG)
    venv_lines = [c for c in setup if "uv venv" in c]
    assert {c.split()[-1] for c in venv_lines} == {VENV, VLLM_VENV}
    for line in venv_lines:  # Ray workers need the driver's Python version: one version for both
        version = re.search(r"--python (\d+)\.(\d+)", line)
        assert version and (int(version[1]), int(version[2])) >= (3, 11), line
        assert any(f"uv python install {version[1]}.{version[2]}" in c for c in setup)
    assert len({re.search(r"--python (\S+)", c)[1] for c in venv_lines}) == 1, venv_lines
    assert any("sys.version_info >= (3, 11)" in c for c in setup)  # checked on the node, not assumed

    installs = [c for c in setup if "uv pip install" in c]
    project = [c for c in installs if f"--python {VENV}/bin/python" in c]
    vllm_side = [c for c in installs if f"--python {VLLM_VENV}/bin/python" in c]
    assert len(project) + len(vllm_side) == len(installs)
    # The project's venv: exact tested versions, no vLLM (its numba pin clashes with ours).
    assert all("-c constraints-cpu.txt" in c and "vllm" not in c for c in project), project
    # vLLM's venv: the `gpu` extra's vLLM with the same constraints (same torch/Ray/transformers as
    # the learner on the other end of the weight sync), then the project without its dependencies.
    pyproject = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    gpu_extra = pyproject["project"]["optional-dependencies"]["gpu"]
    assert any(all(f'"{spec.replace(" ", "")}"' in c for spec in gpu_extra) and "-c constraints-cpu.txt" in c
               for c in vllm_side), (gpu_extra, vllm_side)
    assert any("--no-deps -e ." in c for c in vllm_side), vllm_side
    assert any("sys.version.split()[0], torch.__version__, ray.__version__" in c and c.startswith("test ")
               for c in setup)  # both interpreters agree on Python, torch and Ray, checked on the node
    # The generators of the submitted config run in that venv.
    home = f"/home/{cluster['auth']['ssh_user']}"
    assert submitted.generator.backend == "vllm"
    on_node = submitted.generator.python_executable.replace("~", home, 1)
    assert on_node == f"{VLLM_VENV.replace('~', home, 1)}/bin/python", on_node

    # Every hcgym call is the venv's and parses with the project's own CLI (catches renamed commands).
    hcgym_lines = [c for c in setup if "hcgym " in c]
    assert all(f"{VENV}/bin/hcgym" in c for c in hcgym_lines)
    hcgym_calls = []
    for line in hcgym_lines:
        words = shlex.split(line.split("&&")[-1])
        binary = next(i for i, w in enumerate(words) if w.endswith("/bin/hcgym"))
        hcgym_calls.append((words[:binary], words[binary + 1:]))  # (VAR=value prefixes, arguments)
    parser = build_parser()
    parsed = [(prefix, parser.parse_args(argv)) for prefix, argv in hcgym_calls]
    assert ["data", "model"] == [p.command for _, p in parsed]
    fetch_env, fetch = next((prefix, p) for prefix, p in parsed if p.command == "model")
    # Importing the project sets HF_HUB_OFFLINE=1 when unset; the fetch must say it is online.
    assert "HF_HUB_OFFLINE=0" in fetch_env, fetch_env
    fetched = fetch.model_id
    # The cache is per node and runs are offline: the fetched id must be the submitted config's model.
    assert submitted.model.path == fetched


SUBMIT_DOCS = ["docs/cluster.md", "README.md", "docs/training.md", "cluster.yaml"]


@pytest.mark.parametrize("doc", SUBMIT_DOCS)
def test_documented_job_submission_puts_the_cluster_venv_first_on_path(cluster, doc):
    """The submit command users copy (tested for real in test_job_submit.py with a local venv)
    must name the venv that cluster.yaml's setup builds, for the config that its setup prepares."""
    text = (REPO_ROOT / doc).read_text(encoding="utf-8")
    venv_bin = f"/home/{cluster['auth']['ssh_user']}/hcgym-venv/bin"
    submits = re.findall(r"ray job submit .*?--runtime-env-json '([^']*)'(.*?)--output-dir", text, flags=re.S)
    assert submits, f"{doc}: no `ray job submit ... --runtime-env-json '...'` command"
    for runtime_env, rest in submits:
        assert json.loads(runtime_env)["env_vars"]["PATH"] == f"{venv_bin}:${{PATH}}", (doc, runtime_env)
        config = re.search(r"python -m learner\.train --config (\S+)", rest)
        assert config and (REPO_ROOT / config[1]) == SUBMITTED_CONFIG, (doc, rest)
    assert "--address http://127.0.0.1:8265" in text and "RAY_AUTH_MODE=token" in text, doc


def test_ray_runs_from_the_venv_with_token_auth_and_a_loopback_dashboard(cluster):
    head = commands(cluster, "head_start_ray_commands")
    workers = commands(cluster, "worker_start_ray_commands")
    for line in head + workers:
        assert "ray " in line and f"{VENV}/bin/ray" in line, line
    for line in (head[-1], workers[-1]):
        assert "ray start" in line
        # token auth decided explicitly, before `ray start`, on every node
        assert line.index("export RAY_AUTH_MODE=token") < line.index("ray start"), line
    assert "--dashboard-host=127.0.0.1" in head[-1]
    text = CLUSTER_YAML.read_text(encoding="utf-8")
    assert "0.0.0.0" not in yaml.safe_dump(cluster)  # nothing bound to every interface on purpose
    assert "RAY_AUTH_MODE=disabled" not in text
    # The token that `ray get-auth-token --generate` wrote on the user's machine, on every node.
    assert cluster["file_mounts"]["/home/ubuntu/.ray/auth_token"] == "~/.ray/auth_token"
    assert {".venv", ".venv-vllm"} <= set(cluster["rsync_exclude"])  # local CPU venvs stay local


def test_nodes_run_an_image_whose_driver_fits_torchs_cuda_build_and_check_it(cluster):
    from modeling.plan import MIN_DRIVER_FOR_CUDA, check_gpu_node, driver_problem

    setup = commands(cluster, "setup_commands")
    check = [i for i, c in enumerate(setup) if "check_gpu_node" in c]
    install = next(i for i, c in enumerate(setup) if "hcgym-venv/bin/python -c constraints-cpu.txt -e ." in c)
    assert check and check[0] > install, "the GPU check runs right after the project (and torch) is installed"
    assert any("build-essential" in c for c in setup[:install])  # gcc for Triton and DeepSpeed's JIT ops
    assert any("flash-linear-attention" in c and "hcgym-venv" in c for c in setup)
    for node in cluster["available_node_types"].values():
        image = node["node_config"]["ImageId"]
        assert image.startswith("resolve:ssm:/aws/service/deeplearning/ami/x86_64/base-oss-nvidia-driver"), image
        ebs = node["node_config"]["BlockDeviceMappings"][0]["Ebs"]
        assert ebs["VolumeType"] == "gp3" and ebs["Throughput"] == 1000 and ebs["Iops"] >= ebs["Throughput"] * 4
    # The driver requirement is derived in one place, from torch's CUDA build: PyPI's torch 2.13.0 is CUDA 13.0.
    assert MIN_DRIVER_FOR_CUDA["13.0"] == "580.65.06"
    assert driver_problem("13.0", "580.95.05") is None and driver_problem("13.0", "595.91.07") is None
    assert driver_problem("13.0", "535.104.05") == (
        "NVIDIA driver 535.104.05 is older than 580.65.06, the minimum for torch's CUDA 13.0 build")
    assert "needs driver >= 580.65.06" in driver_problem("13.0", None)
    assert "CPU build" in driver_problem(None, None)
    # On this CPU machine the check fails and says what it found and what it needs.
    import torch

    if not torch.cuda.is_available():
        with pytest.raises(SystemExit, match="GPU node check failed: .*(CPU build|driver)"):
            check_gpu_node()


def test_the_shipped_configs_plan_for_cluster_yamls_nodes(cluster):
    from learner.config import load_config

    node = cluster["available_node_types"][cluster["head_node_type"]]
    planned = load_config(SUBMITTED_CONFIG).cluster
    assert (planned.gpus_per_node, planned.cpus_per_node) == (node["resources"]["GPU"], node["resources"]["CPU"])
    assert planned.checkpoint_volume_mib_s == node["node_config"]["BlockDeviceMappings"][0]["Ebs"]["Throughput"]
