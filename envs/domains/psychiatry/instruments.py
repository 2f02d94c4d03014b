"""Questionnaire item labels, interview wording, and the Mood Disorder Questionnaire scoring rule.

The PHQ-9 and GAD-7 item wordings are public domain (Pfizer, no permission required). The
C-SSRS screener, AUDIT-C, EPDS and MDQ items are given as short paraphrased labels with their
citations. Scoring of every instrument except the MDQ is done by `envs.calculators`; the MDQ
(not in the calculator package) is scored here by its published rule.
"""

from __future__ import annotations

from envs.calculators._core import CalculatorInputError, ScoreResult, make_result

FREQUENCY = ["not at all", "several days", "more than half the days", "nearly every day"]

PHQ9_ITEMS = [
    "Little interest or pleasure in doing things",
    "Feeling down, depressed, or hopeless",
    "Trouble falling or staying asleep, or sleeping too much",
    "Feeling tired or having little energy",
    "Poor appetite or overeating",
    "Feeling bad about yourself, or that you are a failure or have let yourself or your family down",
    "Trouble concentrating on things, such as reading the newspaper or watching television",
    "Moving or speaking so slowly that other people could have noticed, or the opposite, being so fidgety "
    "or restless that you have been moving around a lot more than usual",
    "Thoughts that you would be better off dead, or of hurting yourself in some way",
]
GAD7_ITEMS = [
    "Feeling nervous, anxious, or on edge",
    "Not being able to stop or control worrying",
    "Worrying too much about different things",
    "Trouble relaxing",
    "Being so restless that it is hard to sit still",
    "Becoming easily annoyed or irritable",
    "Feeling afraid, as if something awful might happen",
]
EPDS_ITEMS = [
    "Able to laugh and see the funny side of things", "Looked forward with enjoyment to things",
    "Blamed myself unnecessarily when things went wrong", "Anxious or worried for no good reason",
    "Scared or panicky for no very good reason", "Things have been getting on top of me",
    "So unhappy that I have had difficulty sleeping", "Felt sad or miserable", "So unhappy that I have been crying",
    "The thought of harming myself has occurred to me",
]
AUDIT_C_ITEMS = [
    ("How often do you have a drink containing alcohol?",
     ["never", "monthly or less", "2-4 times a month", "2-3 times a week", "4 or more times a week"]),
    ("How many standard drinks do you have on a typical day when you are drinking?",
     ["1 or 2", "3 or 4", "5 or 6", "7 to 9", "10 or more"]),
    ("How often do you have six or more drinks on one occasion?",
     ["never", "less than monthly", "monthly", "weekly", "daily or almost daily"]),
]
MDQ_ITEMS = [
    "felt so good or hyper that others thought you were not your normal self, or got into trouble",
    "so irritable that you shouted at people or started fights or arguments",
    "felt much more self-confident than usual",
    "got much less sleep than usual and found you didn't really miss it",
    "much more talkative or spoke much faster than usual",
    "thoughts raced through your head or you couldn't slow your mind down",
    "so easily distracted by things around you that you had trouble concentrating or staying on track",
    "had much more energy than usual",
    "much more active or did many more things than usual",
    "much more social or outgoing than usual",
    "much more interested in sex than usual",
    "did things that were unusual for you or that other people might have thought were excessive, foolish or risky",
    "spending money got you or your family into trouble",
]
CSSRS_QUESTIONS = {
    "wish_to_be_dead": "In the past month, have you wished you were dead or wished you could go to sleep and not wake up?",
    "suicidal_thoughts": "In the past month, have you actually had any thoughts of killing yourself?",
    "thoughts_with_method": "Have you been thinking about how you might do this?",
    "intent": "Have you had these thoughts and had some intention of acting on them?",
    "plan_with_intent": "Have you started to work out or worked out the details of how to kill yourself, and do you "
                        "intend to carry out this plan?",
    "suicidal_behavior": "Have you ever done anything, started to do anything, or prepared to do anything to end your life?",
}
CIWA_FIELDS = ["nausea_vomiting", "tremor", "paroxysmal_sweats", "anxiety", "agitation", "tactile_disturbances",
               "auditory_disturbances", "visual_disturbances", "headache", "orientation"]
MDQ_PROBLEM_LEVELS = ("no problem", "minor problem", "moderate problem", "serious problem")
MDQ_REFERENCE = ("Hirschfeld RMA et al. Development and validation of a screening instrument for bipolar spectrum "
                 "disorder: the Mood Disorder Questionnaire. Am J Psychiatry 2000;157:1873-1875.")


def score_mdq(items: list[bool], same_period: bool, problem_level: str) -> ScoreResult:
    """Mood Disorder Questionnaire: positive when >= 7 of the 13 symptom items are "yes", several
    occurred during the same period, and they caused a moderate or serious problem (Hirschfeld 2000).

    Args:
        items: The 13 yes/no answers of question 1, in form order.
        same_period: Question 2: have several of these happened during the same period of time?
        problem_level: Question 3: "no problem", "minor problem", "moderate problem" or "serious problem".
    """
    fn = "screen_bipolar"
    if not isinstance(items, (list, tuple)) or len(items) != 13 or not all(isinstance(x, bool) for x in items):
        raise CalculatorInputError(fn, "items", "a list of 13 booleans (question 1, in form order)", items)
    if not isinstance(same_period, bool):
        raise CalculatorInputError(fn, "same_period", "a boolean", same_period)
    if problem_level not in MDQ_PROBLEM_LEVELS:
        raise CalculatorInputError(fn, "problem_level", "one of " + ", ".join(repr(p) for p in MDQ_PROBLEM_LEVELS),
                                   problem_level)
    yes = sum(items)
    impairment = problem_level in ("moderate problem", "serious problem")
    positive = yes >= 7 and same_period and impairment
    missing = []
    if yes < 7:
        missing.append(f"only {yes} of 13 symptom items endorsed (needs >= 7)")
    if not same_period:
        missing.append("symptoms did not cluster in the same period")
    if not impairment:
        missing.append(f"functional impact is '{problem_level}' (needs moderate or serious)")
    text = ("MDQ positive: screen suggests bipolar spectrum disorder; confirm with a diagnostic interview"
            if positive else "MDQ negative: " + "; ".join(missing))
    return make_result("Mood Disorder Questionnaire", yes, "items endorsed", "positive" if positive else "negative",
                       text + ".", {"items_yes": yes, "same_period": same_period, "problem_level": problem_level},
                       MDQ_REFERENCE)
