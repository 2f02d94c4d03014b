"""A knowledge-base build on a disk that fills: sqlite's bare "database or disk is full" becomes an
error naming the build's staging folder and saying that the disk is full; the passages committed
before stay, the previous knowledge base is untouched, and the build run again after space is
freed resumes after them and ends with every passage exactly once.

The disk is a real 16 MiB tmpfs (tests/small_disk.py) holding the build folder, with a ballast file
leaving 0.5 MiB free; the input (3.6 MB of text, which the store compresses to 1.3 MB) lies
elsewhere, so the build fills the disk on its own, during ingestion; deleting the ballast frees
the space.
"""

from __future__ import annotations

import json
import random
import re
import sqlite3

import pytest

from envs.core.files import DiskFullError
from kb_service.ingest import build_kb, file_input
from kb_service.kb import KnowledgeBase
from tests.small_disk import small_disk

WORDS = ("patient dose renal hepatic warfarin aspirin sepsis lactate insulin potassium "
         "creatinine fever cough rash troponin").split()


@pytest.fixture
def disk():
    with small_disk(16) as mounted:
        yield mounted


def test_a_full_disk_stops_the_build_naming_it_and_the_rerun_resumes_without_duplicates(disk, tmp_path):
    rng = random.Random(0)
    n = 2500
    docs = [{"doc_id": f"d{i}", "source": "s", "title": f"T{i}",
             "content": " ".join(f"{rng.choice(WORDS)}{rng.randrange(100)}" for _ in range(150)) + f" marker{i}"}
            for i in range(n)]
    source = tmp_path / "passages.jsonl"
    source.write_text("".join(json.dumps(d) + "\n" for d in docs), encoding="utf-8")
    out = disk.root / "kb"
    staging = disk.root / "kb.building"
    quiet = {"progress": False, "echo": lambda line: None, "batch_size": 200}
    disk.fill(leave=1 << 19)

    with pytest.raises(DiskFullError) as info:
        build_kb([file_input(source)], out, **quiet)
    message = str(info.value)
    assert re.match(rf"{re.escape(str(staging))}: the disk is full \(\d[\d,]* bytes free", message), message
    committed = int(re.search(r"keeps the (\d+) passages committed so far", message).group(1))
    assert 0 < committed < n, message
    print(f"[figures] {message}")
    assert not out.exists() and "resumes after them" in message

    disk.free()
    lines: list[str] = []
    summary = build_kb([file_input(source)], out, **{**quiet, "echo": lines.append})
    assert any(f"resuming after {committed} records" in line for line in lines), lines
    assert summary["n_passages"] == n
    assert summary["inputs"][0]["duplicates"] == 0
    kb = KnowledgeBase.open(out)
    assert kb.n_passages == n and kb.search("marker2499", k=1)[0].doc_id == "d2499"
    conn = sqlite3.connect(out / "passages.sqlite")
    assert conn.execute("SELECT count(DISTINCT doc_id) FROM passages").fetchone()[0] == n
    conn.close()
