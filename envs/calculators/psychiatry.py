"""Psychiatric and substance-use instruments: PHQ-9, GAD-7, C-SSRS screener, EPDS, AUDIT-C,
CAGE and CIWA-Ar.

Questionnaires take their answers as already-scored integers in the order printed on the form
(e.g. PHQ-9 answers 0 "not at all" to 3 "nearly every day"). EPDS items 3 and 5-10 are printed
with reversed wording; the caller passes the scored value (0-3) of each item, as on the scoring
key, not the position of the ticked box. Safety items (PHQ-9 item 9, EPDS item 10, any C-SSRS
ideation) are reported in ``flags`` whatever the total, because they need action on their own.
"""

from __future__ import annotations

from typing import Literal

from ._core import (
    CalculatorInputError,
    ScoreResult,
    check_bool,
    check_choice,
    check_int,
    check_responses,
    make_result,
)


def administer_phq9(responses: list[int]) -> ScoreResult:
    """Patient Health Questionnaire-9 depression severity (0-27), flagging item 9 (self-harm thoughts).

    Args:
        responses: The nine item answers in form order, each an integer 0-3 (0 not at all,
            1 several days, 2 more than half the days, 3 nearly every day).
    """
    fn = "administer_phq9"
    items = check_responses(fn, "responses", responses, 9, 0, 3)
    total = sum(items)
    if total >= 20:
        cat = "severe"
    elif total >= 15:
        cat = "moderately severe"
    elif total >= 10:
        cat = "moderate"
    elif total >= 5:
        cat = "mild"
    else:
        cat = "minimal"
    flags: tuple[str, ...] = ()
    text = f"PHQ-9 {total}/27: {cat} depression"
    if items[8] > 0:
        flags = ("item 9 positive: thoughts of death or self-harm",)
        text += "; item 9 is positive: assess suicide risk today (e.g. C-SSRS)"
    return make_result(
        "PHQ-9",
        total,
        "points",
        cat,
        text + ".",
        {f"item_{k + 1}": v for k, v in enumerate(items)},
        "Kroenke K, Spitzer RL, Williams JBW. The PHQ-9: validity of a brief depression severity measure. "
        "J Gen Intern Med 2001;16:606-613.",
        flags,
    )


def administer_gad7(responses: list[int]) -> ScoreResult:
    """Generalized Anxiety Disorder-7 severity (0-21).

    Args:
        responses: The seven item answers in form order, each an integer 0-3 (0 not at all,
            1 several days, 2 more than half the days, 3 nearly every day).
    """
    fn = "administer_gad7"
    items = check_responses(fn, "responses", responses, 7, 0, 3)
    total = sum(items)
    cat = "severe" if total >= 15 else "moderate" if total >= 10 else "mild" if total >= 5 else "minimal"
    tail = "; >= 10 warrants further evaluation for an anxiety disorder" if total >= 10 else ""
    return make_result(
        "GAD-7",
        total,
        "points",
        cat,
        f"GAD-7 {total}/21: {cat} anxiety{tail}.",
        {f"item_{k + 1}": v for k, v in enumerate(items)},
        "Spitzer RL, Kroenke K, Williams JBW, Lowe B. A brief measure for assessing generalized anxiety "
        "disorder: the GAD-7. Arch Intern Med 2006;166:1092-1097.",
    )


_BEHAVIOR = ("never", "over_3_months_ago", "past_3_months")


def assess_suicide_risk(
    wish_to_be_dead: bool,
    suicidal_thoughts: bool,
    thoughts_with_method: bool = False,
    intent: bool = False,
    plan_with_intent: bool = False,
    suicidal_behavior: Literal["never", "over_3_months_ago", "past_3_months"] = "never",
) -> ScoreResult:
    """Columbia Suicide Severity Rating Scale (C-SSRS) screener triage: none, low, moderate or high risk.

    Args:
        wish_to_be_dead: Q1, past month: wished you were dead or could go to sleep and not wake up.
        suicidal_thoughts: Q2, past month: actually had thoughts of killing yourself.
        thoughts_with_method: Q3 (asked only if Q2 is yes): thought about how you might do this.
        intent: Q4 (only if Q2 is yes): had these thoughts and some intention of acting on them.
        plan_with_intent: Q5 (only if Q2 is yes): started to work out or worked out the details
            of how to kill yourself, and intend to carry out this plan.
        suicidal_behavior: Q6, ever done, started or prepared to do anything to end your life:
            "never", "over_3_months_ago" or "past_3_months".
    """
    fn = "assess_suicide_risk"
    q1 = check_bool(fn, "wish_to_be_dead", wish_to_be_dead)
    q2 = check_bool(fn, "suicidal_thoughts", suicidal_thoughts)
    q3 = check_bool(fn, "thoughts_with_method", thoughts_with_method)
    q4 = check_bool(fn, "intent", intent)
    q5 = check_bool(fn, "plan_with_intent", plan_with_intent)
    q6 = check_choice(fn, "suicidal_behavior", suicidal_behavior, _BEHAVIOR)
    if not q2:  # the screener skips Q3-5 when Q2 is "no"; a "yes" there contradicts Q2
        for name, value in (("thoughts_with_method", q3), ("intent", q4), ("plan_with_intent", q5)):
            if value:
                raise CalculatorInputError(
                    fn, name, "false when suicidal_thoughts is false (Q3-5 follow a yes to Q2)", value
                )
    comps = {
        "q1_wish_to_be_dead": q1,
        "q2_suicidal_thoughts": q2,
        "q3_method": q3,
        "q4_intent": q4,
        "q5_plan_with_intent": q5,
        "q6_behavior": q6,
    }
    if q4 or q5 or q6 == "past_3_months":
        level, cat = 3, "high risk"
        text = (
            "immediate mental-health evaluation and safety precautions (constant observation, remove means)"
        )
    elif q3 or q6 == "over_3_months_ago":
        level, cat = 2, "moderate risk"
        text = "mental-health evaluation before discharge and safety planning"
    elif q1 or q2:
        level, cat = 1, "low risk"
        text = "mental-health referral and safety resources"
    else:
        level, cat = 0, "no risk identified"
        text = "no suicidal ideation or behaviour reported on the screener"
    flags = ("suicidal ideation or behaviour reported",) if level > 0 else ()
    return make_result(
        "C-SSRS screener",
        level,
        "level",
        cat,
        f"C-SSRS screen {cat}: {text}.",
        comps,
        "Posner K et al. The Columbia-Suicide Severity Rating Scale. Am J Psychiatry 2011;168:1266-1277; "
        "C-SSRS Screen Version with triage points (Columbia Lighthouse Project).",
        flags,
    )


def administer_epds(responses: list[int]) -> ScoreResult:
    """Edinburgh Postnatal Depression Scale (0-30), flagging item 10 (self-harm thoughts).

    Args:
        responses: The ten scored item values in form order, each an integer 0-3 (items 3 and
            5-10 already reverse-scored as on the scoring key).
    """
    fn = "administer_epds"
    items = check_responses(fn, "responses", responses, 10, 0, 3)
    total = sum(items)
    if total >= 13:
        cat, text = "probable depression", "probable depression (>= 13): clinical assessment"
    elif total >= 10:
        cat, text = "possible depression", "possible depression (10-12): repeat in 2-4 weeks or assess"
    else:
        cat, text = "depression unlikely", "depression unlikely (< 10)"
    flags: tuple[str, ...] = ()
    if items[9] > 0:
        flags = ("item 10 positive: thoughts of self-harm",)
        text += "; item 10 is positive: assess suicide risk today"
    return make_result(
        "EPDS",
        total,
        "points",
        cat,
        f"EPDS {total}/30: {text}.",
        {f"item_{k + 1}": v for k, v in enumerate(items)},
        "Cox JL, Holden JM, Sagovsky R. Detection of postnatal depression: development of the 10-item "
        "Edinburgh Postnatal Depression Scale. Br J Psychiatry 1987;150:782-786.",
        flags,
    )


def administer_audit_c(responses: list[int], sex: Literal["male", "female"]) -> ScoreResult:
    """AUDIT-C alcohol-misuse screen (0-12) with sex-specific thresholds.

    The thresholds apply at every adult age: USPSTF 2018 and the VA/DoD SUD guideline set none by
    age; their age adjustment (65 and older) is to the single-question screen's and item 3's binge
    count (4 drinks) and to the daily and weekly drinking limits, not to the AUDIT-C cut-off.

    Args:
        responses: The three item answers in form order, each an integer 0-4 (frequency of drinking,
            drinks on a typical day, frequency of >= 6 drinks on one occasion).
        sex: "male" (positive >= 4) or "female" (positive >= 3).
    """
    fn = "administer_audit_c"
    items = check_responses(fn, "responses", responses, 3, 0, 4)
    s = check_choice(fn, "sex", sex, ("male", "female"))
    total = sum(items)
    threshold = 4 if s == "male" else 3
    positive = total >= threshold
    cat = "positive" if positive else "negative"
    return make_result(
        "AUDIT-C",
        total,
        "points",
        cat,
        f"AUDIT-C {total}/12: {'positive screen for hazardous drinking' if positive else 'negative screen'} "
        f"(threshold {threshold} for {s} patients).",
        {f"item_{k + 1}": v for k, v in enumerate(items)},
        "Bush K et al. The AUDIT alcohol consumption questions (AUDIT-C). Arch Intern Med "
        "1998;158:1789-1795; "
        "thresholds: Bradley KA et al. Alcohol Clin Exp Res 2007;31:1208-1217.",
    )


def administer_cage(cut_down: bool, annoyed: bool, guilty: bool, eye_opener: bool) -> ScoreResult:
    """CAGE questionnaire for alcohol-use disorder (0-4; >= 2 clinically significant).

    Args:
        cut_down: Have you ever felt you should Cut down on your drinking?
        annoyed: Have people Annoyed you by criticising your drinking?
        guilty: Have you ever felt bad or Guilty about your drinking?
        eye_opener: Have you ever had a drink first thing in the morning (Eye-opener)?
    """
    fn = "administer_cage"
    comps = {
        "cut_down": int(check_bool(fn, "cut_down", cut_down)),
        "annoyed": int(check_bool(fn, "annoyed", annoyed)),
        "guilty": int(check_bool(fn, "guilty", guilty)),
        "eye_opener": int(check_bool(fn, "eye_opener", eye_opener)),
    }
    total = sum(comps.values())
    cat = "positive" if total >= 2 else "negative"
    return make_result(
        "CAGE",
        total,
        "points",
        cat,
        f"CAGE {total}/4: "
        + (
            "clinically significant (>= 2): assess for alcohol-use disorder."
            if total >= 2
            else "below the threshold of 2."
        ),
        comps,
        "Ewing JA. Detecting alcoholism: the CAGE questionnaire. JAMA 1984;252:1905-1907.",
    )


def calculate_ciwa_ar(
    nausea_vomiting: int,
    tremor: int,
    paroxysmal_sweats: int,
    anxiety: int,
    agitation: int,
    tactile_disturbances: int,
    auditory_disturbances: int,
    visual_disturbances: int,
    headache: int,
    orientation: int,
) -> ScoreResult:
    """CIWA-Ar alcohol-withdrawal severity (0-67).

    Args:
        nausea_vomiting: Nausea and vomiting, integer 0-7.
        tremor: Tremor with arms extended, integer 0-7.
        paroxysmal_sweats: Paroxysmal sweats, integer 0-7.
        anxiety: Anxiety, integer 0-7.
        agitation: Agitation, integer 0-7.
        tactile_disturbances: Tactile disturbances, integer 0-7.
        auditory_disturbances: Auditory disturbances, integer 0-7.
        visual_disturbances: Visual disturbances, integer 0-7.
        headache: Headache or fullness in the head, integer 0-7.
        orientation: Orientation and clouding of sensorium, integer 0-4.
    """
    fn = "calculate_ciwa_ar"
    comps = {
        "nausea_vomiting": check_int(fn, "nausea_vomiting", nausea_vomiting, 0, 7),
        "tremor": check_int(fn, "tremor", tremor, 0, 7),
        "paroxysmal_sweats": check_int(fn, "paroxysmal_sweats", paroxysmal_sweats, 0, 7),
        "anxiety": check_int(fn, "anxiety", anxiety, 0, 7),
        "agitation": check_int(fn, "agitation", agitation, 0, 7),
        "tactile_disturbances": check_int(fn, "tactile_disturbances", tactile_disturbances, 0, 7),
        "auditory_disturbances": check_int(fn, "auditory_disturbances", auditory_disturbances, 0, 7),
        "visual_disturbances": check_int(fn, "visual_disturbances", visual_disturbances, 0, 7),
        "headache": check_int(fn, "headache", headache, 0, 7),
        "orientation": check_int(fn, "orientation", orientation, 0, 4),
    }
    total = sum(comps.values())
    if total <= 8:
        cat, text = "minimal", "absent or minimal withdrawal: symptom-triggered medication usually not needed"
    elif total <= 15:
        cat, text = "moderate", "moderate withdrawal: symptom-triggered benzodiazepine"
    else:
        cat, text = "severe", "severe withdrawal: risk of seizures and delirium tremens; close monitoring"
    return make_result(
        "CIWA-Ar",
        total,
        "points",
        cat,
        f"CIWA-Ar {total}/67: {text}.",
        comps,
        "Sullivan JT et al. Assessment of alcohol withdrawal: the revised Clinical Institute Withdrawal "
        "Assessment for Alcohol scale (CIWA-Ar). Br J Addict 1989;84:1353-1357; severity bands (<= 8, "
        "9-15, >= 16) as used in symptom-triggered withdrawal protocols.",
    )
