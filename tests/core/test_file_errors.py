"""Task, split, database and policy files: every failure names the file (and the task / split /
field where there is one), including files that are not UTF-8."""

from __future__ import annotations

import json

import pytest

from envs.core.db import DB, DataFileError, read_json_file, read_text_file
from envs.core.domain import DomainTaskStore, read_policy
from envs.core.task import load_split, load_tasks

TASKS = [{"id": "t1", "ticket": "Which drug?", "options": {"A": "x", "B": "y"}, "correct_answer": "A"}]


class WardDB(DB):
    """A two-field database, enough to exercise DB.load."""

    beds: dict[str, str] = {}
    capacity: int = 0


def test_latin1_task_file_names_file_line_and_byte(tmp_path):
    path = tmp_path / "tasks.json"
    # "Bézier" in Latin-1: é is the single byte 0xe9, invalid as UTF-8; on line 2 of the file.
    path.write_bytes(b'[\n{"id": "t1", "ticket": "B\xe9zier"}]\n')
    with pytest.raises(DataFileError) as err:
        load_tasks(path)
    text = str(err.value)
    assert str(path) in text and "task file is not UTF-8" in text
    assert "0xe9" in text and "line 2" in text


def test_utf16_task_file_is_refused_with_the_file(tmp_path):
    path = tmp_path / "tasks.json"
    path.write_bytes(json.dumps(TASKS).encode("utf-16"))
    with pytest.raises(DataFileError, match="not UTF-8"):
        load_tasks(path)


def test_utf8_bom_task_file_loads(tmp_path):
    # Windows editors save UTF-8 with a BOM; the content is the same, so it loads.
    path = tmp_path / "tasks.json"
    path.write_bytes(b"\xef\xbb\xbf" + json.dumps(TASKS).encode("utf-8"))
    assert [t.id for t in load_tasks(path)] == ["t1"]


def test_non_utf8_database_names_the_database_file(tmp_path):
    path = tmp_path / "db.json"
    path.write_bytes(b'{"beds": {"b1": "M\xfcller"}, "capacity": 3}')
    with pytest.raises(DataFileError) as err:
        WardDB.load(path)
    assert str(path) in str(err.value) and "database file is not UTF-8" in str(err.value)


def test_database_errors_name_file_and_field(tmp_path):
    path = tmp_path / "db.json"
    path.write_text('{"beds": {}, "capacity": "many"}', encoding="utf-8")
    with pytest.raises(DataFileError) as err:
        WardDB.load(path)
    assert str(path) in str(err.value) and "'capacity'" in str(err.value)
    path.write_text('{"beds": {}, "capacity": 3', encoding="utf-8")  # truncated
    with pytest.raises(DataFileError, match=r"db\.json: not valid JSON at line 1"):
        WardDB.load(path)


def test_deeply_nested_and_huge_number_json_name_the_file(tmp_path):
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100_000 + "]" * 100_000, encoding="utf-8")
    with pytest.raises(DataFileError) as err:
        read_json_file(deep, "task file")
    assert str(deep) in str(err.value) and "nested too deeply" in str(err.value)
    huge = tmp_path / "huge.json"
    huge.write_text("[" + "9" * 5000 + "]", encoding="utf-8")
    with pytest.raises(DataFileError) as err:
        read_json_file(huge, "task file")
    assert str(huge) in str(err.value)


def test_directory_instead_of_file_names_it(tmp_path):
    folder = tmp_path / "tasks.json"
    folder.mkdir()
    with pytest.raises(DataFileError) as err:
        read_text_file(folder, "task file")
    assert str(folder) in str(err.value) and "cannot read the task file" in str(err.value)


def test_split_file_errors_name_file_and_split(tmp_path):
    path = tmp_path / "split_tasks.json"
    path.write_bytes(b'{"train": ["t1"], "test": ["caf\xe9"]}')
    with pytest.raises(DataFileError, match="split file is not UTF-8"):
        load_split(path)
    path.write_text('{"train": ["t1"], "test": ["t2", 7]}', encoding="utf-8")
    with pytest.raises(DataFileError) as err:
        load_split(path)
    assert str(path) in str(err.value) and "split 'test' entry #1" in str(err.value)
    path.write_text('{"train": "t1"}', encoding="utf-8")
    with pytest.raises(DataFileError, match="split 'train': expected a list"):
        load_split(path)


def test_non_utf8_policy_names_the_policy_file(tmp_path):
    (tmp_path / "policy.md").write_bytes(b"Follow the NICE guideline \x96 always.\n")
    with pytest.raises(DataFileError) as err:
        read_policy(tmp_path)
    assert str(tmp_path / "policy.md") in str(err.value) and "domain policy is not UTF-8" in str(err.value)


def test_domain_store_reports_the_bad_file_among_several(tmp_path):
    package, build = tmp_path / "package", tmp_path / "build"
    package.mkdir()
    build.mkdir()
    (package / "tasks.json").write_text(json.dumps(TASKS), encoding="utf-8")
    (build / "tasks.json").write_bytes(b'[{"id": "t2", "ticket": "\xff"}]')
    store = DomainTaskStore("ward_test", package, build)
    with pytest.raises(DataFileError) as err:
        store.all_tasks()
    assert str(build / "tasks.json") in str(err.value)
    assert str(package / "tasks.json") not in str(err.value)
