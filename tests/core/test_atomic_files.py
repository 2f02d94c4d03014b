"""Atomic writes used by checkpoints, evaluation results, the KB and the EHR store: a failed write
leaves the previous file and no temporary file behind."""

from __future__ import annotations

import pytest

from envs.core.files import replace_atomic, write_text_atomic


def test_a_failed_write_keeps_the_old_file_and_removes_its_temp(tmp_path):
    target = tmp_path / "results.json"
    write_text_atomic(target, "old")

    def half_then_fail(tmp):
        tmp.write_text("half a fi", encoding="utf-8")
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        replace_atomic(target, half_then_fail)
    assert target.read_text(encoding="utf-8") == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results.json"]


def test_the_eval_results_store_and_kb_json_write_through_it(tmp_path, monkeypatch):
    import kb_service.engines as engines

    calls = []
    original = engines.write_text_atomic
    monkeypatch.setattr(engines, "write_text_atomic", lambda path, text: calls.append(path) or original(path, text))
    engines.write_json(tmp_path / "meta.json", {"k": 1})
    assert calls == [tmp_path / "meta.json"] and (tmp_path / "meta.json").read_text().startswith("{")
    assert [p.name for p in tmp_path.iterdir()] == ["meta.json"]
