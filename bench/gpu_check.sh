#!/usr/bin/env bash
# bench/gpu_check.py on a lent device machine (the device tool's `run`) or a cluster node.
# Wheels carried in .whl/ are installed first (the device machine has no package registry); the
# figures go to $OUT/gpu_check.json when $OUT is set (the device tool brings that folder back),
# else ./gpu_check.json. Extra arguments go to gpu_check.py (e.g. --vllm-python ~/hcgym-vllm/bin/python).
set -u
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if compgen -G ".whl/*.whl" >/dev/null; then
  "$PY" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl \
    || { echo "bench/gpu_check.sh: installing the carried wheels failed"; exit 1; }
  export PYTHONPATH=/tmp/site${PYTHONPATH:+:$PYTHONPATH}
fi
export PYTHONUNBUFFERED=1 HF_HUB_OFFLINE=1 TRANSFORMERS_OFFLINE=1 RAY_USAGE_STATS_ENABLED=0 TOKENIZERS_PARALLELISM=false
exec timeout 590 "$PY" bench/gpu_check.py --out "${OUT:-.}/gpu_check.json" --budget-s 570 "$@"
