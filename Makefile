# Healthcare AI GYM. `make demo` runs the main job, `make test` the test suite.
# Both set up .venv first (idempotent: re-running installs nothing when nothing changed).
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
# The CPU path needs these; envs/_runtime.py also sets them on import for users who skip make.
export OMP_NUM_THREADS := 1
export MKL_NUM_THREADS := 1
export TOKENIZERS_PARALLELISM := false
export RAY_AUTH_MODE := disabled
export RAY_USAGE_STATS_ENABLED := 0
export HF_HUB_OFFLINE := 1
export TRANSFORMERS_OFFLINE := 1
export DS_ACCELERATOR := cpu
export PIP_DISABLE_PIP_VERSION_CHECK := 1

.PHONY: setup data demo tour test validate bench clean

setup: $(STAMP)

$(STAMP): pyproject.toml constraints-cpu.txt
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q -c constraints-cpu.txt torch==2.13.0
	$(BIN)/pip install -q -c constraints-cpu.txt -e ".[test,embed]"
	$(BIN)/python -c "import torch; assert torch.__version__.endswith('+cpu'), torch.__version__"
	touch $(STAMP)

data: setup
	$(BIN)/hcgym data build

# The main job: tiny-model TT-OPD on a local 2-CPU Ray cluster (SFT warm start on gold replays,
# then RL), writing runs/demo/ with metrics.jsonl and training_dynamics.png.
demo: data
	$(BIN)/hcgym train --config configs/tiny_cpu_ttopd.yaml --output-dir runs/demo
	$(BIN)/hcgym plot runs/demo

# A scripted gold-replay tour of every domain (no model).
tour: data
	$(BIN)/hcgym demo

validate: data
	$(BIN)/hcgym tasks validate

test: data
	$(BIN)/hcgym tasks validate
	$(BIN)/python -m pytest -q

bench: data
	for b in bench/*.py; do $(BIN)/python $$b || exit 1; done

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis
