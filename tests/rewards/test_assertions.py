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


# -- negative criteria: broken only by the forbidden act on its object -----------------------------
@pytest.fixture(scope="module")
def _model():
    from envs.rewards import similarity

    similarity.set_embedder(None)  # lazy loading of the locally installed model (never the network)
    embedder = similarity.get_embedder()
    assert embedder is not None, similarity.embedding_status()
    return embedder, similarity.embedding_status()


@pytest.fixture(params=["keywords", "embeddings"])
def grading(request):
    """Each case graded by keywords only and with the real embedding model (the defects fixed here
    were in the semantic half, which the default reward tests leave out)."""
    from envs.rewards import similarity

    if request.param == "embeddings":
        similarity.set_embedder(*request.getfixturevalue("_model"))
    return request.param


def _di_task(*criteria: str) -> Task:
    return Task(ticket="Patient P1: check the combination and advise.", patient_id="P1", correct_answer="major",
                answer_type="exact", domain="drug_interaction", evaluation_criteria={"nl_assertions": list(criteria)})


def _nl_scores(task: Task, trajectory) -> list[float]:
    return [r.score for r in RuleGrader().grade(task.evaluation_criteria.nl_assertions, EpisodeView(trajectory, task))]


def test_negative_criterion_is_not_broken_by_the_recommended_alternative(grading):
    # di-auth-01's gold: it names ibuprofen only in negated sentences and recommends paracetamol,
    # which the embedding alone read as half "prescribing ibuprofen" (score 0.51)
    task = _di_task("The agent does not prescribe or endorse ibuprofen for this patient.")
    gold = episode(task, turn(call("check_drug_interactions", {"drug_a": "warfarin", "drug_b": "ibuprofen"})), answer="major",
                   reasoning="Warfarin + ibuprofen: ANSM class rule oral anticoagulants + NSAIDs, 'not recommended' (major): "
                             "bleeding risk. Ibuprofen is not appropriate for her. Paracetamol is the alternative: with a "
                             "vitamin K antagonist it is a precaution for use, so if she takes it regularly her INR should "
                             "be monitored more closely.")
    assert _nl_scores(task, gold)[0] >= 0.9
    # negative control: a gold that does prescribe ibuprofen breaks it
    bad = episode(task, turn(call("check_drug_interactions", {"drug_a": "warfarin", "drug_b": "ibuprofen"})), answer="major",
                  reasoning="Paracetamol is not enough for her. Ibuprofen 400 mg three times daily with food is fine.")
    assert _nl_scores(task, bad)[0] < 0.5
    # a "rather than" clause names the forbidden drug without prescribing it
    alternative = episode(task, answer="major", reasoning="Give paracetamol rather than ibuprofen.")
    assert _nl_scores(task, alternative)[0] >= 0.9


def test_negative_criterion_on_a_combination_needs_the_combination(grading):
    # di-auth-02's gold recommends azithromycin instead (0.48 before: "azithromycin with the statin")
    task = _di_task("The agent does not recommend clarithromycin together with simvastatin.")
    gold = episode(task, answer="contraindicated",
                   reasoning="Clarithromycin must not be combined with simvastatin: contraindicated, because clarithromycin "
                             "is a strong CYP3A4 inhibitor that raises simvastatin levels, with a risk of rhabdomyolysis. "
                             "Way out, checked with the tools: azithromycin (only a precaution for use with the statin), "
                             "or suspend the statin during the antibiotic course.")
    assert _nl_scores(task, gold)[0] >= 0.9
    bad = episode(task, turn(call("prescribe_medication", {"drug": "clarithromycin", "dose": "500 mg twice daily"})),
                  answer="minor", reasoning="Clarithromycin 500 mg twice daily; carry on with the simvastatin.")
    assert _nl_scores(task, bad)[0] < 0.5


def test_negative_stop_criterion_against_continue_and_hold(grading):
    # di-auth-30: "does not interrupt dual antiplatelet therapy". Continuing it is the contrary act
    # (an embedding puts "continue DAPT" at 0.81 of "interrupt DAPT"); holding it is the act itself,
    # although "hold" is a negation cue
    task = _di_task("The agent does not interrupt dual antiplatelet therapy to make room for the antibiotic.")
    gold = episode(task, answer="contraindicated",
                   reasoning="Ticagrelor + clarithromycin (strong CYP3A4 inhibitor) is contraindicated. Dual antiplatelet "
                             "therapy is not interrupted for the antibiotic. I propose another antibiotic, amoxicillin or "
                             "doxycycline, after checking its interactions with the tools.")
    assert _nl_scores(task, gold)[0] >= 0.9
    continued = episode(task, answer="contraindicated",
                        reasoning="Continue dual antiplatelet therapy through the antibiotic course; use amoxicillin.")
    assert _nl_scores(task, continued)[0] >= 0.9
    for reasoning in ("Hold dual antiplatelet therapy for the antibiotic course.",
                      "Interrupt the dual antiplatelet therapy for 7 days and give clarithromycin."):
        bad = episode(task, answer="contraindicated", reasoning=reasoning)
        assert _nl_scores(task, bad)[0] < 0.5, reasoning
    # a stop verb that is itself negated is not the act
    kept = episode(task, answer="contraindicated", reasoning="Do not stop dual antiplatelet therapy for the antibiotic.")
    assert _nl_scores(task, kept)[0] >= 0.9


# -- negation scopes over its clause, not the whole sentence ---------------------------------------
_CRITERION = "The report states the assessment category in the impression with its management recommendation."


def _report_episode(task: Task, impression: str, recommendation: str, answer: str):
    # the shape of rad_report_RAD-283's and RAD-273's gold replays: the draft call is one evidence unit
    draft = call("draft_report", {"study_id": "RAD-283", "findings": "lingula: 6 x 2 mm solid nodule",
                                  "impression": impression, "category": answer, "recommendation": recommendation})
    finalize = call("finalize_report", {"study_id": "RAD-283"})
    for record in (draft, finalize):
        record.tool_type = "write"  # as the environment records them: writing the report is the agent's act
    return episode(task, turn(draft), turn(finalize), answer=answer)


def test_negated_category_does_not_negate_the_report_sentence(grading):
    task = Task(ticket="Report study RAD-283.", correct_answer="no routine follow-up", answer_type="exact",
                domain="radiology_report", evaluation_criteria={"nl_assertions": [_CRITERION]})
    fleischner = _report_episode(task, "Assessment category: no routine follow-up. Management: Fleischner 2017: "
                                       "no routine follow-up.", "Fleischner 2017: no routine follow-up.",
                                 "no routine follow-up")
    assert _nl_scores(task, fleischner)[0] >= 0.9
    tirads = _report_episode(task, "Assessment category: TR2. Management: ACR TI-RADS TR2 (not suspicious, 2 points): "
                                   "no FNA.", "ACR TI-RADS TR2 (not suspicious, 2 points): no FNA.", "TR2")
    assert _nl_scores(task, tirads)[0] >= 0.9
    # control: what the negation does reach stays negated ("no routine follow-up" recommends none)
    follow_up = Task(ticket="Report study RAD-283.", correct_answer="no routine follow-up", answer_type="exact",
                     domain="radiology_report",
                     evaluation_criteria={"nl_assertions": ["The report recommends routine follow-up CT of the nodule."]})
    assert _nl_scores(follow_up, fleischner)[0] < 0.5


@pytest.mark.parametrize("said", ["Avoid ibuprofen.", "Ibuprofen: not recommended.", "Ibuprofen should be avoided.",
                                  "Ibuprofen is not appropriate for her.", "Give paracetamol rather than ibuprofen.",
                                  "Ibuprofen: avoid with warfarin."])
def test_avoiding_a_drug_never_meets_recommending_it(said, grading):
    task = _di_task("The agent recommends ibuprofen.")
    assert _nl_scores(task, episode(task, answer="major", reasoning=said))[0] < 0.5
    control = episode(task, answer="major", reasoning="Ibuprofen 400 mg three times daily is appropriate.")
    assert _nl_scores(task, control)[0] >= 0.9


def test_unnegated_keeps_the_clauses_a_negation_does_not_reach():
    from envs.rewards.text import unnegated
    assert unnegated("Assessment category: no routine follow-up.").startswith("Assessment category:")
    assert "ibuprofen" not in unnegated("Give paracetamol rather than ibuprofen.")
    assert "paracetamol" in unnegated("Give paracetamol rather than ibuprofen.")
    assert unnegated("No interaction of concern: start sertraline").endswith("start sertraline")
    for whole in ("Avoid ibuprofen.", "Ibuprofen: not recommended.", "Clarithromycin must not be combined with simvastatin.",
                  "Ibuprofen should be avoided.", "Ibuprofen: avoid with warfarin.", "Stop ibuprofen."):
        assert unnegated(whole) == "", whole
    assert unnegated("Plain sentence.") == "Plain sentence."


def test_an_act_on_another_drug_does_not_break_a_negative_criterion(grading):
    # the verb alone must not break the criterion: prescribing ceftriaxone is not prescribing
    # amoxicillin (cd_case_cd_p13's criterion against another case's replay)
    task = _di_task("The agent does not prescribe amoxicillin.")
    other = episode(task, turn(call("prescribe_medication", {"drug": "ceftriaxone", "dose": "2 g IV daily"})),
                    answer="pyelonephritis", reasoning="Ceftriaxone 2 g IV daily.")
    assert _nl_scores(task, other)[0] >= 0.9
    same = episode(task, turn(call("prescribe_medication", {"drug": "amoxicillin", "dose": "500 mg three times daily"})),
                   answer="otitis media")
    assert _nl_scores(task, same)[0] < 0.5
    # an object named among alternatives: "NSAIDs such as ibuprofen" is broken by naproxen only
    # through the embedding, by ibuprofen always
    nsaid = _di_task("The agent does not recommend NSAIDs such as ibuprofen.")
    assert _nl_scores(nsaid, episode(nsaid, answer="major", reasoning="Ibuprofen 400 mg is fine."))[0] < 0.5


def test_a_remnant_with_another_number_does_not_meet_a_numbered_criterion(grading):
    # "Assigned ESI level 5: no resources needed." now states "Assigned ESI level 5" (the negation
    # reaches only its own clause), which an embedding puts at 0.98 of "Assigns ESI level 3"
    task = Task(ticket="Triage this child.", correct_answer="3", answer_type="exact", domain="triage_emergency",
                evaluation_criteria={"nl_assertions": ["Assigns ESI level 3"]})
    five = episode(task, answer="5", reasoning="Assigned ESI level 5: no resources needed.")
    # keywords: assign, esi, level present, the number (weight 3) missing -> recall 3/6 -> 0.6; the
    # embedding must not lift it (it did to 0.98 without the number check)
    assert _nl_scores(task, five)[0] == pytest.approx(0.6)
    three = episode(task, answer="3", reasoning="Assigned ESI level 3: no immediate threat, two resources expected.")
    assert _nl_scores(task, three)[0] >= 0.9


def test_applying_fleischner_to_a_known_malignancy_breaks_the_criterion(grading):
    # rad_fleischner_* tasks: their one assertion is this negative criterion
    criterion = "The agent does not apply the Fleischner 2017 guideline because the patient has a known malignancy."
    task = Task(ticket="Report study RAD-213 (staging CT, known colorectal cancer).", correct_answer="not applicable",
                answer_type="exact", domain="radiology_report", evaluation_criteria={"nl_assertions": [criterion]})
    applied = _report_episode(task, "Assessment category: no routine follow-up. Management: Fleischner 2017: "
                                    "no routine follow-up.", "Fleischner 2017: no routine follow-up.", "no routine follow-up")
    assert _nl_scores(task, applied)[0] < 0.5
    staged = _report_episode(task, "Pulmonary nodule in a patient with known malignancy: Fleischner does not apply. "
                                   "Compare on the oncologic staging follow-up CT.",
                             "Oncologic staging follow-up; the incidental-nodule guideline does not apply.", "not applicable")
    assert _nl_scores(task, staged)[0] >= 0.9
