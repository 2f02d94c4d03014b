"""An evaluation on a disk that fills: the error names the file and says the disk is full (not
pyarrow's bare "[Errno 28] Error writing bytes to file" on the progress-bar line), the results
written before stay, and the same command run after space is freed finishes with one result and
one trajectory per episode. A damaged results file is named in its error.

The disk is a real 16 MiB tmpfs (tests/small_disk.py) filled by a ballast file at an exact flush
(learner.faults.at), so the next write meets the kernel's own ENOSPC.
"""

from __future__ import annotations

import re

import pytest

from envs.core.files import DiskFullError
from evals.policies import ScriptedPolicy
from evals.runner import run_eval
from evals.types import RESULTS_FILE, TRAJECTORIES_FILE, read_results
from learner import faults
from tests.evals.test_eval_resume_consistency import SEEDS, assert_one_trajectory_per_result
from tests.evals.test_runner import ITEMS, options
from tests.small_disk import small_disk

pytestmark = pytest.mark.usefixtures("ward_domain")


@pytest.fixture
def disk():
    with small_disk(16) as mounted:
        yield mounted
    faults.clear_actions()


def test_a_full_disk_stops_the_evaluation_naming_the_file_and_the_rerun_completes_it(disk, capsys):
    out = disk.root / "eval"
    # After the 5th flush (one per finished episode) the disk is full.
    faults.at("eval_results_written:5", disk.fill)
    with pytest.raises(DiskFullError) as info:
        run_eval(ScriptedPolicy("gold"), ITEMS, out, options(seeds=SEEDS, progress=True), suite="ward")
    message = str(info.value)
    assert re.match(rf"{re.escape(str(out / TRAJECTORIES_FILE))}: the disk is full \(\d[\d,]* bytes free", message)
    assert f"{out} keeps the 5 results written before the disk filled" in message, message
    assert "run the same command again" in message
    # The progress bar was closed (its line ended) before the error left run_eval, so the CLI's
    # error message starts on a line of its own.
    assert capsys.readouterr().err.endswith("\n")
    assert len(read_results(out)) == 5
    assert not list(out.glob(".*.tmp"))

    disk.free()
    resumed = run_eval(ScriptedPolicy("gold"), ITEMS, out, options(seeds=SEEDS), suite="ward")
    assert resumed["episodes_run"] == 10 and resumed["episodes_skipped_done"] == 5
    assert_one_trajectory_per_result(out)


def test_a_damaged_results_file_is_named_in_the_error(tmp_path):
    out = tmp_path / "eval"
    run_eval(ScriptedPolicy("gold"), ITEMS, out, options(seeds=(0,)), suite="ward")
    path = out / RESULTS_FILE
    data = bytearray(path.read_bytes())
    footer = int.from_bytes(data[-8:-4], "little")  # the file metadata (thrift) sits before its length
    for offset in range(len(data) - 8 - footer, len(data) - 8, 7):
        data[offset] ^= 0xFF
    path.write_bytes(bytes(data))
    with pytest.raises(ValueError, match=rf"{re.escape(str(path))}: not a readable Parquet file, damaged"):
        read_results(out)
    # A resume refuses the folder the same way, and leaves the damaged file as it was.
    with pytest.raises(ValueError, match=re.escape(str(path))):
        run_eval(ScriptedPolicy("gold"), ITEMS, out, options(seeds=(0, 1)), suite="ward")
    assert path.read_bytes() == bytes(data)
