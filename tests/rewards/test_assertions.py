"""NL assertions and rubrics: the rule grader, and an LLM judge against a local OpenAI-style server."""

from __future__ import annotations

import json
import threading
from http.server import BaseHTTPRequestHandler, HTTPServer

import pytest

from envs.core.task import Task
from envs.rewards import score_episode
from envs.rewards.assertions import LLMJudge, RuleGrader, grade_assertions
from envs.rewards.view import EpisodeView
from tests.rewards.builders import call, episode, turn

TASK = Task(
    ticket="Patient P1 on warfarin asks for pain relief for knee osteoarthritis.", patient_id="P1",
    correct_answer="acetaminophen", answer_type="exact",
    evaluation_criteria={
        "nl_assertions": ["The agent checks for drug interactions with warfarin",
                          "The agent does not recommend NSAIDs such as ibuprofen"],
        "rubric": [
            {"criterion": "Calls check_drug_interactions", "kind": "required_tool", "points": 2},
            {"criterion": "Recommends acetaminophen as the analgesic", "kind": "required_element", "points": 3},
            {"criterion": "Recommends ibuprofen", "kind": "forbidden_element", "points": 3},
        ],
    },
)


def good_episode():
    return episode(TASK, turn(call("get_patient_info", {"patient_id": "P1"})),
                   turn(call("check_drug_interactions", {"patient_id": "P1", "drug": "acetaminophen"})),
                   answer="acetaminophen",
                   reasoning="Interactions with warfarin checked. Recommend acetaminophen 650 mg as the analgesic; "
                             "avoid NSAIDs like ibuprofen because of bleeding risk. Follow up in two weeks.")


def bad_episode():
    return episode(TASK, turn(call("get_patient_info", {"patient_id": "P1"})),
                   answer="ibuprofen", reasoning="Recommend ibuprofen 400 mg for the knee pain.")


def test_rule_grader_scores_good_and_bad_episodes():
    good = grade_assertions(EpisodeView(good_episode(), TASK), RuleGrader())
    bad = grade_assertions(EpisodeView(bad_episode(), TASK), RuleGrader())
    assert [r.met for r in good.nl] == [True, True]
    assert [r.met for r in bad.nl] == [False, False]
    assert good.rubric == pytest.approx(1.0)
    # bad: tool not called (0/2), acetaminophen absent (0/3), ibuprofen recommended (-3) -> clipped at 0
    assert bad.rubric == 0.0
    assert good.score == pytest.approx(1.0) and bad.score == 0.0
    assert good.errors == [] and bad.errors == []


def test_rubric_points_weighting():
    task = TASK.model_copy(update={"evaluation_criteria": TASK.evaluation_criteria.model_copy(update={"nl_assertions": []})})
    # "paracetamol" used to stand for a missing element here; it is acetaminophen's other name (the
    # grader now reads both as one keyword), so a different drug plays that part
    half = episode(task, turn(call("check_drug_interactions", {"patient_id": "P1"})), answer="tramadol",
                   reasoning="Checked interactions.")
    outcome = grade_assertions(EpisodeView(half, task), RuleGrader())
    assert [r.score for _, r in outcome.rubric_items][0] == 1.0
    assert outcome.rubric == pytest.approx(2 / 5)


class _Judge(BaseHTTPRequestHandler):
    mode = "ok"
    seen: list[dict] = []

    def do_POST(self):  # noqa: N802
        length = int(self.headers["Content-Length"])
        body = json.loads(self.rfile.read(length))
        type(self).seen.append({"path": self.path, "body": body, "auth": self.headers.get("Authorization")})
        if self.mode == "http500":
            self.send_response(500)
            self.end_headers()
            self.wfile.write(b"boom")
            return
        n = body["messages"][1]["content"].split("CRITERIA:\n", 1)[1].count("\n") + 1
        if self.mode == "ok":
            content = json.dumps({"verdicts": [{"id": i + 1, "met": i % 2 == 0, "reason": "judged"} for i in range(n)]})
        elif self.mode == "fenced_partial":
            content = "```json\n" + json.dumps({"verdicts": [{"id": 1, "met": True}]}) + "\n```"
        else:
            content = "I think they all pass."
        payload = {"id": "x", "object": "chat.completion", "model": body["model"],
                   "choices": [{"index": 0, "message": {"role": "assistant", "content": content}, "finish_reason": "stop"}]}
        data = json.dumps(payload).encode()
        self.send_response(200)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(data)))
        self.end_headers()
        self.wfile.write(data)

    def log_message(self, *args):
        pass


@pytest.fixture()
def judge_server():
    server = HTTPServer(("127.0.0.1", 0), _Judge)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    _Judge.seen = []
    _Judge.mode = "ok"
    yield f"http://127.0.0.1:{server.server_address[1]}/v1"
    server.shutdown()
    server.server_close()


def test_llm_judge_grades_through_an_openai_compatible_endpoint(judge_server, monkeypatch):
    monkeypatch.setenv("JUDGE_KEY", "sk-test")
    judge = LLMJudge(endpoint=judge_server, model="judge-model", api_key_env="JUDGE_KEY", timeout_s=5)
    outcome = grade_assertions(EpisodeView(good_episode(), TASK), judge)
    request = _Judge.seen[0]
    assert request["path"] == "/v1/chat/completions" and request["auth"] == "Bearer sk-test"
    assert request["body"]["model"] == "judge-model" and request["body"]["temperature"] == 0.0
    # 4 criteria go to the judge (2 NL + 2 text rubric items; the required tool is checked directly)
    assert [r.score for r in outcome.nl] == [1.0, 0.0]
    assert [r.grader for r in outcome.nl] == ["judge", "judge"]
    assert [r.grader for _, r in outcome.rubric_items] == ["tool", "judge", "judge"]
    assert outcome.errors == []


def test_judge_configured_by_environment_variables(judge_server, monkeypatch):
    monkeypatch.setenv("HCGYM_JUDGE_ENDPOINT", judge_server)
    monkeypatch.setenv("HCGYM_JUDGE_MODEL", "env-model")
    breakdown = score_episode(good_episode(), TASK)
    assert _Judge.seen and _Judge.seen[0]["body"]["model"] == "env-model"
    assert breakdown.details["assertion"]["nl_assertions"][0]["grader"] == "judge"


@pytest.mark.parametrize("mode, message", [("http500", "HTTP 500"), ("prose", "not JSON")])
def test_judge_failure_is_reported_and_graded_by_rules(judge_server, mode, message):
    _Judge.mode = mode
    judge = LLMJudge(endpoint=judge_server, model="m", timeout_s=5)
    breakdown = score_episode(good_episode(), TASK, grader=judge)
    assert any(message in e and "graded by rules instead" in e for e in breakdown.grader_errors)
    # never silently "not met": the rule grader's verdicts stand in
    graded = breakdown.details["assertion"]["nl_assertions"]
    assert [g["score"] for g in graded] == [1.0, 1.0]
    assert breakdown.assertion == pytest.approx(1.0)


def test_judge_missing_verdicts_fall_back_per_criterion(judge_server):
    _Judge.mode = "fenced_partial"
    outcome = grade_assertions(EpisodeView(good_episode(), TASK), LLMJudge(endpoint=judge_server, model="m", timeout_s=5))
    assert outcome.nl[0].grader == "judge" and outcome.nl[0].score == 1.0
    assert outcome.nl[1].grader == "rule" and "fallback" in outcome.nl[1].reason
    assert any("no verdict for 3 criteria" in e for e in outcome.errors)


def test_unreachable_judge_is_an_error_not_a_zero():
    judge = LLMJudge(endpoint="http://127.0.0.1:9/v1", model="m", timeout_s=2)
    breakdown = score_episode(bad_episode(), TASK, grader=judge)
    assert any("URLError" in e or "ConnectionRefused" in e for e in breakdown.grader_errors)
    assert breakdown.assertion == 0.0  # the rules' verdict on a bad episode, reported with the error
