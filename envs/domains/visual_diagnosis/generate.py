"""Generate the visual-diagnosis studies (rendered PNG images), the reference archive and the tasks.

Each study is rendered from a findings specification (`render.py`); it is kept only when the pixel
analysis (`analysis.py`) recovers the specification: the finding types, sides, zones, sizes within
tolerance, the cardiothoracic ratio, and for CT the number, type and axes of the nodules. Gold
answers are the specification's values (for Fleischner: `envs.calculators` on the specified
nodule, which the check guarantees the image measurement reproduces).
"""

from __future__ import annotations

import math
import random
from pathlib import Path
from typing import Any, Callable

import numpy as np
from scipy import ndimage

from envs.calculators import CALCULATORS
from envs.coherence import indication_fits_age
from envs.domains.visual_diagnosis import analysis as A
from envs.domains.visual_diagnosis import render as R
from envs.domains.visual_diagnosis.case_schema import CASES_DIR, Case, ChestCT, Radiograph, fill, load_cases, placeholders
from envs.domains.imaging_guidelines import KNOWN_MALIGNANCY_ALIASES, KNOWN_MALIGNANCY_GUIDELINE, KNOWN_MALIGNANCY_MANAGEMENT
from envs.domains.visual_diagnosis.data_model import ArchivedCase, PatientInfo, Study
from envs.domains.visual_diagnosis.png import write_png

PROVENANCE = {"source": "authored", "generator": "envs.domains.visual_diagnosis.generate", "license": "project (ours)"}
CXR_KINDS = ["normal", "nodule", "mass", "consolidation", "pleural effusion", "pneumothorax", "cardiomegaly"]
ORIENT_CXR = "PA, radiological convention: the patient's right is on the image left"
ORIENT_CT = "axial, viewed from the feet: the patient's right is on the image left, anterior at the top"
INDICATION = {"normal": "pre-employment screening", "nodule": "chronic cough", "mass": "weight loss and haemoptysis",
              "consolidation": "fever and productive cough", "pleural effusion": "breathlessness",
              "pneumothorax": "sudden pleuritic chest pain", "cardiomegaly": "ankle swelling and orthopnoea"}
# A normal radiograph past working age is a pre-operative film, not a pre-employment one (envs.coherence).
OLDER_NORMAL_INDICATION = "pre-operative assessment"


def _indication(kind: str, age: int) -> str:
    indication = INDICATION.get(kind, "incidental finding")
    return indication if indication_fits_age(indication, age) else OLDER_NORMAL_INDICATION


def _patient(rng: random.Random, kind: str, smoker: bool | None = None) -> PatientInfo:
    smoker = rng.random() < 0.5 if smoker is None else smoker
    pack = float(rng.choice([15, 25, 30, 40])) if smoker else 0.0
    age = rng.randint(19, 35) if kind == "pneumothorax" else rng.randint(35, 84)
    return PatientInfo(age=age, sex=rng.choice(["female", "male"]), history=rng.choice(["no relevant history", "hypertension",
                                                                                          "type 2 diabetes", "asthma", "COPD"]),
                       smoking_pack_years=pack, lung_cancer_risk="high" if smoker else "low",
                       symptoms=[_indication(kind, age)])


def place(mask: np.ndarray, zone: str, r: float, rng: random.Random) -> tuple[float, float] | None:
    ys, _ = np.nonzero(mask)
    top, bottom = ys.min(), ys.max()
    h = bottom - top + 1
    inner = ndimage.distance_transform_edt(mask) > r + 4
    lo, hi = {"upper": (0.1, 0.3), "middle": (0.38, 0.62), "lower": (0.7, 0.86)}[zone]
    y0, y1 = int(top + h * lo), int(top + h * hi)
    cand = np.argwhere(inner[y0:y1 + 1])
    if len(cand) == 0:
        return None
    cy, cx = cand[rng.randrange(len(cand))]
    return float(cy + y0), float(cx)


def cxr_spec(kind: str, rng: random.Random, seed: int, side: str | None = None, zone: str | None = None) -> tuple[dict, dict] | None:
    ctr = rng.uniform(0.56, 0.63) if kind == "cardiomegaly" else rng.uniform(0.38, 0.46)
    anatomy = R.cxr_anatomy(seed, ctr)
    side = side or rng.choice(["right", "left"])
    zone = zone or rng.choice(["upper", "middle", "lower"])
    f: dict[str, Any] = {"type": kind, "side": side, "zone": zone}
    if kind in ("nodule", "mass"):
        d = rng.uniform(9, 24) if kind == "nodule" else rng.uniform(38, 48)
        if kind == "mass":
            zone = f["zone"] = "middle"
        pos = place(anatomy["masks"][side], zone, d / 2 / R.CXR_SPACING_MM, rng)
        if pos is None:
            return None
        f.update(diameter_mm=round(d, 1), cy=pos[0], cx=pos[1])
    elif kind == "consolidation":
        pos = place(anatomy["masks"][side], zone, 16, rng)
        if pos is None:
            return None
        f.update(cy=pos[0], cx=pos[1])
    elif kind == "pleural effusion":
        f.update(level_fraction=round(rng.uniform(0.45, 0.7), 3), zone="lower")
    elif kind == "pneumothorax":
        f.update(depth_px=round(rng.uniform(10, 18), 2), zone="apical/lateral")
    elif kind in ("normal", "cardiomegaly"):
        f.update(side="central" if kind == "cardiomegaly" else "none", zone="cardiac" if kind == "cardiomegaly" else "none")
    spec = {"ctr": round(ctr, 4), "findings": [] if kind in ("normal", "cardiomegaly") else [f]}
    return spec, f


def cxr_agrees(out: dict, spec: dict, f: dict) -> bool:
    found = out["findings"]
    kind = f["type"]
    names = [x["finding"] for x in found]
    if names != ([] if kind == "normal" else [kind]):
        return False
    if abs(out["cardiothoracic_ratio"] - spec["ctr"]) > 0.02:
        return False
    if kind in ("nodule", "mass"):
        return abs(found[0]["diameter_mm"] - f["diameter_mm"]) <= 1.5 and found[0]["side"] == f["side"] and found[0]["zone"] == f["zone"]
    if kind in ("consolidation", "pleural effusion", "pneumothorax"):
        return found[0]["side"] == f["side"] and (kind != "consolidation" or found[0]["zone"] == f["zone"])
    return True


def make_cxr(sid: str, rng: random.Random, kind: str, image_dir: Path, **kw) -> tuple[Study, dict]:
    for _ in range(30):
        seed = rng.randint(0, 10 ** 9)
        made = cxr_spec(kind, rng, seed, **kw)
        if made is None:
            continue
        spec, f = made
        img, _ = R.render_cxr(spec, seed)
        out = A.analyze_cxr(img, R.CXR_SPACING_MM)
        if not cxr_agrees(out, spec, f):
            continue
        write_png(image_dir / f"{sid}.png", img)
        patient = _patient(rng, kind)
        study = Study(study_id=sid, modality="CR", body_part="chest", view="PA", image_file=f"images/{sid}.png", width=R.SIZE,
                      height=R.SIZE, pixel_spacing_mm=R.CXR_SPACING_MM, orientation=ORIENT_CXR, indication=patient.symptoms[0],
                      acquired="today", patient=patient, provenance=PROVENANCE)
        truth = {"finding": kind, "side": f["side"], "zone": f["zone"], "ctr": spec["ctr"], "diameter_mm": f.get("diameter_mm"),
                 "seed": seed, "centroid_px": [round(f["cx"], 1), round(f["cy"], 1)] if "cx" in f else None}
        return study, truth
    raise RuntimeError(f"could not render a {kind} radiograph that analyses as designed")


def _ct_nodule(rng: random.Random, anatomy: dict, placed: list[dict], typ: str, mean_mm: float) -> dict | None:
    ratio = rng.uniform(0.7, 1.0)
    short = round(2 * mean_mm / (1 + 1 / ratio), 1)
    long_ = round(2 * mean_mm - short, 1)
    side = rng.choice(["right", "left"])
    g = anatomy["lungs"][side]
    yy, xx = np.mgrid[0:R.SIZE, 0:R.SIZE]
    lung = ((xx - g["cx"]) / g["rx"]) ** 2 + ((yy - g["cy"]) / g["ry"]) ** 2 < 1
    room = ndimage.distance_transform_edt(lung) > long_ / 2 / R.CT_SPACING_MM + 5
    for m in placed:
        room &= np.hypot(yy - m["cy"], xx - m["cx"]) > (long_ + m["long_mm"]) / 2 / R.CT_SPACING_MM + 8
    cand = np.argwhere(room)
    if len(cand) == 0:
        return None
    cy, cx = map(float, cand[rng.randrange(len(cand))])
    n = {"side": side, "cy": cy, "cx": cx, "long_mm": long_, "short_mm": short, "angle": round(rng.uniform(0, math.pi), 3), "type": typ}
    if typ == "part_solid":
        n["solid_mm"] = round(short * rng.uniform(0.4, 0.6), 1)
    return n


def ct_agrees(out: dict, nodules: list[dict]) -> bool:
    if out["nodule_count"] != len(nodules):
        return False
    for x in out["nodules"]:
        m = min(nodules, key=lambda q: math.hypot(q["cx"] - x["centroid_px"][0], q["cy"] - x["centroid_px"][1]))
        if x["type"] != m["type"] or abs(x["long_axis_mm"] - m["long_mm"]) > 0.8 or abs(x["short_axis_mm"] - m["short_mm"]) > 0.8:
            return False
        true_mean = (m["long_mm"] + m["short_mm"]) / 2
        if math.floor(x["mean_diameter_mm"] + 0.5) != math.floor(true_mean + 0.5) or abs(x["mean_diameter_mm"] - true_mean) > 0.6:
            return False
    return True


# (indication, known primary cancer) of a CT without a prior: a staging CT means a known malignancy.
CT_INDICATIONS = [("staging CT for colorectal cancer", "colorectal adenocarcinoma"), ("trauma", None), ("chronic cough", None),
                  ("pre-operative assessment", None)]


def make_ct(sid: str, rng: random.Random, image_dir: Path, plan: list[tuple[str, float]], smoker: bool | None = None,
            prior_plan: list[float | None] | None = None) -> tuple[Study, dict, Study | None]:
    """plan: [(type, mean_mm)] for the current image; prior_plan: per nodule the prior mean (None: absent)."""
    for _ in range(40):
        seed = rng.randint(0, 10 ** 9)
        anatomy = R.ct_anatomy(seed)
        nodules: list[dict] = []
        for typ, mean in plan:
            n = _ct_nodule(rng, anatomy, nodules, typ, mean)
            if n is None:
                break
            nodules.append(n)
        if len(nodules) != len(plan):
            continue
        img, _ = R.render_ct({"nodules": nodules}, seed)
        if not ct_agrees(A.analyze_ct(img, R.CT_SPACING_MM), nodules):
            continue
        prior_study, prior_nodules = None, None
        if prior_plan is not None:
            prior_nodules = []
            for n, pm in zip(nodules, prior_plan):
                if pm is None:
                    continue
                scale = pm / ((n["long_mm"] + n["short_mm"]) / 2)
                prior_nodules.append({**n, "long_mm": round(n["long_mm"] * scale, 1), "short_mm": round(n["short_mm"] * scale, 1),
                                      **({"solid_mm": round(n["solid_mm"] * scale, 1)} if "solid_mm" in n else {})})
            pimg, _ = R.render_ct({"nodules": prior_nodules, "keep_clear": nodules}, seed)
            if not ct_agrees(A.analyze_ct(pimg, R.CT_SPACING_MM), prior_nodules):
                continue
            pid = f"{sid}-P"
            write_png(image_dir / f"{pid}.png", pimg)
        patient = _patient(rng, "nodule", smoker)
        if prior_plan is not None:
            prior_study = Study(study_id=pid, modality="CT", body_part="chest", view="axial", image_file=f"images/{pid}.png",
                                width=R.SIZE, height=R.SIZE, pixel_spacing_mm=R.CT_SPACING_MM, orientation=ORIENT_CT,
                                indication="nodule surveillance", acquired="12 months ago", patient=patient, provenance=PROVENANCE)
        write_png(image_dir / f"{sid}.png", img)
        indication, cancer = ("nodule surveillance", None) if prior_plan is not None else rng.choice(CT_INDICATIONS)
        if cancer:  # a staging CT: the patient has a known primary cancer (outside Fleischner 2017)
            patient = patient.model_copy(update={"known_malignancy": cancer, "history": f"{cancer} diagnosed this month, staging in progress"})
        study = Study(study_id=sid, modality="CT", body_part="chest", view="axial", image_file=f"images/{sid}.png", width=R.SIZE,
                      height=R.SIZE, pixel_spacing_mm=R.CT_SPACING_MM, orientation=ORIENT_CT, indication=indication,
                      acquired="today", patient=patient, prior_study_id=prior_study.study_id if prior_study else None,
                      provenance=PROVENANCE)
        return study, {"nodules": nodules, "prior_nodules": prior_nodules, "seed": seed}, prior_study
    raise RuntimeError(f"could not render CT {sid} with {plan}")


# -- archive --------------------------------------------------------------------------------------
ARCHIVE_RULES = [
    ("nodule", lambda size, age, smk: "calcified granuloma" if size < 10 and smk < 10 else "pulmonary hamartoma" if size < 16 and smk < 10
     else "primary lung adenocarcinoma", "CT follow-up / biopsy"),
    ("mass", lambda size, age, smk: "squamous cell carcinoma" if smk >= 20 else "primary lung adenocarcinoma", "CT-guided biopsy"),
    ("consolidation", lambda size, age, smk: "community-acquired pneumonia" if age < 75 else "aspiration pneumonia", "clinical and radiological resolution"),
    ("pleural effusion", lambda size, age, smk: "heart failure (transudate)" if age >= 65 else "parapneumonic effusion", "thoracentesis (Light's criteria)"),
    ("pneumothorax", lambda size, age, smk: "primary spontaneous pneumothorax" if age < 40 else "secondary pneumothorax (COPD)", "clinical course"),
    ("cardiomegaly", lambda size, age, smk: "dilated cardiomyopathy" if age < 70 else "ischaemic cardiomyopathy", "echocardiography"),
    ("normal", lambda size, age, smk: "no abnormality", "clinical follow-up"),
]


def make_archive(rng: random.Random, n_per: int) -> dict[str, ArchivedCase]:
    out = {}
    k = 0
    for finding, rule, how in ARCHIVE_RULES:
        for _ in range(n_per):
            k += 1
            size = round(rng.uniform(6, 28), 1) if finding == "nodule" else round(rng.uniform(35, 70), 1) if finding == "mass" else None
            age = rng.randint(20, 38) if finding == "pneumothorax" and rng.random() < 0.6 else rng.randint(35, 88)
            smk = float(rng.choice([0, 0, 10, 25, 40]))
            modality = "CT" if finding == "nodule" and rng.random() < 0.5 else "CR"
            dx = rule(size or 0, age, smk)
            cid = f"ARC-{k:03d}"
            out[cid] = ArchivedCase(case_id=cid, modality=modality, finding=finding, side=rng.choice(["right", "left"]) if finding not in ("cardiomegaly", "normal") else "central",
                                    zone=rng.choice(["upper", "middle", "lower"]), size_mm=size, nodule_type="solid" if finding == "nodule" else None,
                                    age=age, sex=rng.choice(["female", "male"]), smoking_pack_years=smk, confirmed_diagnosis=dx, confirmation=how,
                                    summary=f"{finding} ({size:g} mm) in a {age}-year-old, {smk:g} pack-years: {dx}." if size else
                                    f"{finding} in a {age}-year-old, {smk:g} pack-years: {dx}.")
    return out


# -- tasks ------------------------------------------------------------------------------------------
def act(name: str, arguments: dict, compare: list[str] | None = None) -> dict:
    return {"name": name, "arguments": arguments, "compare_args": list(arguments) if compare is None else compare}


# The reference each generated task type's gold follows (in the task's provenance).
_GLOSSARY = "Fleischner Society Glossary of Terms for Thoracic Imaging (Hansell et al., Radiology 2008;246:697-722)"
_MEASURE = "Fleischner Society recommendations for measuring pulmonary nodules at CT (Bankier et al., Radiology 2017;285:584-600)"
GUIDELINES = {
    "cxr_principal_finding": _GLOSSARY, "cxr_laterality": _GLOSSARY, "cxr_zone": _GLOSSARY,
    "cxr_lesion_size": _GLOSSARY + " (nodule <= 3 cm, mass > 3 cm)",
    "cxr_cardiothoracic_ratio": "Cardiothoracic ratio on a PA radiograph, > 0.50 = cardiomegaly (Danzer 1919; " + _GLOSSARY + ")",
    "ct_nodule_count": _MEASURE, "ct_nodule_size": _MEASURE, "ct_nodule_type": _MEASURE,
    "ct_interval_change": _MEASURE + " (change in mean diameter)",
    "ct_fleischner": "Fleischner Society 2017 guidelines for incidental pulmonary nodules (MacMahon et al., Radiology 2017;284:228-243)",
}
# Equivalent phrasings of the Fleischner 2017 intervals.
FLEISCHNER_ALIASES = {"CT at 6-12 months": ["CT in 6 to 12 months", "follow-up CT at 6-12 months"],
                      "CT at 3-6 months": ["CT in 3 to 6 months", "follow-up CT at 3-6 months"],
                      "optional CT at 12 months": ["CT at 12 months (optional)"],
                      "no routine follow-up": ["no routine follow-up required"]}


def task_dict(task_id: str, ticket: str, study: Study, image_root: Path, *, answer: str, answer_type: str, task_type: str,
              actions: list[dict], category: str, options: dict | None = None, unit: str | None = None,
              tolerance: float | None = None, metadata: dict | None = None, aliases: list[str] | None = None,
              guideline: str | None = None) -> dict:
    t: dict[str, Any] = {
        "id": task_id, "ticket": ticket, "correct_answer": answer, "answer_type": answer_type,
        "image_path": str(image_root / study.image_file),
        "description": {"purpose": f"Image interpretation: {category}.", "difficulty": "medium", "source": "generated",
                        "category": category, "task_type": task_type,
                        "provenance": {**PROVENANCE, "guideline": guideline or GUIDELINES[task_type]}},
        "evaluation_criteria": {"actions": actions, "reward_basis": ["ACTION", "ANSWER"]},
        "metadata": {"study_id": study.study_id, **(metadata or {})},
    }
    for k, v in (("options", options), ("answer_unit", unit), ("answer_tolerance", tolerance)):
        if v is not None:
            t[k] = v
    if aliases:
        t["answer_aliases"] = aliases
    return t


def _intro(s: Study) -> str:
    kind = "PA chest radiograph" if s.modality == "CR" else "axial chest CT image"
    return f"{kind.capitalize()} {s.study_id} ({s.patient.age}-year-old {s.patient.sex}, {s.indication}; image attached)."


LETTERS = "ABCDE"
FINDING_LABEL = {"normal": "No abnormality", "nodule": "Pulmonary nodule", "mass": "Pulmonary mass", "consolidation": "Consolidation",
                 "pleural effusion": "Pleural effusion", "pneumothorax": "Pneumothorax", "cardiomegaly": "Cardiomegaly"}


def generate(seed: int, build_dir: Path) -> tuple[list[Study], dict[str, ArchivedCase], list[dict]]:
    rng = random.Random(seed)
    image_dir = build_dir / "images"
    studies: list[Study] = []
    tasks: list[dict] = []
    n = 100

    def new_id() -> str:
        nonlocal n
        n += 1
        return f"VIS-{n:03d}"

    for i in range(112):  # principal finding, multiple choice
        kind = CXR_KINDS[i % len(CXR_KINDS)]
        sid = new_id()
        s, truth = make_cxr(sid, rng, kind, image_dir)
        studies.append(s)
        others = [k for k in CXR_KINDS if k != kind]
        rng.shuffle(others)
        labels = [FINDING_LABEL[kind]] + [FINDING_LABEL[k] for k in others[:4]]
        rng.shuffle(labels)
        options = {LETTERS[j]: lab for j, lab in enumerate(labels)}
        gold = LETTERS[labels.index(FINDING_LABEL[kind])]
        ticket = _intro(s) + " " + rng.choice(["What is the principal finding?", "Which abnormality does the radiograph show, if any?",
                                              "Interpret the radiograph: what is the main finding?"])
        tasks.append(task_dict(f"vis_cxr_finding_{sid}", ticket, s, build_dir, answer=gold, answer_type="choice", options=options,
                               task_type="cxr_principal_finding", actions=[act("analyze_medical_image", {"study_id": sid})],
                               category="chest radiograph interpretation", metadata={"truth": truth}))
    for i in range(35):  # side
        kind = ["nodule", "mass", "consolidation", "pleural effusion", "pneumothorax"][i % 5]
        sid = new_id()
        s, truth = make_cxr(sid, rng, kind, image_dir, side=["right", "left"][(i // 5) % 2])
        studies.append(s)
        ticket = _intro(s) + f" There is a {kind}. On which side of the patient is it (left or right)?"
        tasks.append(task_dict(f"vis_cxr_side_{sid}", ticket, s, build_dir, answer=truth["side"], answer_type="exact",
                               task_type="cxr_laterality", actions=[act("analyze_medical_image", {"study_id": sid})],
                               category="chest radiograph interpretation", metadata={"truth": truth},
                               aliases=[f"{truth['side']} side", f"patient's {truth['side']}"]))
    for i in range(25):  # nodule size
        kind = "nodule" if i % 4 else "mass"
        sid = new_id()
        s, truth = make_cxr(sid, rng, kind, image_dir)
        studies.append(s)
        ticket = _intro(s) + f" Measure the {kind} on the image: what is its diameter in millimetres?"
        x, y = (int(round(c)) for c in truth["centroid_px"])
        tasks.append(task_dict(f"vis_cxr_size_{sid}", ticket, s, build_dir, answer=f"{truth['diameter_mm']:.1f}", answer_type="numeric",
                               unit="mm", tolerance=2.0, task_type="cxr_lesion_size",
                               actions=[act("analyze_medical_image", {"study_id": sid}),
                                        act("measure_lesion", {"study_id": sid, "x": x, "y": y}, ["study_id"])],
                               category="lesion measurement", metadata={"truth": truth}))
    for i in range(25):  # cardiothoracic ratio
        kind = "cardiomegaly" if i % 2 else "normal"
        sid = new_id()
        s, truth = make_cxr(sid, rng, kind, image_dir)
        studies.append(s)
        ticket = _intro(s) + " Measure the cardiothoracic ratio (two decimals)."
        tasks.append(task_dict(f"vis_cxr_ctr_{sid}", ticket, s, build_dir, answer=f"{truth['ctr']:.2f}", answer_type="numeric",
                               tolerance=0.03, task_type="cxr_cardiothoracic_ratio",
                               actions=[act("measure_cardiothoracic_ratio", {"study_id": sid})],
                               category="cardiac size", metadata={"truth": truth}))
    for i in range(25):  # zone
        kind = "consolidation" if i % 2 else "nodule"
        zone = ["upper", "middle", "lower"][i % 3]
        sid = new_id()
        s, truth = make_cxr(sid, rng, kind, image_dir, zone=zone)
        studies.append(s)
        ticket = _intro(s) + f" In which zone (upper, middle or lower) of the {truth['side']} lung is the {kind}?"
        tasks.append(task_dict(f"vis_cxr_zone_{sid}", ticket, s, build_dir, answer=truth["zone"], answer_type="exact",
                               task_type="cxr_zone", actions=[act("analyze_medical_image", {"study_id": sid})],
                               category="chest radiograph interpretation", metadata={"truth": truth},
                               aliases=[f"{truth['zone']} zone", f"{truth['side']} {truth['zone']} zone"]))
    # -- CT ----------------------------------------------------------------------------------------
    for i in range(40):  # count
        count = [0, 1, 2, 3][i % 4]
        sid = new_id()
        plan = [(rng.choice(["solid", "solid", "ground_glass", "part_solid"]), float(rng.randint(5, 14))) for _ in range(count)]
        s, truth, _ = make_ct(sid, rng, image_dir, plan)
        studies.append(s)
        ticket = _intro(s) + " How many pulmonary nodules (3 mm or larger) are on this image?"
        tasks.append(task_dict(f"vis_ct_count_{sid}", ticket, s, build_dir, answer=str(count), answer_type="numeric", tolerance=0,
                               task_type="ct_nodule_count", actions=[act("analyze_medical_image", {"study_id": sid})],
                               category="CT nodule detection", metadata={"truth": truth}))
    for i in range(45):  # size of the largest
        sid = new_id()
        k = 1 + (i % 2)
        means = sorted((round(rng.uniform(5, 18), 1) for _ in range(k)), reverse=True)
        if k == 2 and means[0] - means[1] < 2:
            means[1] = max(4.0, means[0] - 3)
        plan = [("solid", means[0])] + [(rng.choice(["solid", "ground_glass"]), m) for m in means[1:]]
        s, truth, _ = make_ct(sid, rng, image_dir, plan)
        studies.append(s)
        big = max(truth["nodules"], key=lambda q: q["long_mm"] + q["short_mm"])
        mean = round((big["long_mm"] + big["short_mm"]) / 2, 1)
        ticket = _intro(s) + " What is the mean diameter (average of long and short axes, mm) of the largest nodule?"
        tasks.append(task_dict(f"vis_ct_size_{sid}", ticket, s, build_dir, answer=f"{mean:.1f}", answer_type="numeric", unit="mm",
                               tolerance=1.0, task_type="ct_nodule_size", actions=[act("analyze_medical_image", {"study_id": sid})],
                               category="CT nodule measurement", metadata={"truth": truth}))
    types = ["solid", "part_solid", "ground_glass"]
    for i in range(30):  # type
        typ = types[i % 3]
        sid = new_id()
        s, truth, _ = make_ct(sid, rng, image_dir, [(typ, float(rng.randint(8, 16)))])
        studies.append(s)
        labels = {"solid": "Solid", "part_solid": "Part-solid", "ground_glass": "Pure ground-glass"}
        order = types[:]
        rng.shuffle(order)
        options = {LETTERS[j]: labels[t] for j, t in enumerate(order)}
        ticket = _intro(s) + " How should the nodule be characterised?"
        tasks.append(task_dict(f"vis_ct_type_{sid}", ticket, s, build_dir, answer=LETTERS[order.index(typ)], answer_type="choice",
                               options=options, task_type="ct_nodule_type", actions=[act("analyze_medical_image", {"study_id": sid})],
                               category="CT nodule characterisation", metadata={"truth": truth}))
    fleischner_plans = [("solid", 4.0, 1, False), ("solid", 4.0, 1, True), ("solid", 7.0, 1, False), ("solid", 7.0, 2, True),
                        ("solid", 11.0, 1, True), ("solid", 12.0, 2, False), ("ground_glass", 9.0, 1, False), ("part_solid", 10.0, 1, True),
                        ("solid", 6.0, 1, True), ("ground_glass", 5.0, 2, False), ("part_solid", 9.0, 2, False), ("solid", 9.0, 1, False)]
    for i in range(36):  # Fleischner from the measured nodule
        typ, mean, count, smoker = fleischner_plans[i % len(fleischner_plans)]
        sid = new_id()
        plan = [(typ, mean)] + [(typ if typ != "solid" else "solid", max(4.0, mean - 3.0))] * (count - 1)
        s, truth, _ = make_ct(sid, rng, image_dir, plan, smoker=smoker)
        studies.append(s)
        res = CALCULATORS["fleischner_recommendation"](nodule_type=typ, size_mm=mean, multiple=count > 1,
                                                       risk="high" if smoker else "low")
        actions = [act("analyze_medical_image", {"study_id": sid}), act("get_clinical_history", {"study_id": sid}),
                   act("fleischner_recommendation", {"study_id": sid}, ["study_id"])]
        if s.patient.known_malignancy:
            # Fleischner 2017 excludes known malignancy: the gold is oncologic follow-up and the
            # question does not presume the guideline applies.
            ticket = _intro(s) + (" What follow-up is appropriate for the nodule? If a guideline does not apply to this patient, "
                                  "say so and give the management that does.")
            tasks.append(task_dict(f"vis_ct_fleischner_{sid}", ticket, s, build_dir, answer=KNOWN_MALIGNANCY_MANAGEMENT, answer_type="exact",
                                   task_type="ct_fleischner", category="nodule in known malignancy", actions=actions,
                                   aliases=KNOWN_MALIGNANCY_ALIASES, guideline=KNOWN_MALIGNANCY_GUIDELINE,
                                   metadata={"truth": truth, "size_mm": mean, "multiple": count > 1, "smoker": smoker,
                                             "known_malignancy": s.patient.known_malignancy}))
            continue
        ticket = _intro(s) + " This is an incidental finding. What follow-up does the Fleischner Society 2017 guideline recommend?"
        tasks.append(task_dict(f"vis_ct_fleischner_{sid}", ticket, s, build_dir, answer=res.category, answer_type="exact",
                               task_type="ct_fleischner", category="incidental nodule management", actions=actions,
                               aliases=FLEISCHNER_ALIASES.get(res.category),
                               metadata={"truth": truth, "size_mm": mean, "multiple": count > 1, "smoker": smoker}))
    for i in range(30):  # growth against the prior
        sid = new_id()
        now = round(rng.uniform(7, 16), 1)
        change = [0.0, 0.4, 2.5, 3.5, 5.0, -2.0][i % 6]
        before = round(now - change, 1)
        s, truth, prior = make_ct(sid, rng, image_dir, [("solid", now)], prior_plan=[before])
        studies += [s, prior]
        delta = mean_change_mm(truth)
        ticket = _intro(s) + f" Compare with the prior CT ({prior.study_id}, 12 months ago). By how many millimetres has the nodule's mean diameter changed (negative if smaller)?"
        tasks.append(task_dict(f"vis_ct_growth_{sid}", ticket, s, build_dir, answer=f"{delta:.1f}", answer_type="numeric", unit="mm",
                               tolerance=1.0, task_type="ct_interval_change",
                               actions=[act("compare_with_prior", {"study_id": sid})],
                               category="nodule surveillance", metadata={"truth": truth}))
    archive = make_archive(rng, 9)
    return studies, archive, tasks


# -- authored workflows ------------------------------------------------------------------------------
AUTHORED_SEED = 2024
AUTHORED_PROVENANCE = {"source": "authored", "license": "project (ours)"}
AUTHORED_PURPOSE = "Authored image-interpretation workflow: analyse, measure, compare, retrieve, record and act."


def mean_change_mm(truth: dict) -> float:
    """The first nodule's mean diameter now minus on the prior (mm, 1 decimal)."""
    now, before = truth["nodules"][0], truth["prior_nodules"][0]
    return round((now["long_mm"] + now["short_mm"]) / 2 - (before["long_mm"] + before["short_mm"]) / 2, 1)


def _cxr_with_cardiomegaly(sid: str, rng: random.Random, image_dir: Path, image: Radiograph,
                           patient: PatientInfo, indication: str) -> tuple[Study, dict]:
    """A radiograph with the case's finding and cardiomegaly, kept when the analysis finds both (in that
    order) on the right side and the CTR within 0.02."""
    for _ in range(40):
        seed = rng.randint(0, 10 ** 9)
        spec, _ = cxr_spec(image.finding, rng, seed, side=image.side, zone=image.zone)
        spec["ctr"] = round(rng.uniform(0.57, 0.62), 4)
        img, _ = R.render_cxr(spec, seed)
        out = A.analyze_cxr(img, R.CXR_SPACING_MM)
        if [x["finding"] for x in out["findings"]] == [image.finding, "cardiomegaly"] and out["findings"][0]["side"] == image.side \
                and abs(out["cardiothoracic_ratio"] - spec["ctr"]) <= 0.02:
            write_png(image_dir / f"{sid}.png", img)
            study = Study(study_id=sid, modality="CR", body_part="chest", view="PA", image_file=f"images/{sid}.png", width=R.SIZE,
                          height=R.SIZE, pixel_spacing_mm=R.CXR_SPACING_MM, orientation=ORIENT_CXR, indication=indication,
                          acquired="today", patient=patient, provenance=AUTHORED_PROVENANCE)
            return study, {"finding": image.finding, "side": image.side, "ctr": spec["ctr"]}
    raise RuntimeError(f"could not render {sid}: {image.finding} with cardiomegaly that analyses as designed")


def _image_values(case: Case, truth: dict, patient: PatientInfo) -> dict[str, Callable[[], Any]]:
    """The values a case's placeholders may name (`case_schema.VALUES`), each computed when named."""
    image = case.image
    if isinstance(image, Radiograph):
        centroid = truth.get("centroid_px")
        return {"cardiothoracic_ratio": lambda: truth["ctr"], "lesion_diameter_mm": lambda: truth["diameter_mm"],
                "lesion_x": lambda: int(round(centroid[0])), "lesion_y": lambda: int(round(centroid[1]))}
    first = image.nodules[0]
    return {"first_nodule_side": lambda: truth["nodules"][0]["side"], "mean_diameter_change_mm": lambda: mean_change_mm(truth),
            "fleischner_recommendation": lambda: CALCULATORS["fleischner_recommendation"](
                nodule_type=first.type, size_mm=first.mean_mm, multiple=len(image.nodules) > 1,
                risk=patient.lung_cancer_risk).category}


def authored(build_dir: Path, folder: Path = CASES_DIR) -> tuple[list[Study], list[dict]]:
    """The studies and tasks of the authored cases (`cases/*.json`), rendered and verified like the
    generated ones; a comparison with a prior keeps the measured change as its truth."""
    rng = random.Random(AUTHORED_SEED)
    image_dir = build_dir / "images"
    studies: list[Study] = []
    tasks: list[dict] = []
    for case, guideline in load_cases(folder):
        p, image = case.patient, case.image
        patient = PatientInfo(age=p.age, sex=p.sex, history=p.history, smoking_pack_years=p.pack_years,
                              lung_cancer_risk="high" if p.pack_years >= 10 else "low", symptoms=list(p.symptoms),
                              known_malignancy=p.known_malignancy)
        own = {"patient": patient, "indication": case.indication, "provenance": AUTHORED_PROVENANCE}
        if isinstance(image, Radiograph) and image.with_cardiomegaly:
            study, rendered = _cxr_with_cardiomegaly(case.study_id, rng, image_dir, image, patient, case.indication)
            studies.append(study)
        elif isinstance(image, Radiograph):
            study, rendered = make_cxr(case.study_id, rng, image.finding, image_dir, side=image.side, zone=image.zone)
            studies.append(study := study.model_copy(update=own))
        else:
            study, rendered, prior = make_ct(case.study_id, rng, image_dir, [(n.type, n.mean_mm) for n in image.nodules],
                                             smoker=p.pack_years >= 10, prior_plan=image.prior_mean_mm)
            studies.append(study := study.model_copy(update=own))
            if prior is not None:
                studies.append(prior.model_copy(update={"patient": patient, "provenance": AUTHORED_PROVENANCE}))
        truth = {"delta_mm": mean_change_mm(rendered)} if isinstance(image, ChestCT) and image.prior_mean_mm is not None else rendered
        offered = {**_image_values(case, rendered, patient), "known_malignancy_management": lambda: KNOWN_MALIGNANCY_MANAGEMENT,
                   "known_malignancy_aliases": lambda: KNOWN_MALIGNANCY_ALIASES}
        values = {name: offered[name]() for name in placeholders([case.answer, case.answer_aliases,
                                                                  [a.arguments for a in case.actions]])}
        actions = [act(a.name, fill(a.arguments, values), a.compare_args) for a in case.actions]
        t: dict[str, Any] = {
            "id": case.id, "ticket": case.ticket, "correct_answer": fill(case.answer, values), "answer_type": case.answer_type,
            "image_path": str(build_dir / study.image_file),
            "description": {"purpose": AUTHORED_PURPOSE, "difficulty": "hard", "source": "authored", "category": case.category,
                            "task_type": "workflow", "provenance": {**AUTHORED_PROVENANCE, "guideline": guideline}},
            "evaluation_criteria": {"actions": actions, "nl_assertions": case.assertions,
                                    "reward_basis": ["ACTION", "ANSWER", "NL_ASSERTION"]},
            "metadata": {"study_id": study.study_id, "truth": truth,
                         **({"gold_reasoning": case.gold_reasoning} if case.gold_reasoning else {})},
        }
        for key, value in (("answer_unit", case.answer_unit), ("answer_tolerance", case.answer_tolerance),
                           ("options", case.options), ("emergency", case.emergency)):
            if value is not None:
                t[key] = value
        aliases = fill(case.answer_aliases, values)
        if aliases:
            t["answer_aliases"] = aliases
        tasks.append(t)
    return studies, tasks
