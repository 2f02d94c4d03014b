"""How the reward recognises clinical actions in tool calls: tool names and argument names.

The safety detector and the process score read the trajectory's tool calls by convention, so
they work for every domain without per-domain code. A tool belongs to a *family* when its name
is listed under that family or contains one of the family's substrings (case-insensitive).
Domains extend the conventions instead of renaming their tools:

    >>> conv = DEFAULT_CONVENTIONS.extend(prescribing=["order_antibiotic"])
    >>> "prescribing" in conv.families("order_antibiotic")
    True

The table of families is in `docs/rewards.md` ("Tool conventions").
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from typing import Any, Iterable

_FAMILY_FIELDS = (
    "prescribing", "place_order", "interaction_check", "interaction_check_all", "escalation",
    "follow_up", "confirmatory", "diagnosis", "discharge", "discontinue", "allergy_review",
    "patient_data", "search", "consent", "invasive", "triage", "resuscitation", "intubation", "submit",
    "think", "monitoring",
)


@dataclass(frozen=True)
class Family:
    """Tool names (exact, lower case) and name substrings that put a tool in a family."""

    names: frozenset[str] = frozenset()
    substrings: tuple[str, ...] = ()

    def matches(self, name: str) -> bool:
        return name in self.names or any(s in name for s in self.substrings)

    def extended(self, names: Iterable[str] = (), substrings: Iterable[str] = ()) -> "Family":
        return Family(self.names | {n.lower() for n in names}, tuple(dict.fromkeys((*self.substrings, *substrings))))


def _fam(names: str = "", substrings: str = "") -> Family:
    return Family(frozenset(names.split()), tuple(substrings.split()))


@dataclass(frozen=True)
class ToolConventions:
    """Tool families and argument names the reward understands. Immutable; use `extend`."""

    prescribing: Family = _fam(
        "prescribe_medication prescribe recommend_drug recommend_medication administer_medication "
        "order_medication start_medication give_medication prescribe_drug add_medication",
        "prescribe",
    )
    #: Generic order tools; a call is a medication order when `order_type` is in `medication_order_types`.
    place_order: Family = _fam("place_order create_order enter_order")
    interaction_check: Family = _fam("", "check_interaction check_all_interactions check_drug_interactions interaction")
    #: Interaction checks that cover every drug of the patient whatever their arguments.
    interaction_check_all: Family = _fam("check_all_interactions check_drug_interactions check_patient_interactions "
                                         "check_psych_med_interactions")
    escalation: Family = _fam(
        "escalate_care activate_code activate_stemi_alert call_rapid_response transfer_to_specialist "
        "activate_stroke_alert activate_sepsis_protocol activate_cath_lab call_911 call_emergency_services "
        "request_icu_admission admit_to_icu transfer_to_ed transfer_to_icu refer_to_emergency page_specialist "
        "activate_rapid_response call_code_blue emergency_consult request_emergency_consult activate_trauma_team "
        "activate_massive_transfusion initiate_emergency_delivery",
        "escalate activate_ rapid_response transfer_to emergency_transfer call_911",
    )
    follow_up: Family = _fam(
        "schedule_follow_up schedule_followup arrange_follow_up book_follow_up schedule_appointment",
        "follow_up followup",
    )
    confirmatory: Family = _fam(
        "order_lab order_test order_imaging order_labs order_ecg order_diagnostic_test get_lab_results "
        "get_imaging_results review_lab_results get_test_results order_biopsy order_culture",
        "order_lab order_test order_imag lab_result imaging_result test_result",
    )
    diagnosis: Family = _fam(
        "record_diagnosis make_diagnosis set_diagnosis document_diagnosis submit_diagnosis confirm_diagnosis "
        "add_diagnosis finalize_diagnosis",
        "record_diagnosis",
    )
    #: Discharging the patient (not writing a discharge summary: names only, plus "discharge_patient").
    discharge: Family = _fam("discharge_patient discharge send_home discharge_home", "discharge_patient")
    discontinue: Family = _fam(
        "discontinue_medication stop_medication hold_medication discontinue_drug remove_medication",
        "discontinue",
    )
    allergy_review: Family = _fam(
        "get_patient_info get_patient_details get_patient_record get_patient_summary get_patient_history "
        "get_medical_history review_chart get_patient",
        "allerg",
    )
    #: Reading the patient's own data (history, vitals, labs, notes, allergies, medications).
    patient_data: Family = _fam(
        "get_patient_info get_patient_details get_patient_record get_patient_summary review_chart get_patient",
        "get_patient patient_info vital lab_result get_lab history chart allerg get_medication medication_list "
        "symptom exam clinical_note notes assess calculate screen score",
    )
    search: Family = _fam(
        "search_pubmed search_medical_wiki retrieve_evidence search_knowledge_base search_guidelines",
        "search retrieve_evidence lookup get_evidence pubmed wiki",
    )
    consent: Family = _fam("obtain_consent document_consent discuss_with_patient", "consent shared_decision")
    invasive: Family = _fam(
        "perform_procedure schedule_surgery order_procedure perform_surgery perform_lumbar_puncture "
        "insert_central_line perform_biopsy",
        "schedule_surgery perform_surgery perform_procedure biopsy lumbar_puncture central_line",
    )
    triage: Family = _fam(
        "assign_esi_level assign_triage_level set_triage_level triage_patient set_esi_level", "esi_level triage_level"
    )
    resuscitation: Family = _fam("activate_code start_cpr perform_cpr call_code_blue", "cpr code_blue")
    intubation: Family = _fam("intubate perform_intubation", "intubat")
    submit: Family = _fam("submit_answer")
    think: Family = _fam("think")
    #: Monitoring orders (INR, drug levels) count as a monitoring plan.
    monitoring: Family = _fam("order_lab order_test schedule_monitoring order_monitoring", "monitor")

    # argument names, in order of preference
    drug_args: tuple[str, ...] = ("drug", "drug_name", "medication", "medication_name", "generic_name", "agent", "name", "item")
    dose_args: tuple[str, ...] = ("dose_mg", "dose", "dosage", "amount_mg", "amount", "strength")
    route_args: tuple[str, ...] = ("route",)
    patient_args: tuple[str, ...] = ("patient_id", "patient", "mrn", "subject_id")
    order_type_args: tuple[str, ...] = ("order_type", "type", "category")
    medication_order_types: frozenset[str] = frozenset({"medication", "med", "drug", "prescription", "pharmacy"})
    test_order_types: frozenset[str] = frozenset({"lab", "labs", "test", "imaging", "radiology", "diagnostic", "ecg", "culture"})
    esi_args: tuple[str, ...] = ("esi_level", "esi", "level", "triage_level", "acuity")
    #: Prescribing tools whose orders must carry a dose and a route (recommendations need not).
    order_tools_needing_dose: frozenset[str] = frozenset(
        {"prescribe_medication", "prescribe", "administer_medication", "order_medication", "give_medication",
         "prescribe_drug", "place_order"}
    )
    #: Classes for which two concurrent drugs are a therapeutic duplication. Not "antiplatelets":
    #: aspirin with a P2Y12 inhibitor is dual antiplatelet therapy (after ACS or a stent), standard
    #: care; two P2Y12 inhibitors are the duplication.
    duplication_classes: frozenset[str] = frozenset({
        "anticoagulants", "nsaids", "ssris", "snris", "maois", "opioids", "benzodiazepines", "ace inhibitors",
        "arbs", "statins", "p2y12 inhibitors", "sulfonylureas", "beta blockers", "proton pump inhibitors",
        "antipsychotics", "direct oral anticoagulants",
    })
    #: More than this many non-urgent calls (not assessment or treatment: searches, documentation,
    #: coding, other tools) before the first escalation call is a delayed escalation.
    escalation_delay_calls: int = 3
    #: Dose at or above this multiple of the maximum single dose is critical (severity 5).
    critical_dose_ratio: float = 2.0
    _cache: dict = field(default_factory=dict, compare=False, repr=False, hash=False)

    def families(self, name: str) -> frozenset[str]:
        """The families a tool name belongs to (cached)."""
        key = name.lower()
        hit = self._cache.get(key)
        if hit is None:
            hit = frozenset(f for f in _FAMILY_FIELDS if getattr(self, f).matches(key))
            self._cache[key] = hit
        return hit

    def extend(self, **changes: Any) -> "ToolConventions":
        """A copy with more names per family (`prescribing=["x"]`), more substrings
        (`prescribing_substrings=["y"]`) or replaced scalar settings (`critical_dose_ratio=3`)."""
        updates: dict[str, Any] = {}
        known = {f.name for f in fields(self)}
        for key, value in changes.items():
            if key.endswith("_substrings") and key[: -len("_substrings")] in _FAMILY_FIELDS:
                base = key[: -len("_substrings")]
                updates[base] = updates.get(base, getattr(self, base)).extended(substrings=value)
            elif key in _FAMILY_FIELDS:
                updates[key] = updates.get(key, getattr(self, key)).extended(names=value)
            elif key in known and not key.startswith("_"):
                updates[key] = value
            else:
                raise ValueError(f"unknown convention {key!r}; families: {', '.join(_FAMILY_FIELDS)}")
        return replace(self, **updates, _cache={})

    def first_arg(self, arguments: dict[str, Any], keys: tuple[str, ...]) -> Any:
        for key in keys:
            if key in arguments and arguments[key] not in (None, ""):
                return arguments[key]
        return None


DEFAULT_CONVENTIONS = ToolConventions()
FAMILIES = _FAMILY_FIELDS
