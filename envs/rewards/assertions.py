"""Assertions: NL assertions and rubric criteria, graded by rules + embeddings or an LLM judge.

Graders return one `CriterionResult` per criterion with a score in [0, 1] (or None when it
could not be graded). The default is `RuleGrader`; when `HCGYM_JUDGE_ENDPOINT` and
`HCGYM_JUDGE_MODEL` are set (or an `LLMJudge` is passed to `score_episode`), an OpenAI-compatible
chat endpoint judges instead. A judge failure (network, HTTP status, unparseable reply, missing
verdicts) is recorded in `RewardBreakdown.grader_errors` and the affected criteria are graded by
the rules instead: a failure is never silently scored as "not met".

Rule grading of a criterion against everything the agent wrote and called (its sentences, its
submitted answer, and its successful tool calls rendered as "check drug interactions drug x"):
  keyword = clip((recall of the criterion's content words - 0.2) / 0.6)
  semantic = calibrated max cosine between the criterion and the agent's sentences (if available)
  score = max(keyword, semantic)
Polarity must match: a criterion without a negation cue is matched only against sentences
without one ("recommends ibuprofen" is not met by "avoid ibuprofen"). A negative criterion
("does not recommend NSAIDs such as ibuprofen") scores 1 - presence of its positive part in
sentences without negation, where naming half of its content words counts as full presence.

Rubric (HealthBench style): required elements and required tools earn their points times their
score; forbidden elements (and any item with negative points) subtract |points| times their
score; rubric = clip(earned / total positive points). A required tool is met when a successful
call names it.

    assertion = mean(NL scores)                       (only NL assertions)
              = rubric                                (only a rubric)
              = 0.5 * mean(NL scores) + 0.5 * rubric  (both)
"""

from __future__ import annotations

import json
import os
import re
import urllib.error
import urllib.request
from dataclasses import dataclass, field
from typing import Any, Protocol

from envs.core.task import RubricItem
from envs.rewards.similarity import calibrate, grading_tokens, similarity_matrix
from envs.rewards.text import clip01, has_negation, sentences, short
from envs.rewards.view import EpisodeView

MET_THRESHOLD = 0.5
_FILLER = frozenset(grading_tokens(
    "agent model assistant response answer should must will correctly appropriately clearly explicitly "
    "properly the patient's mention mentions mentioned state states stated note notes noted include "
    "includes included recommend recommends recommended provide provides provided identify identifies "
    "identified discuss discusses discussed address addresses addressed ensure ensures also"
))
_NEGATIVE = re.compile(
    r"^\s*(?:the\s+)?(?:agent|model|assistant|response)?\s*(?:does\s+not|doesn't|should\s+not|shouldn't|must\s+not|"
    r"never|avoids?|do\s+not|don't|did\s+not|no)\b\s*",
    re.IGNORECASE,
)


@dataclass
class CriterionResult:
    text: str
    score: float | None            # None: could not be graded
    grader: str                    # "rule", "judge", "tool"
    reason: str = ""

    @property
    def met(self) -> bool | None:
        return None if self.score is None else self.score >= MET_THRESHOLD


class GraderError(RuntimeError):
    """A grader could not grade (endpoint down, bad reply)."""


class AssertionGrader(Protocol):
    name: str

    def grade(self, criteria: list[str], view: EpisodeView) -> list[CriterionResult]:
        """One result per criterion, in order. Raise GraderError when grading is impossible."""
        ...


# -- rules + embeddings ----------------------------------------------------------------------------
class RuleGrader:
    """Keyword recall plus sentence-embedding similarity (no network, no model required)."""

    name = "rule"

    def grade(self, criteria: list[str], view: EpisodeView) -> list[CriterionResult]:
        evidence = _evidence_sentences(view)
        all_tokens = set(grading_tokens(" ".join(evidence)))
        plain = [s for s in evidence if not has_negation(s)]
        plain_tokens = set(grading_tokens(" ".join(plain)))
        positives = [(_NEGATIVE.sub("", c, count=1), bool(_NEGATIVE.match(c))) for c in criteria]
        sims = similarity_matrix([p for p, _ in positives], evidence) if evidence else None
        plain_idx = [i for i, s in enumerate(evidence) if not has_negation(s)]
        results = []
        for i, (positive, is_negative) in enumerate(positives):
            words = [w for w in grading_tokens(positive) if w not in _FILLER] or grading_tokens(positive)
            # polarity must match: "recommends ibuprofen" is not met by "avoid ibuprofen", while
            # "recommends avoiding NSAIDs" is
            plain_only = is_negative or not has_negation(positive)
            pool = plain_tokens if plain_only else all_tokens
            recall = sum(w in pool for w in words) / len(words) if words else 0.0
            # a negative criterion is broken by naming half of what it forbids ("NSAIDs such as ibuprofen")
            keyword = clip01(recall / 0.5) if is_negative else clip01((recall - 0.2) / 0.6)
            semantic = None
            if sims is not None:
                row = sims[i, plain_idx] if plain_only else sims[i]
                semantic = calibrate(float(row.max())) if len(row) else 0.0
            present = max(keyword, semantic or 0.0)
            score = 1.0 - present if is_negative else present
            reason = f"keyword recall {recall:.2f}" + (f", semantic {semantic:.2f}" if semantic is not None else "")
            results.append(CriterionResult(criteria[i], round(score, 4), "rule", reason))
        return results


def _evidence_sentences(view: EpisodeView) -> list[str]:
    out: list[str] = []
    for _, text in view.turn_texts:
        out.extend(sentences(text))
    out.extend(sentences(view.answer_text))
    for ref in view.calls:
        if ref.call.ok and not ({"think", "submit"} & ref.families):
            args = " ".join(f"{k} {v}" for k, v in ref.args.items() if isinstance(v, (str, int, float)))
            out.append(f"{ref.name.replace('_', ' ')} {args}".strip())
    return [s for s in dict.fromkeys(s.strip() for s in out) if s][:400]


# -- LLM judge -------------------------------------------------------------------------------------
_JUDGE_SYSTEM = (
    "You grade a medical AI agent's episode against criteria. For each numbered criterion decide whether "
    "the agent's actions and answer satisfy it (for a criterion describing something to avoid, 'met' means "
    "the described behaviour did occur). Reply with JSON only: {\"verdicts\": [{\"id\": <number>, "
    "\"met\": true|false, \"reason\": \"<short>\"}]} with one verdict per criterion."
)


@dataclass
class LLMJudge:
    """Grades criteria with any OpenAI-compatible chat-completions endpoint (stdlib urllib).

    Args:
        endpoint: Base URL (`http://host:8000/v1`) or the full `.../chat/completions` URL.
        model: Model name sent in the request.
        api_key_env: Name of the environment variable holding the API key (none sent if unset).
        timeout_s: Per-request timeout.
        max_chars: Transcript budget sent to the judge.
    """

    endpoint: str
    model: str
    api_key_env: str = "OPENAI_API_KEY"
    timeout_s: float = 30.0
    max_chars: int = 12_000
    name: str = field(default="judge", init=False)

    @classmethod
    def from_env(cls) -> "LLMJudge | None":
        """`HCGYM_JUDGE_ENDPOINT`, `HCGYM_JUDGE_MODEL`, `HCGYM_JUDGE_API_KEY_ENV`, `HCGYM_JUDGE_TIMEOUT`."""
        endpoint, model = os.environ.get("HCGYM_JUDGE_ENDPOINT"), os.environ.get("HCGYM_JUDGE_MODEL")
        if not endpoint or not model:
            return None
        return cls(endpoint=endpoint, model=model,
                   api_key_env=os.environ.get("HCGYM_JUDGE_API_KEY_ENV", "OPENAI_API_KEY"),
                   timeout_s=float(os.environ.get("HCGYM_JUDGE_TIMEOUT", "30")))

    @property
    def url(self) -> str:
        base = self.endpoint.rstrip("/")
        return base if base.endswith("/chat/completions") else base + "/chat/completions"

    def transcript(self, view: EpisodeView) -> str:
        lines = [f"TASK:\n{short(view.task.ticket, 3000)}"]
        for turn in view.trajectory.turns:
            if turn.message:
                lines.append(f"[agent] {short(turn.message, 1500)}")
            for call in turn.tool_calls:
                lines.append(f"[tool call] {call.name}({short(json.dumps(call.arguments, ensure_ascii=False), 400)})")
                lines.append(f"[tool result] {short(call.result or ('ERROR ' + str(call.error)), 400)}")
        lines.append(f"FINAL ANSWER:\n{short(view.answer_text, 2000)}")
        text = "\n".join(lines)
        return text if len(text) <= self.max_chars else text[: self.max_chars // 2] + "\n...\n" + text[-self.max_chars // 2:]

    def grade(self, criteria: list[str], view: EpisodeView) -> list[CriterionResult]:
        numbered = "\n".join(f"{i + 1}. {c}" for i, c in enumerate(criteria))
        body = {
            "model": self.model, "temperature": 0.0,
            "messages": [{"role": "system", "content": _JUDGE_SYSTEM},
                         {"role": "user", "content": f"{self.transcript(view)}\n\nCRITERIA:\n{numbered}"}],
        }
        headers = {"Content-Type": "application/json"}
        key = os.environ.get(self.api_key_env) if self.api_key_env else None
        if key:
            headers["Authorization"] = f"Bearer {key}"
        request = urllib.request.Request(self.url, data=json.dumps(body).encode(), headers=headers, method="POST")
        try:
            with urllib.request.urlopen(request, timeout=self.timeout_s) as response:
                payload = json.loads(response.read().decode("utf-8"))
            content = payload["choices"][0]["message"]["content"]
        except urllib.error.HTTPError as exc:
            raise GraderError(f"judge {self.url}: HTTP {exc.code} {exc.reason}") from None
        except (urllib.error.URLError, TimeoutError, OSError) as exc:
            raise GraderError(f"judge {self.url}: {type(exc).__name__}: {exc}") from None
        except (ValueError, KeyError, IndexError, TypeError) as exc:
            raise GraderError(f"judge {self.url}: malformed completion ({type(exc).__name__}: {exc})") from None
        verdicts = _parse_verdicts(content, len(criteria))
        return [
            CriterionResult(c, None, "judge", "no verdict") if i not in verdicts
            else CriterionResult(c, verdicts[i][0], "judge", verdicts[i][1])
            for i, c in enumerate(criteria)
        ]


def _parse_verdicts(content: Any, n: int) -> dict[int, tuple[float, str]]:
    if not isinstance(content, str):
        raise GraderError("judge reply has no text content")
    text = content.strip()
    fence = re.search(r"```(?:json)?\s*(.*?)```", text, re.DOTALL)
    if fence:
        text = fence.group(1)
    start, end = text.find("{"), text.rfind("}")
    if start < 0 or end <= start:
        raise GraderError(f"judge reply is not JSON: {short(content, 120)!r}")
    try:
        data = json.loads(text[start:end + 1])
    except json.JSONDecodeError as exc:
        raise GraderError(f"judge reply is not valid JSON ({exc.msg}): {short(content, 120)!r}") from None
    items = data.get("verdicts") if isinstance(data, dict) else None
    if not isinstance(items, list):
        raise GraderError("judge reply has no 'verdicts' list")
    out: dict[int, tuple[float, str]] = {}
    for item in items:
        if not isinstance(item, dict):
            continue
        try:
            index = int(item.get("id")) - 1
        except (TypeError, ValueError):
            continue
        met = item.get("met")
        if 0 <= index < n and isinstance(met, bool):
            score = item.get("score")
            value = float(score) if isinstance(score, (int, float)) and 0 <= score <= 1 else (1.0 if met else 0.0)
            out[index] = (value, str(item.get("reason", ""))[:300])
    return out


def default_grader() -> AssertionGrader:
    return LLMJudge.from_env() or RuleGrader()


# -- rubric and the dimension ----------------------------------------------------------------------
@dataclass
class AssertionOutcome:
    score: float | None                     # the assertion dimension (None: not applicable / ungradable)
    rubric: float | None                    # the rubric score (also used by process)
    nl: list[CriterionResult] = field(default_factory=list)
    rubric_items: list[tuple[RubricItem, CriterionResult]] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)

    def details(self) -> dict[str, Any]:
        return {
            "nl_assertions": [{"text": r.text, "score": r.score, "grader": r.grader, "reason": r.reason} for r in self.nl],
            "rubric": [{"criterion": item.criterion, "kind": item.kind, "points": item.points, "score": r.score,
                        "grader": r.grader} for item, r in self.rubric_items],
            "rubric_score": self.rubric,
        }


_TOOL_TOKEN = re.compile(r"\b[a-z][a-z0-9]*(?:_[a-z0-9]+)+\b")


def _required_tool(item: RubricItem, view: EpisodeView) -> CriterionResult | None:
    """Deterministic grade of a required_tool item; None when it names no tool."""
    called = {c.name.lower() for c in view.calls if c.call.ok}
    text = item.criterion.lower()
    named = set(_TOOL_TOKEN.findall(text))
    if not named:
        words = " ".join(grading_tokens(text))
        named = {n for n in called if " ".join(grading_tokens(n.replace("_", " "))) in words}
        if not named:
            return None
    hit = named & called
    return CriterionResult(item.criterion, 1.0 if hit else 0.0, "tool",
                           f"called {sorted(hit)}" if hit else f"none of {sorted(named)} called")


def _grade(grader: AssertionGrader, criteria: list[str], view: EpisodeView, errors: list[str]) -> list[CriterionResult]:
    if not criteria:
        return []
    try:
        results = grader.grade(criteria, view)
        if len(results) != len(criteria):
            raise GraderError(f"{grader.name} returned {len(results)} results for {len(criteria)} criteria")
    except GraderError as exc:
        errors.append(f"assertion grader {grader.name!r} failed: {exc}; graded by rules instead")
        results = [CriterionResult(c, None, grader.name, "grader failed") for c in criteria]
    missing = [i for i, r in enumerate(results) if r.score is None]
    if missing and grader.name != "rule":
        if not any("failed" in e for e in errors):
            errors.append(f"assertion grader {grader.name!r} gave no verdict for {len(missing)} criteria; graded by rules instead")
        fallback = RuleGrader().grade([criteria[i] for i in missing], view)
        for i, result in zip(missing, fallback):
            result.reason = f"fallback after {grader.name} failure: {result.reason}"
            results[i] = result
    return results


def grade_assertions(view: EpisodeView, grader: AssertionGrader | None = None) -> AssertionOutcome:
    crit = view.task.evaluation_criteria
    if not crit.nl_assertions and not crit.rubric:
        return AssertionOutcome(None, None)
    grader = grader or default_grader()
    errors: list[str] = []
    texts: list[str] = list(crit.nl_assertions)
    rubric_pairs: list[tuple[RubricItem, CriterionResult | None]] = []
    for item in crit.rubric:
        tool = _required_tool(item, view) if item.kind == "required_tool" else None
        rubric_pairs.append((item, tool))
        if tool is None:
            texts.append(item.criterion)
    graded = _grade(grader, texts, view, errors)
    nl = graded[: len(crit.nl_assertions)]
    rest = iter(graded[len(crit.nl_assertions):])
    items = [(item, tool if tool is not None else next(rest)) for item, tool in rubric_pairs]

    rubric_score = None
    if items:
        earned, possible, forbidden_total = 0.0, 0.0, 0.0
        for item, result in items:
            if result.score is None:
                continue
            if item.kind == "forbidden_element" or item.points < 0:
                earned -= abs(item.points) * result.score
                forbidden_total += abs(item.points)
            else:
                earned += item.points * result.score
                possible += item.points
        if possible > 0:
            rubric_score = clip01(earned / possible)
        elif forbidden_total > 0:
            rubric_score = clip01(1.0 + earned / forbidden_total)
    nl_scores = [r.score for r in nl if r.score is not None]
    parts = ([sum(nl_scores) / len(nl_scores)] if nl_scores else []) + ([rubric_score] if rubric_score is not None else [])
    score = sum(parts) / len(parts) if parts else None
    if score is None:
        errors.append("no assertion or rubric criterion could be graded; assertion dimension left out")
    return AssertionOutcome(score, rubric_score, nl, items, errors)
