"""Assertions: NL assertions and rubric criteria, graded by rules + embeddings or an LLM judge.

Graders return one `CriterionResult` per criterion with a score in [0, 1] (or None when it
could not be graded). The default is `RuleGrader`; when `HCGYM_JUDGE_ENDPOINT` and
`HCGYM_JUDGE_MODEL` are set (or an `LLMJudge` is passed to `score_episode`), an OpenAI-compatible
chat endpoint judges instead. A judge failure (network, HTTP status, unparseable reply, missing
verdicts) is recorded in `RewardBreakdown.grader_errors` and the affected criteria are graded by
the rules instead: a failure is never silently scored as "not met".

Rule grading of a criterion against the episode's evidence: the agent's sentences, its submitted
answer, its successful tool calls rendered as "check drug interactions drug x", and what those
calls returned (JSON results flattened to one line per object, text split into sentences: what
the agent established with its tools):
  recall = share of the criterion's keywords in the evidence, a number weighing 3 ("ESI level 2"
           is not met by "esi_level 3"), or of the keywords outside its parentheses if higher (a
           gloss such as "(or equivalent tests)" elaborates); keywords are stemmed content words in the canonical
           wording of `equivalence.canonical` ("ECG" = "electrocardiogram", "6-12 months" =
           "6 to 12 months")
  keyword = clip((recall - 0.2) / (0.7 - 0.2))
  semantic = calibrated max cosine between the criterion and the evidence units (if available)
             holding every number of the criterion (an embedding does not tell "ESI level 5"
             from "ESI level 3")
  score = max(keyword, semantic)
Polarity must match: a criterion without a negation cue is matched only against what the evidence
states without negation ("recommends ibuprofen" is not met by "avoid ibuprofen"). A negation scopes
over its clause (`text.unnegated`): a cue that takes an object ("no", "avoid", "without", "rather
than", ...) negates that object up to the end of its clause, so "Assessment category: no routine
follow-up" still states the category; any other cue ("not", "must not", "contraindicated"), or an
object cue with nothing after it ("ibuprofen should be avoided"), negates its whole sentence,
subject included ("ibuprofen: not recommended", "ibuprofen is not appropriate").
A negative criterion ("does not recommend NSAIDs such as ibuprofen") scores 1 - presence of its
positive part (the forbidden act) in what the agent itself said or did (its sentences and answer
without negation, and its acting calls: write tools, prescribing, orders, escalation...), not in
read calls or their results (checking an interaction with sildenafil is not prescribing it);
naming half of its keywords counts as full presence. Only the agent's units that name the act's
object count (a keyword of the phrase after the act verbs, up to its first adjunct: "ibuprofen" in
"prescribe or endorse ibuprofen for this patient", "dual antiplatelet therapy" in "interrupt dual
antiplatelet therapy to make room for the antibiotic"; either alternative of "NSAIDs such as
ibuprofen"), so a sentence recommending the alternative (paracetamol, azithromycin), which an
embedding reads as close to the forbidden drug, or prescribing another drug cannot break it; a
unit doing the contrary act on the object does not count either ("continue dual antiplatelet
therapy" against "interrupt dual antiplatelet therapy"), while a stop-type act is done by a stop verb that is itself a negation cue
("hold DAPT"), unless that verb is negated ("do not stop DAPT").
`RuleGrader(use_observations=False)` leaves tool results out: it grades only the agent's
text, its answer and its calls (the baseline of `bench/assertion_calibration.py`).

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
from envs.rewards.equivalence import canonical
from envs.rewards.similarity import calibrate, grading_tokens, similarity_matrix
from envs.rewards.text import STOPWORDS, clip01, has_negation, negated, sentences, short, tokens, unnegated
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
    """Keyword recall plus sentence-embedding similarity (no network, no model required).

    Args:
        use_observations: Count what the agent's successful tool calls returned as evidence for
            positive criteria (what the agent established in the episode). False grades only the
            agent's text, its answer and its calls (the baseline `bench/assertion_calibration.py` compares
            against).
    """

    name = "rule"

    def __init__(self, use_observations: bool = True) -> None:
        self.use_observations = use_observations

    def grade(self, criteria: list[str], view: EpisodeView) -> list[CriterionResult]:
        said = _evidence_sentences(view)
        observed = _observation_sentences(view) if self.use_observations else []
        evidence = list(dict.fromkeys(said + observed))[:_MAX_EVIDENCE]
        all_tokens = set(_keyword_tokens(evidence))
        # what each unit states without negation: a negation scopes over its clause, so "Assessment
        # category: no routine follow-up" still states the category, while "avoid ibuprofen" and
        # "ibuprofen is not appropriate" state nothing about ibuprofen (text.unnegated)
        plain_of = {s: unnegated(s) for s in evidence}
        plain = [p for p in plain_of.values() if p]
        plain_tokens = set(_keyword_tokens(plain))
        # the part left of a partly negated unit is a unit of its own for the embedding
        units = list(dict.fromkeys(evidence + plain))
        plain_set = set(plain)
        plain_idx = [i for i, u in enumerate(units) if u in plain_set]
        # what a negative criterion forbids is present only in what the agent itself wrote or did
        # (an interaction check naming sildenafil, or a result listing it, is not prescribing it)
        own = list(dict.fromkeys(_said_only(view) + _acting_sentences(view)))
        own_plain = list(dict.fromkeys(p for p in map(unnegated, own) if p))
        positives = [(_NEGATIVE.sub("", c, count=1), bool(_NEGATIVE.match(c))) for c in criteria]
        # a stop-type forbidden act ("interrupt dual antiplatelet therapy") is also done by a
        # sentence whose stop verb is itself a negation cue ("Hold DAPT", "stop ticagrelor")
        stopping = [s for s in own if _stop_verb_used(s)] if any(
            neg and _STOP_VERBS.search(p.lower()) for p, neg in positives) else []
        own_units = list(dict.fromkeys(own_plain + stopping))
        sims = similarity_matrix([p for p, _ in positives], units) if units else None
        token_sets: dict[int, set[str]] = {}

        def unit_tokens(j: int) -> set[str]:
            if j not in token_sets:
                token_sets[j] = set(_keyword_tokens([units[j]]))
            return token_sets[j]

        own_sims = similarity_matrix([p for p, _ in positives], own_units) if own_units else None
        results = []
        for i, (positive, is_negative) in enumerate(positives):
            words = [w for w in _keyword_tokens([positive]) if w not in _FILLER] or _keyword_tokens([positive])
            semantic = None
            if is_negative:
                pool = _forbidden_act_units(positive, own_plain, stopping)
                pool_tokens = set(_keyword_tokens(pool))
                recall = sum(w in pool_tokens for w in words) / len(words) if words else 0.0
                # a negative criterion is broken by naming half of what it forbids ("NSAIDs such as ibuprofen")
                keyword = clip01(recall / 0.5)
                if own_sims is not None:
                    chosen = set(pool)
                    idx = [j for j, u in enumerate(own_units) if u in chosen]
                    semantic = calibrate(float(own_sims[i, idx].max())) if idx else 0.0
                elif sims is not None:
                    semantic = 0.0
            else:
                # polarity must match: "recommends ibuprofen" is not met by "avoid ibuprofen", while
                # "recommends avoiding NSAIDs" is
                plain_only = not has_negation(positive)
                pool = plain_tokens if plain_only else all_tokens
                # a parenthesised gloss ("(or equivalent confirmatory tests)", "(shock index > 1)")
                # elaborates the requirement: meeting the main clause is enough
                main = [w for w in _keyword_tokens([_PAREN.sub(" ", positive)]) if w not in _FILLER]
                recall = max(_weighted_recall(words, pool), _weighted_recall(main, pool) if main else 0.0)
                keyword = clip01((recall - KEYWORD_FLOOR) / (KEYWORD_FULL - KEYWORD_FLOOR))
                if sims is not None:
                    idx = plain_idx if plain_only else range(len(evidence))
                    # an embedding does not tell "ESI level 5" from "ESI level 3": a unit lacking a
                    # number of the criterion is no semantic evidence for it (as NUMBER_WEIGHT for keywords)
                    numbers = {w for w in (main or words) if any(ch.isdigit() for ch in w)}
                    if numbers:
                        idx = [j for j in idx if numbers <= unit_tokens(j)]
                    semantic = calibrate(float(sims[i, list(idx)].max())) if len(idx) else 0.0
            present = max(keyword, semantic or 0.0)
            score = 1.0 - present if is_negative else present
            reason = f"keyword recall {recall:.2f}" + (f", semantic {semantic:.2f}" if semantic is not None else "")
            results.append(CriterionResult(criteria[i], round(score, 4), "rule", reason))
        return results


#: Verbs of a negative criterion's forbidden act, not its object: "prescribe or endorse ibuprofen"
#: is about ibuprofen, and a sentence that does not name ibuprofen cannot be prescribing it.
_ACT_WORDS = frozenset(grading_tokens(
    "prescribe prescribes prescribed prescribing endorse endorses endorsed endorsing give gives given giving "
    "administer administers administered start starts started starting initiate initiates initiated begin begins "
    "continue continues continued maintain maintains keep keeps interrupt interrupts interrupted interrupting "
    "stop stops stopped stopping discontinue discontinues discontinued hold holds withhold withholds suspend "
    "suspends suspended pause pauses paused cease ceases omit omits omitted order orders ordered perform "
    "performs performed use uses used using combine combines combined suggest suggests suggested advise "
    "advises advised offer offers offered make makes made take takes add adds added switch switches switched "
    "repeat repeats repeated apply applies applied activate activates activated together concomitantly alongside"
))
#: Where the object of the forbidden act ends: a preposition or conjunction opening an adjunct
#: ("to make room for the antibiotic", "before arrival", "because the patient has ...").
_OBJECT_END = frozenset(tokens(" ".join(STOPWORDS - {"a", "an", "the", "or", "and", "other", "any", "all", "such"})
                               + " before after during because since until despite unless while whilst beyond"))
_ALTERNATIVES = re.compile(r",|\bor\b|\band\b|\bsuch as\b|\blike\b|\bincluding\b|\be\.g\.")


def _act_objects(positive: str) -> list[set[str]]:
    """The object of a negative criterion's forbidden act, as its alternatives' keyword sets: the
    content words after the act verbs up to the first adjunct ("interrupt dual antiplatelet therapy
    to make room for the antibiotic" -> [{dual, antiplatelet, therapy}]; "give piperacillin-
    tazobactam or another penicillin after ..." -> [{piperacillin, tazobactam}, {penicillin}];
    "NSAIDs such as ibuprofen" -> [{nsaid}, {ibuprofen}]). [] when the act names no object
    ("does not discharge the patient")."""
    phrase = re.split(r"[:;.()\[\]]", positive, maxsplit=1)[0].lower()
    objects: list[set[str]] = []
    for part in _ALTERNATIVES.split(phrase):
        words: list[str] = []
        ended = False
        for raw in tokens(part):
            stemmed = grading_tokens(raw)
            is_act = not stemmed or stemmed[0] in _ACT_WORDS or stemmed[0] in _FILLER
            if not words and (is_act or raw in STOPWORDS or raw == "another"):
                continue  # the verbs and determiners before the object
            if raw in _OBJECT_END or (words and stemmed and stemmed[0] in _ACT_WORDS):
                ended = True
                break
            if stemmed:
                words.append(raw)
        keys = set(_keyword_tokens([" ".join(words)])) - _FILLER
        if keys:
            objects.append(keys)
        if ended and objects:
            break
    return objects


_STOP_VERBS = re.compile(r"\b(?:interrupt\w*|stop(?:s|ped|ping)?|discontinu\w*|hold(?:s|ing)?|held|withh\w*|suspend\w*|"
                         r"paus\w*|ceas\w*|omit\w*)\b")
_CONTINUE_VERBS = re.compile(r"\b(?:continu\w*|maintain\w*|keep(?:s|ing)?|kept|carr(?:y|ies|ied) on|remains? on)\b")


def _stop_verb_used(sentence: str) -> bool:
    """The sentence stops something: a stop verb not itself negated ("hold DAPT", not "do not hold DAPT")."""
    low = sentence.lower()
    return any(not negated(low, m.start()) for m in _STOP_VERBS.finditer(low))


def _forbidden_act_units(positive: str, own_plain: list[str], stopping: list[str]) -> list[str]:
    """The agent's own units that can break the negative criterion whose forbidden act is `positive`:
    those naming its object (a keyword of one of its alternatives, `_act_objects`: "ibuprofen" in
    "prescribe or endorse ibuprofen"), so the gold's sentences about the alternative it
    recommends (paracetamol, azithromycin), which an embedding reads as close to the forbidden drug,
    do not count; and not those doing the contrary act ("continue dual antiplatelet therapy" is not
    "interrupt dual antiplatelet therapy", nor the reverse), which an embedding cannot tell apart."""
    low = positive.lower()
    stop_act, continue_act = bool(_STOP_VERBS.search(low)), bool(_CONTINUE_VERBS.search(low))
    objects = _act_objects(positive)
    out = []
    for unit in dict.fromkeys(own_plain + (stopping if stop_act else [])):
        # naming the object at all: "Per the ACR/Fleischner recommendation" names "Fleischner 2017
        # guideline"; the act's adjuncts are not its object ("to make room for the antibiotic")
        if objects and not any(alternative & set(_keyword_tokens([unit])) for alternative in objects):
            continue
        u = unit.lower()
        does_stop, does_continue = bool(_STOP_VERBS.search(u)), bool(_CONTINUE_VERBS.search(u))
        if (stop_act and does_continue and not does_stop) or (continue_act and does_stop and not does_continue):
            continue
        out.append(unit)
    return out


def _keyword_tokens(texts: list[str]) -> list[str]:
    """Stemmed content tokens of texts in the canonical wording of `equivalence.canonical`, so that
    an abbreviation and its expansion ("ECG", "CT", "MgSO4", "FNA") or two writings of one quantity
    or interval ("6 to 12 months", "6-12 months") count as the same keyword."""
    return [t for text in texts for t in grading_tokens(canonical(text[:2000]))]


def _weighted_recall(words: list[str], pool: set[str]) -> float:
    """Share of the criterion's keywords present, a number counting `NUMBER_WEIGHT` times: "assigns
    ESI level 2" is not met by "assign triage level esi_level 3" although three of its four words are."""
    if not words:
        return 0.0
    weights = [NUMBER_WEIGHT if any(ch.isdigit() for ch in w) else 1.0 for w in words]
    return sum(wt for w, wt in zip(words, weights) if w in pool) / sum(weights)


NUMBER_WEIGHT = 3.0
_PAREN = re.compile(r"\([^()]*\)")
#: Keyword recall at or below the floor scores 0, at or above `KEYWORD_FULL` scores 1.
KEYWORD_FLOOR, KEYWORD_FULL = 0.2, 0.7
_MAX_EVIDENCE = 600
_MAX_OBSERVATION_UNITS = 40  # per call: a long result (a whole chart) must not drown the rest


def _said_only(view: EpisodeView) -> list[str]:
    out: list[str] = []
    for _, text in view.turn_texts:
        out.extend(sentences(text))
    out.extend(sentences(view.answer_text))
    return [s for s in dict.fromkeys(s.strip() for s in out) if s]


def _render_call(ref) -> str:
    args = " ".join(f"{k} {v}" for k, v in ref.args.items() if isinstance(v, (str, int, float)))
    return f"{ref.name.replace('_', ' ')} {args}".strip()


def _evidence_sentences(view: EpisodeView) -> list[str]:
    out = _said_only(view)
    for ref in view.calls:
        if ref.call.ok and not ({"think", "submit"} & ref.families):
            out.append(_render_call(ref))
    return [s for s in dict.fromkeys(s.strip() for s in out) if s][:400]


def _acting_sentences(view: EpisodeView) -> list[str]:
    """Calls that change the world (prescribe, order, escalate, document), attempted or not:
    what a negative criterion ("does not prescribe X") can be broken by."""
    return [_render_call(ref) for ref in view.calls
            if ref.call.tool_type == "write" or (ref.families & _ACTING_FAMILIES)]


_ACTING_FAMILIES = frozenset({"prescribing", "place_order", "escalation", "discharge", "discontinue", "invasive",
                              "triage", "diagnosis", "resuscitation", "intubation", "follow_up"})


def _flatten(value: Any, prefix: str, out: list[str], depth: int = 0) -> None:
    if len(out) >= _MAX_OBSERVATION_UNITS or depth > 6:
        return
    if isinstance(value, dict):
        scalars = [f"{k.replace('_', ' ')} {v}" for k, v in value.items()
                   if isinstance(v, (str, int, float, bool)) and not isinstance(v, bool) or isinstance(v, bool) and v]
        if scalars:
            out.append((prefix + " " + "; ".join(str(s) for s in scalars)).strip())
        for k, v in value.items():
            if isinstance(v, (dict, list)):
                _flatten(v, f"{prefix} {str(k).replace('_', ' ')}".strip(), out, depth + 1)
    elif isinstance(value, list):
        if value and all(isinstance(v, (str, int, float)) for v in value):
            out.append(f"{prefix} {', '.join(str(v) for v in value)}".strip())
        else:
            for v in value:
                _flatten(v, prefix, out, depth + 1)
    elif isinstance(value, (str, int, float)):
        out.extend(f"{prefix} {s}".strip() for s in sentences(str(value)))


def _observation_sentences(view: EpisodeView) -> list[str]:
    """What the agent's successful calls returned, as short units: JSON results flattened to one
    line per object ("severity major; mechanism ..."), text results split into sentences."""
    out: list[str] = []
    for ref in view.calls:
        call = ref.call
        if not call.ok or not call.result or ({"think", "submit"} & ref.families):
            continue
        units: list[str] = []
        text = call.result.strip()
        try:
            data = json.loads(text) if text[:1] in "[{" else None
        except (ValueError, RecursionError):
            data = None
        if data is not None:
            _flatten(data, "", units)
        else:
            units = sentences(text)[:_MAX_OBSERVATION_UNITS]
        out.extend(" ".join(u.split())[:400] for u in units if u.strip())
    return [s for s in dict.fromkeys(out) if s]


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
