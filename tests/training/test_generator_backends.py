"""A generator backend is one module: `actors/generator_<name>.py` declaring `BACKEND` is found by the
registry, its options are checked when a run config loads, and training and evaluation start it
through one function."""

from __future__ import annotations

import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from actors.generator import REPO_ROOT, generator_backend, generator_backends, generator_python_executable
from actors.generator_hf import HFGenerator, HFOptions
from actors.generator_vllm import VLLMOptions
from learner.config import ConfigError, GeneratorConfig, load_config
from tests.config_files import extended_config

REPO = Path(__file__).resolve().parents[2]


def test_the_registry_holds_the_hf_and_vllm_backends_with_their_options_and_interpreters():
    backends = generator_backends()
    assert sorted(backends) == ["hf", "vllm"]
    assert backends["hf"].generator is HFGenerator and backends["hf"].options is HFOptions
    assert backends["hf"].interpreter is None and generator_python_executable("hf", "auto") is None
    assert backends["vllm"].options is VLLMOptions and backends["vllm"].interpreter.venv == ".venv-vllm"
    assert generator_python_executable("vllm", "auto") == str(REPO_ROOT / ".venv-vllm" / "bin" / "python")
    with pytest.raises(ValueError, match=r"generator backend 'sglang' is unknown; choose one of \['hf', 'vllm'\]"):
        generator_backend("sglang")


def _config(tmp_path: Path, generator: str) -> Path:
    return extended_config(tmp_path, f"generator:\n{textwrap.indent(generator, '  ')}")


def test_backend_and_options_are_checked_when_the_config_loads(tmp_path):
    with pytest.raises(ConfigError, match=r"generator.backend: .*'sglang' is unknown; choose one of \['hf', 'vllm'\]"):
        load_config(_config(tmp_path, "backend: sglang"))
    # A typo in the backend's options fails at load (before the SFT warm start), naming the field.
    with pytest.raises(ConfigError, match=r"generator.options.reuse_kv_cach: Extra inputs are not permitted \(backend hf\)"):
        load_config(_config(tmp_path, "backend: hf\noptions: {reuse_kv_cach: true}"))
    with pytest.raises(ConfigError, match=r"generator.options.tensor_parallel_size: .*greater than or equal to 1"):
        load_config(_config(tmp_path, "backend: vllm\noptions: {tensor_parallel_size: 0}"))
    with pytest.raises(ConfigError, match=r"generator.num_gpus: \(2\) must equal generator.options.tensor_parallel_size"):
        load_config(_config(tmp_path, "backend: vllm\nnum_gpus: 2\noptions: {tensor_parallel_size: 1}"))
    cfg = load_config(_config(tmp_path, "backend: vllm\nnum_gpus: 2\noptions: {tensor_parallel_size: 2}"))
    assert cfg.generator.ranks_per_generator() == 2 and GeneratorConfig(backend="hf").ranks_per_generator() == 1


ECHO_BACKEND = '''
"""A test backend: answers every request with its prompt's last token, then a stop token."""

from pydantic import BaseModel, ConfigDict

from actors.generator import GenerationResult, Generator, GeneratorBackend


class EchoOptions(BaseModel):
    model_config = ConfigDict(extra="forbid")
    repeat: int = 1


class EchoGenerator(Generator):
    name = "echo"

    def __init__(self, model_dir, sampling, stop_token_ids, initial_version=0, options=None):
        super().__init__(model_dir, sampling, stop_token_ids, initial_version, options)
        self.options = EchoOptions.model_validate(options or {})

    def generate(self, requests):
        return [GenerationResult(request_id=r.request_id, token_ids=[r.prompt_ids[-1]] * self.options.repeat
                                 + [self.stop_token_ids[0]], logprobs=[0.0] * (self.options.repeat + 1),
                                 finish_reason="stop", policy_version=self.version) for r in requests]

    def update_weights(self, state_dict, version):
        self.version = version

    def join_weight_sync(self, config, rank, world_size, peer_names):
        raise NotImplementedError

    def receive_weights(self, version):
        raise NotImplementedError


BACKEND = GeneratorBackend(name="echo", generator=EchoGenerator, options=EchoOptions)
'''

PROBE = '''
import argparse

import actors
from actors.generator import GenerationRequest, SamplingConfig, generator_backends, make_generator
from evals.cli import add_arguments
from learner.config import GeneratorConfig

assert actors.__file__.startswith({root!r}), actors.__file__
parser = argparse.ArgumentParser()
add_arguments(parser)
args = parser.parse_args(["--generator-backend", "echo"])
GeneratorConfig(backend="echo", options={{"repeat": 2}})
try:
    GeneratorConfig(backend="echo", options={{"repeats": 2}})
except ValueError as exc:
    refused = "generator.options.repeats" in str(exc)
generator = make_generator("echo", "unused", SamplingConfig(), [0], options={{"repeat": 2}})
result = generator.generate([GenerationRequest(request_id="r", prompt_ids=[5, 7], max_new_tokens=4, seed=0)])[0]
print(sorted(generator_backends()), args.generator_backend, refused, result.token_ids)
'''


def test_a_new_backend_is_one_module(tmp_path):
    """actors/generator_echo.py added to a copy of the package (nothing else edited) is a backend the
    run config validates and evaluation's CLI offers, built by make_generator."""
    shutil.copytree(REPO / "actors", tmp_path / "actors", ignore=shutil.ignore_patterns("__pycache__"))
    (tmp_path / "actors" / "generator_echo.py").write_text(textwrap.dedent(ECHO_BACKEND))
    out = subprocess.run([sys.executable, "-c", PROBE.format(root=str(tmp_path))], cwd=tmp_path,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.split("\n")[-2] == "['echo', 'hf', 'vllm'] echo True [7, 7, 0]"
