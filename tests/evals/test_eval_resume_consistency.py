"""An evaluation whose two files did not commit together resumes to one trajectory per result.

A flush renames trajectories.parquet, then results.parquet. When the second write fails (a full
disk, or the process killed between the two renames), trajectories.parquet holds rows of
episodes that have no result: the resumed evaluation runs those episodes again and must not keep
both trajectories of each (it kept 30 trajectory rows for 15 results before).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import pyarrow.parquet as pq
import pytest

from evals.policies import ScriptedPolicy
from evals.runner import row_id, run_eval
from evals.types import RESULTS_FILE, TRAJECTORIES_FILE, read_results
from learner.faults import FAULT_ENV
from tests.evals.test_runner import ITEMS, options

pytestmark = pytest.mark.usefixtures("ward_domain")
SEEDS = (0, 1, 2, 3, 4)  # 3 tasks x 5 seeds = 15 episodes


def assert_one_trajectory_per_result(out) -> None:
    rows = read_results(out)
    trajectories = pq.read_table(out / TRAJECTORIES_FILE).to_pylist()
    ids = [t["row_id"] for t in trajectories]
    assert len(rows) == 15 and len({r.key() for r in rows}) == 15
    assert len(ids) == 15, f"{len(ids)} trajectory rows ({len(set(ids))} unique ids) for {len(rows)} results"
    assert set(ids) == {row_id(r.key()) for r in rows}


def test_results_write_failing_after_trajectories_resumes_without_duplicates(tmp_path):
    out = tmp_path / "eval"
    out.mkdir()
    # results.parquet cannot be replaced (a directory is in the way): the flush fails after it
    # renamed trajectories.parquet, as it does on a full disk.
    (out / RESULTS_FILE).mkdir()
    with pytest.raises(OSError):
        run_eval(ScriptedPolicy("gold"), ITEMS, out, options(seeds=SEEDS, flush_every_s=3600.0), suite="ward")
    (out / RESULTS_FILE).rmdir()
    assert len(pq.read_table(out / TRAJECTORIES_FILE)) == 15 and not read_results(out)

    resumed = run_eval(ScriptedPolicy("gold"), ITEMS, out, options(seeds=SEEDS), suite="ward")
    assert resumed["episodes_run"] == 15
    assert_one_trajectory_per_result(out)


SCRIPT = """
import sys
from evals.policies import ScriptedPolicy
from evals.runner import run_eval
from tests.evals.test_runner import ITEMS, options
run_eval(ScriptedPolicy("gold"), ITEMS, sys.argv[1], options(seeds=(0, 1, 2, 3, 4), flush_every_s=3600.0),
         suite="ward")
"""


def test_eval_killed_between_the_two_renames_resumes_without_duplicates(tmp_path):
    out = tmp_path / "eval"
    env = {**os.environ, FAULT_ENV: "eval_trajectories_written:1", "HCGYM_EMBEDDINGS": "0"}
    killed = subprocess.run([sys.executable, "-c", SCRIPT, str(out)], env=env, capture_output=True, text=True,
                            timeout=120)
    assert killed.returncode == -signal.SIGKILL, killed.stderr[-2000:]
    assert len(pq.read_table(out / TRAJECTORIES_FILE)) == 15 and not (out / RESULTS_FILE).exists()

    resumed = run_eval(ScriptedPolicy("gold"), ITEMS, out, options(seeds=SEEDS), suite="ward")
    assert resumed["episodes_run"] == 15
    assert_one_trajectory_per_result(out)
