import pytest

from envs import registry
from envs.core.contamination import find_leaks, normalise
from envs.validate import check_domain_contamination
from envs.core.task import Task


def t(tid, ticket, answer="A", options=None):
    return Task(id=tid, ticket=ticket, options=options or {"A": "yes", "B": "no"}, correct_answer=answer)


def test_exact_and_near_duplicates_are_found():
    long = ("A 54 year old man with type 2 diabetes and stage 3 chronic kidney disease presents with "
            "fatigue and a potassium of 6.1 mmol per litre after starting a new blood pressure medicine today")
    train = [t("tr1", long), t("tr2", "Which drug treats absence seizures in children best?")]
    held = [
        t("te1", long.upper() + "!!"),                                  # same text after normalisation
        t("te2", "please " + long),                                      # one word added, same answer
        t("te3", "please " + long, answer="B"),                          # same question, other answer
        t("te4", "Completely different question about asthma inhalers and technique"),
    ]
    leaks = {leak.held_out_id: leak.kind for leak in find_leaks(train, held)}
    assert leaks == {"te1": "exact", "te2": "near"}
    assert normalise("Hello,   World!") == "hello world"


@pytest.mark.parametrize("domain", registry.list_domains())
def test_no_held_out_task_appears_in_train(domain):
    leaks = check_domain_contamination(domain)
    assert leaks == [], f"{domain}: {len(leaks)} held-out tasks leak into train, e.g. {leaks[:3]}"


def test_templated_tickets_about_different_patients_are_not_leaks():
    ticket = ("Patient {} has just arrived at the emergency department triage desk. Review the presentation and "
              "vital signs, assign an ESI level and answer with the level.")
    a = Task(id="a", ticket=ticket.format("E-1"), correct_answer="3", answer_type="exact", patient_id="E-1")
    b = Task(id="b", ticket=ticket.format("E-2"), correct_answer="3", answer_type="exact", patient_id="E-2")
    c = Task(id="c", ticket=ticket.format("E-1") + " Be quick.", correct_answer="3", answer_type="exact", patient_id="E-1")
    assert find_leaks([a], [b]) == []
    assert [leak.kind for leak in find_leaks([a], [c])] == ["near"]
