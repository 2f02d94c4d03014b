"""The viewer's JSON API and file handling, over HTTP on 127.0.0.1 (no browser needed)."""

from __future__ import annotations

import json
import urllib.error
import urllib.request

import pyarrow.parquet as pq
import pytest

from viewer.data import EpisodeQuery, ViewerError, discover

pytestmark = pytest.mark.ray


def get(served, path: str) -> tuple[int, object]:
    try:
        with urllib.request.urlopen(served.url.rstrip("/") + path, timeout=30) as response:
            body = response.read()
            status = response.status
    except urllib.error.HTTPError as error:
        body, status = error.read(), error.code
    try:
        return status, json.loads(body)
    except json.JSONDecodeError:
        return status, body.decode("utf-8", "replace")


def test_it_listens_on_loopback_only(served):
    host, _ = served.httpd.server_address[:2]
    assert host == "127.0.0.1" and served.url.startswith("http://127.0.0.1:")


def test_bad_requests_get_a_400_naming_what_was_wrong(served, trained_run):
    status, body = get(served, "/api/episodes?source=s0&reward_min=abc")
    assert status == 400 and "reward_min" in body["error"]
    status, body = get(served, "/api/episodes?source=s0&reward_min=nan")
    assert status == 400 and "reward_min" in body["error"]
    status, body = get(served, "/api/episodes?source=s0&colour=red")
    assert status == 400 and "colour" in body["error"]
    status, body = get(served, "/api/episodes?source=s0&limit=100000")
    assert status == 400 and "limit" in body["error"]
    status, body = get(served, "/api/episodes?source=nope")
    assert status == 400 and "'nope'" in body["error"]
    status, body = get(served, "/api/run/episode?source=s0&file=999&row=0")
    assert status == 400 and "999" in body["error"]
    status, body = get(served, "/api/run/episode?source=s0&file=x&row=0")
    assert status == 400 and "file" in body["error"]
    status, body = get(served, "/api/nothing")
    assert status == 404
    # the server keeps serving after all of that
    status, body = get(served, "/api/sources")
    assert status == 200 and len(body) == 4


def test_static_files_never_leave_the_static_folder(served):
    for path in ("/static/../server.py", "/static/%2e%2e/server.py", "/../../etc/passwd", "/static/..%2fdata.py"):
        status, _ = get(served, path)
        assert status == 404, path
    status, body = get(served, "/")
    assert status == 200 and "<title>" in body


def test_the_episode_table_counts_what_the_files_hold(served, trained_run):
    run = next(s for s in served.app.sources.values() if s.path == trained_run.resolve())
    files = sorted((trained_run / "trajectories").glob("*.parquet"))
    rewards = [r for p in files for r in pq.read_table(p, columns=["reward"]).column("reward").to_pylist()]
    page = run.episodes(EpisodeQuery(part="train", reward_max=0.25, limit=7))
    assert page["matched"] == sum(r <= 0.25 for r in rewards)
    assert len(page["rows"]) == min(7, page["matched"])
    assert all(row["reward"] <= 0.25 and row["part"] == "train" for row in page["rows"])
    # every row points at its own record: the same sample id in that file's row
    for row in page["rows"]:
        episode = run.episode(row["file"], row["row"])
        assert episode["sample_id"] == row["sample_id"]


def test_error_kind_and_severity_filters_use_the_episode_records(served, gold_run, tmp_path):
    from learner.metrics import read_samples, write_samples

    samples, _ = read_samples(gold_run / "trajectories" / "step_000001.parquet")
    # a failed call and a parse error, recorded by the real env on a real episode
    bad = samples[0].model_copy(deep=True)
    bad.sample_id += ":bad"
    bad.episode.turns[0].tool_calls[0].error = "no such patient"
    bad.episode.turns[0].tool_calls[0].error_kind = "tool_error"
    bad.episode.turns[0].parse_errors.append("unterminated <tool_call>")
    bad.episode.reward_details["violations"] = [{"severity": 4, "pattern_id": "x"}]
    run = tmp_path / "run"
    write_samples([*samples, bad], run / "trajectories" / "step_000001.parquet", step=1)
    (source,) = discover([run])
    assert [r["sample_id"] for r in source.episodes(EpisodeQuery(error_kind="tool_error"))["rows"]] == [bad.sample_id]
    assert [r["sample_id"] for r in source.episodes(EpisodeQuery(error_kind="parse_error"))["rows"]] == [bad.sample_id]
    assert [r["sample_id"] for r in source.episodes(EpisodeQuery(min_severity=3))["rows"]] == [bad.sample_id]
    assert source.episodes(EpisodeQuery(min_severity=5))["matched"] == 0


def test_discover_names_a_folder_that_is_neither(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(ViewerError, match="empty.*neither a run folder"):
        discover([tmp_path / "empty"])
    with pytest.raises(ViewerError, match="not a folder"):
        discover([tmp_path / "missing"])


def test_a_half_written_metrics_file_still_shows(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    (run / "metrics.jsonl").write_text('{"step": 1, "accuracy": 0.5}\n{"step": 2, "accur', encoding="utf-8")
    (source,) = discover([run])
    assert source.metrics()["train"] == [{"step": 1, "accuracy": 0.5}]
    assert source.episodes(EpisodeQuery())["total"] == 0


def test_nan_metrics_are_written_as_null_and_read_back_as_nan(tmp_path):
    import math

    from learner.metrics import MetricsSink, read_metrics

    logger = MetricsSink(tmp_path, run_name="t", tensorboard=False, ray_metrics=False)
    logger.write({"step": 1, "kl_teacher": float("nan"), "accuracy": 0.5, "grad_norm": float("inf")})
    line = (tmp_path / "metrics.jsonl").read_text(encoding="utf-8").strip()
    assert json.loads(line) == {"step": 1, "kl_teacher": None, "accuracy": 0.5, "grad_norm": None}
    (row,) = read_metrics(tmp_path)
    assert math.isnan(row["kl_teacher"]) and row["accuracy"] == 0.5
    (source,) = discover([tmp_path])
    assert source.metrics()["train"][0]["kl_teacher"] is None  # the page gets JSON null, not NaN
