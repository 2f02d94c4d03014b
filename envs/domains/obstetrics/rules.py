"""Obstetric rules computed from the record: gestational dating, hypertensive disorders of
pregnancy, and a combined fetal-status assessment.

* Dating (ACOG Committee Opinion 700, 2017): EDD = LMP + 280 days (Naegele); gestational age from
  the crown-rump length by Robinson & Fleming (1975): days = 8.052 x sqrt(CRL mm) + 23.73. The
  ultrasound redates the pregnancy when it differs from LMP dating by more than 5 days (scan
  before 9 0/7 weeks) or more than 7 days (9 0/7 to 13 6/7 weeks).
* Hypertension in pregnancy (ACOG Practice Bulletin 222, 2020): hypertension = two readings
  >= 140 systolic or >= 90 diastolic at least 4 hours apart after 20 weeks; proteinuria =
  protein/creatinine ratio >= 0.3 mg/mg, or >= 300 mg/24 h, or dipstick >= 2+ when neither is
  available; severe features = two severe-range readings (>= 160 / >= 110) at least 4 h apart
  (15 minutes suffice once antihypertensives are needed), platelets < 100 x10^9/L, creatinine
  > 1.1 mg/dL, transaminases >= 2x the upper limit, severe RUQ/epigastric pain, pulmonary oedema,
  new headache or visual disturbance; HELLP = LDH >= 600 U/L, AST or ALT >= 2x upper limit,
  platelets < 100; eclampsia = new seizures.
"""

from __future__ import annotations

import math
from datetime import date, timedelta

AST_ULN = 40.0
ALT_ULN = 40.0


def parse_date(text: str, field: str) -> date:
    try:
        return date.fromisoformat(text)
    except (TypeError, ValueError):
        raise ValueError(f"argument {field!r} must be an ISO date YYYY-MM-DD, got {text!r}") from None


def weeks_days(days: int) -> str:
    return f"{days // 7} weeks {days % 7} days"


def crl_days(crl_mm: float) -> int:
    if not 3.0 <= crl_mm <= 84.0:
        raise ValueError(f"argument 'crown_rump_length_mm' must be 3-84 mm (the range CRL dating is valid for), got {crl_mm}")
    return int(round(8.052 * math.sqrt(crl_mm) + 23.73))


def gestational_age(on: date, lmp: date | None = None, crl_mm: float | None = None, scan: date | None = None) -> dict:
    """Best obstetric estimate of gestational age on `on` from LMP and/or a first-trimester CRL."""
    if lmp is None and crl_mm is None:
        raise ValueError("give an LMP date, a crown-rump length with its scan date, or both")
    out: dict = {"on_date": on.isoformat()}
    lmp_days = None
    if lmp is not None:
        lmp_days = (on - lmp).days
        if not 0 <= lmp_days <= 310:
            raise ValueError(f"LMP {lmp.isoformat()} gives {lmp_days} days of gestation on {on.isoformat()} (expected 0-310)")
        out["by_lmp"] = {"days": lmp_days, "ga": weeks_days(lmp_days), "edd": (lmp + timedelta(days=280)).isoformat()}
    us_days = None
    if crl_mm is not None:
        if scan is None:
            raise ValueError("argument 'scan_date' is required with a crown-rump length")
        at_scan = crl_days(crl_mm)
        us_days = at_scan + (on - scan).days
        out["by_ultrasound"] = {"ga_at_scan": weeks_days(at_scan), "days": us_days, "ga": weeks_days(us_days),
                                "edd": (on + timedelta(days=280 - us_days)).isoformat()}
        if lmp is not None:
            diff = abs(at_scan - (scan - lmp).days)
            limit = 5 if at_scan < 63 else 7
            out["discrepancy_days"] = diff
            out["redating_threshold_days"] = limit
            use_us = diff > limit
        else:
            use_us = True
    else:
        use_us = False
    days = us_days if use_us else lmp_days
    basis = "ultrasound (CRL)" if use_us else "LMP"
    out["best_estimate"] = {"basis": basis, "days": days, "ga": weeks_days(days), "completed_weeks": days // 7,
                            "edd": (on + timedelta(days=280 - days)).isoformat()}
    return out


def _readings(bps: list[dict], sys_cut: int, dia_cut: int) -> list[dict]:
    return [b for b in bps if b["systolic"] >= sys_cut or b["diastolic"] >= dia_cut]


def _apart(readings: list[dict], hours: float) -> bool:
    times = sorted(b["hours_ago"] for b in readings)
    return bool(times) and times[-1] - times[0] >= hours


def hypertensive_disorder(ga_weeks: float, bps: list[dict], labs: dict[str, float], symptoms: dict,
                          chronic_hypertension: bool, on_antihypertensive: bool = False) -> dict:
    """Classify a hypertensive disorder of pregnancy from readings, labs and symptoms (ACOG PB 222)."""
    hyper = _readings(bps, 140, 90)
    severe = _readings(bps, 160, 110)
    hypertension = len(hyper) >= 2 and _apart(hyper, 4.0)
    severe_bp = len(severe) >= 2 and (_apart(severe, 4.0) or (on_antihypertensive and _apart(severe, 0.25)))
    if len(severe) >= 2 and _apart(severe, 0.25):
        hypertension = True
    upcr, p24, dip = labs.get("urine protein/creatinine ratio"), labs.get("24-hour urine protein"), labs.get("urine dipstick protein")
    if upcr is not None or p24 is not None:
        proteinuria = (upcr is not None and upcr >= 0.3) or (p24 is not None and p24 >= 300)
    else:
        proteinuria = dip is not None and dip >= 2
    plt, cr = labs.get("platelets"), labs.get("creatinine")
    ast, alt, ldh = labs.get("AST"), labs.get("ALT"), labs.get("LDH")
    liver = (ast is not None and ast >= 2 * AST_ULN) or (alt is not None and alt >= 2 * ALT_ULN)
    features = []
    if severe_bp:
        features.append("severe-range blood pressure on two occasions")
    if plt is not None and plt < 100:
        features.append(f"thrombocytopenia (platelets {plt:g} x10^9/L)")
    if cr is not None and cr > 1.1:
        features.append(f"renal insufficiency (creatinine {cr:g} mg/dL)")
    if liver:
        features.append("transaminases at least twice the upper limit")
    if symptoms.get("epigastric_or_ruq_pain"):
        features.append("severe RUQ or epigastric pain")
    if symptoms.get("pulmonary_edema"):
        features.append("pulmonary oedema")
    if symptoms.get("headache") or symptoms.get("visual_disturbance"):
        features.append("new cerebral or visual symptoms")
    hellp = ldh is not None and ldh >= 600 and liver and plt is not None and plt < 100
    organ = [f for f in features if not f.startswith("severe-range")]
    if symptoms.get("seizure") and (hypertension or hyper):
        category = "eclampsia"
    elif hellp:
        category = "HELLP syndrome"
    elif chronic_hypertension:
        category = ("chronic hypertension with superimposed preeclampsia with severe features" if (proteinuria or organ) and features
                    else "chronic hypertension with superimposed preeclampsia" if proteinuria else "chronic hypertension")
    elif ga_weeks < 20:
        category = "hypertension before 20 weeks (chronic)" if hypertension else "no hypertensive disorder"
    elif not hypertension:
        category = "no hypertensive disorder"
    elif proteinuria or organ:
        category = "preeclampsia with severe features" if features else "preeclampsia without severe features"
    elif severe_bp:
        category = "severe gestational hypertension"
    else:
        category = "gestational hypertension"
    return {"category": category, "hypertension": hypertension, "proteinuria": proteinuria, "severe_features": features,
            "hellp": hellp, "elevated_readings": len(hyper), "severe_range_readings": len(severe)}


def fetal_status(ctg_category: str | None, bpp_score: int | None, bpp_max: int | None, oligohydramnios: bool,
                 ga_weeks: float) -> dict:
    """Combine the latest CTG category and biophysical profile into one status and next step."""
    if ctg_category is None and bpp_score is None:
        raise ValueError("no CTG tracing or biophysical profile on file: record one first")
    reasons = []
    status = "reassuring"
    if ctg_category == "Category III":
        status = "abnormal"
        reasons.append("Category III tracing")
    if bpp_score is not None and bpp_max == 10 and bpp_score <= 4:
        status = "abnormal"
        reasons.append(f"biophysical profile {bpp_score}/10")
    if status != "abnormal":
        if ctg_category == "Category II":
            status = "indeterminate"
            reasons.append("Category II tracing")
        if bpp_score is not None and ((bpp_max == 10 and bpp_score == 6) or (bpp_max == 8 and bpp_score < 8)):
            status = "indeterminate"
            reasons.append(f"equivocal biophysical profile {bpp_score}/{bpp_max}")
        if oligohydramnios:
            status = "indeterminate"
            reasons.append("oligohydramnios")
    if status == "abnormal":
        action = ("expedite delivery (intrauterine resuscitation while preparing; emergency delivery if the "
                  "tracing does not resolve)")
    elif status == "indeterminate":
        action = "intrauterine resuscitation, continuous monitoring and reassessment; consider delivery at term"
    else:
        action = "routine care and monitoring"
    if not reasons:
        reasons.append("Category I tracing" if ctg_category == "Category I" else "normal biophysical profile")
    return {"status": status, "reasons": reasons, "recommended_action": action, "gestational_age_weeks": ga_weeks}
