"""Visual-diagnosis domain: the PNG codec, rendering/analysis agreement, every tool on known images,
the tools reproduce every task's gold answer from the pixels, splits, gold replay, speed."""

from __future__ import annotations

import collections
import statistics
import time
import zlib

import numpy as np
import pytest

from envs import registry
from envs.validate import check_domain_contamination
from envs.core.tools import ToolError
from envs.domains.visual_diagnosis import build as vis_build
from envs.domains.visual_diagnosis import png
from envs.domains.visual_diagnosis.case_schema import load_cases, placeholders

registry.DOMAINS.setdefault("visual_diagnosis", "envs.domains.visual_diagnosis.environment")


def use(toolkit, tool: str, **arguments):
    outcome = toolkit.call(tool, arguments)
    if outcome.error:
        raise ToolError(outcome.error)
    return outcome.result


@pytest.fixture(scope="module")
def built():
    return vis_build.build()


@pytest.fixture
def env(built):
    return registry.get_environment("visual_diagnosis")


@pytest.fixture
def tk(env):
    return env.toolkit


@pytest.fixture(scope="module")
def tasks(built):
    return registry.get_tasks("visual_diagnosis")


def test_png_roundtrip_and_filters():
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (17, 23), dtype=np.uint8)
    assert np.array_equal(png.decode_png(png.encode_png(img)), img)
    # A PNG written with the Sub (1) and Paeth (4) filters decodes to the same pixels.
    rows = []
    prev = np.zeros(23, dtype=np.int32)
    for y, row in enumerate(img.astype(np.int32)):
        if y % 2 == 0:
            left = np.concatenate(([0], row[:-1]))
            rows.append(b"\x01" + ((row - left) & 0xFF).astype(np.uint8).tobytes())
        else:
            out = []
            for x in range(23):
                a, b, c = (row[x - 1] if x else 0), prev[x], (prev[x - 1] if x else 0)
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                pred = a if pa <= pb and pa <= pc else b if pb <= pc else c
                out.append((row[x] - pred) & 0xFF)
            rows.append(b"\x04" + bytes(out))
        prev = row
    data = png.encode_png(img)
    head, _, tail = data.partition(b"IDAT")
    raw = zlib.compress(b"".join(rows))
    import struct
    chunk = struct.pack(">I", len(raw)) + b"IDAT" + raw + struct.pack(">I", zlib.crc32(b"IDAT" + raw) & 0xFFFFFFFF)
    rebuilt = head[:-4] + chunk + png._chunk(b"IEND", b"")
    assert np.array_equal(png.decode_png(rebuilt), img)
    with pytest.raises(ValueError, match="signature"):
        png.decode_png(b"GIF89a")


def test_tools_on_authored_images(tk):
    meta = use(tk, "get_study_metadata", study_id="vis-001")
    assert meta["pixel_spacing_mm"] == 1.4 and "patient's right is on the image left" in meta["orientation"]
    a = use(tk, "analyze_medical_image", study_id="VIS-001")
    assert [f["finding"] for f in a["findings"]] == ["pneumothorax"] and a["findings"][0]["side"] == "right"
    assert a["image_statistics"]["pixels"] == 256 * 256
    two = use(tk, "analyze_medical_image", study_id="VIS-003")
    assert [f["finding"] for f in two["findings"]] == ["pleural effusion", "cardiomegaly"]
    assert use(tk, "measure_cardiothoracic_ratio", study_id="VIS-003")["cardiomegaly"] is True
    assert use(tk, "measure_cardiothoracic_ratio", study_id="VIS-009")["cardiomegaly"] is False
    nodule = next(f for f in use(tk, "analyze_medical_image", study_id="VIS-007")["findings"] if f["finding"] == "nodule")
    x, y = (int(round(c)) for c in nodule["centroid_px"])
    m = use(tk, "measure_lesion", study_id="VIS-007", x=x, y=y)
    assert abs(m["equivalent_diameter_mm"] - nodule["diameter_mm"]) <= 1.0
    with pytest.raises(ToolError, match="does not stand out"):
        use(tk, "measure_lesion", study_id="VIS-007", x=5, y=5)
    roi = use(tk, "get_region_statistics", study_id="VIS-007", x0=0, y0=0, x1=9, y1=9)
    assert roi["pixels"] == 100 and roi["mean"] < 20
    ct = use(tk, "analyze_medical_image", study_id="VIS-014")
    assert ct["nodule_count"] == 3 and {n["type"] for n in ct["nodules"]} == {"solid", "ground_glass"}
    cmp = use(tk, "compare_with_prior", study_id="VIS-004")
    assert cmp["nodules"][0]["status"] == "growing" and cmp["nodules"][0]["volume_ratio"] > 2
    assert use(tk, "compare_with_prior", study_id="VIS-015")["nodules"][0]["status"] == "shrinking"
    with pytest.raises(ToolError, match="no prior"):
        use(tk, "compare_with_prior", study_id="VIS-013")
    assert use(tk, "fleischner_recommendation", study_id="VIS-017")["category"] == "CT at 3 months, PET/CT or tissue sampling"
    with pytest.raises(ToolError, match="measured on CT"):
        use(tk, "fleischner_recommendation", study_id="VIS-001")
    sign = use(tk, "lookup_imaging_sign", term="CTR")
    assert sign["term"] == "cardiothoracic ratio"
    with pytest.raises(ToolError, match="not in the glossary"):
        use(tk, "lookup_imaging_sign", term="zebra sign")


def test_similar_cases(tk):
    res = use(tk, "search_similar_cases", study_id="VIS-008")
    assert res["query"]["finding"] == "mass" and next(iter(res["diagnosis_counts"])) == "squamous cell carcinoma"
    assert next(iter(use(tk, "search_similar_cases", study_id="VIS-002")["diagnosis_counts"])) == "community-acquired pneumonia"
    assert next(iter(use(tk, "search_similar_cases", study_id="VIS-012")["diagnosis_counts"])) == "secondary pneumothorax (COPD)"
    case = use(tk, "get_case_report", case_id=res["cases"][0]["case_id"])
    assert case["finding"] == "mass" and case["confirmed_diagnosis"]
    with pytest.raises(ToolError, match="finding must be one of"):
        use(tk, "search_similar_cases", finding="tumour")


def test_records_change_state(env, tk):
    h0 = env.db_hash()
    use(tk, "record_finding", study_id="VIS-016", finding="Pleural effusion", side="left", location="left base")
    use(tk, "escalate_critical_finding", study_id="VIS-001", finding="tension pneumothorax", recipient="ED team")
    assert len(tk.db.recorded_findings) == 1 and len(tk.db.escalations) == 1 and env.db_hash() != h0
    h1 = env.db_hash()
    bad = tk.call("record_finding", {"study_id": "VIS-016", "finding": "effusion", "side": "left", "location": "x"})
    assert bad.error and "finding must be one of" in bad.error and env.db_hash() == h1
    assert registry.get_environment("visual_diagnosis").db_hash() == h0


def test_tools_reproduce_every_gold_answer(tasks, tk):
    checked = collections.Counter()
    for t in tasks:
        sid = t.metadata["study_id"]
        tt = t.description.task_type
        truth = t.metadata.get("truth", {})
        if tt == "cxr_principal_finding":
            found = [f["finding"] for f in use(tk, "analyze_medical_image", study_id=sid)["findings"]]
            label = t.options[t.correct_answer].lower()
            assert (found == [] and label == "no abnormality") or (found and found[0] in label), (t.id, found, label)
        elif tt == "cxr_laterality":
            f = use(tk, "analyze_medical_image", study_id=sid)["findings"][0]
            assert f["side"] == t.correct_answer, t.id
        elif tt == "cxr_lesion_size":
            x, y = (int(round(c)) for c in truth["centroid_px"])
            assert abs(use(tk, "measure_lesion", study_id=sid, x=x, y=y)["equivalent_diameter_mm"] - float(t.correct_answer)) <= t.answer_tolerance, t.id
        elif tt == "cxr_cardiothoracic_ratio":
            assert abs(use(tk, "measure_cardiothoracic_ratio", study_id=sid)["cardiothoracic_ratio"] - float(t.correct_answer)) <= 0.03, t.id
        elif tt == "cxr_zone":
            assert use(tk, "analyze_medical_image", study_id=sid)["findings"][0]["zone"] == t.correct_answer, t.id
        elif tt == "ct_nodule_count":
            assert use(tk, "analyze_medical_image", study_id=sid)["nodule_count"] == int(t.correct_answer), t.id
        elif tt == "ct_nodule_size":
            largest = use(tk, "analyze_medical_image", study_id=sid)["nodules"][0]
            assert abs(largest["mean_diameter_mm"] - float(t.correct_answer)) <= 0.6, t.id
        elif tt == "ct_nodule_type":
            kind = use(tk, "analyze_medical_image", study_id=sid)["nodules"][0]["type"]
            assert t.options[t.correct_answer].lower().replace("pure ", "").replace("-", "_") == kind, t.id
        elif tt == "ct_fleischner":
            assert use(tk, "fleischner_recommendation", study_id=sid)["category"] == t.correct_answer, t.id
        elif tt == "ct_interval_change":
            assert abs(use(tk, "compare_with_prior", study_id=sid)["nodules"][0]["change_mm"] - float(t.correct_answer)) <= 0.6, t.id
        checked[tt] += 1
    assert sum(checked.values()) >= 400


def test_tasks_counts_splits_images(tasks):
    generated = [t for t in tasks if t.description.source == "generated"]
    authored = [t for t in tasks if t.description.source == "authored"]
    assert len(generated) >= 400 and len(authored) >= 20
    splits = registry.get_splits("visual_diagnosis")
    assert len(splits["validation"]) == 37
    train, test, val = (set(splits[k]) for k in ("train", "test", "validation"))
    assert not (train & test or train & val or test & val) and train | test | val == {t.id for t in tasks}
    for t in tasks:
        assert t.image_path and t.image_path.endswith(".png") and png.read_png(t.image_path).shape == (256, 256)
        assert t.has_gold_answer and t.evaluation_criteria.actions
    for t in authored:
        assert len(t.evaluation_criteria.actions) >= 2 and len(t.evaluation_criteria.nl_assertions) >= 2
    # every authored case file's case is built, with its file's guideline and no placeholder left unfilled
    guideline = {case.id: g for case, g in load_cases()}
    assert sorted(t.id for t in authored) == sorted(guideline)
    for t in authored:
        assert t.description.provenance["guideline"] == guideline[t.id]
        assert not placeholders([t.correct_answer, t.answer_aliases, [a.arguments for a in t.evaluation_criteria.actions]]), t.id


def test_no_held_out_leaks(tasks):
    assert check_domain_contamination("visual_diagnosis") == []


def test_gold_replay(tasks):
    from envs.validate import validate_task

    definitions = registry.get_environment("visual_diagnosis").toolkit.definitions
    sample = [t for t in tasks if t.description.source == "authored"]
    sample += list({t.description.task_type: t for t in tasks if t.description.source == "generated"}.values())
    for t in sample:
        report = validate_task(t, "visual_diagnosis", definitions)
        assert report.ok, (t.id, report.problems)
        assert report.reward_components.get("safety") == 1.0, (t.id, report.reward_components)


def test_reset_and_tool_latency(tasks):
    registry.get_environment("visual_diagnosis")
    start = time.perf_counter()
    for _ in range(50):
        registry.get_environment("visual_diagnosis").db_hash()
    assert (time.perf_counter() - start) / 50 < 0.01
    times = collections.defaultdict(list)
    env = registry.get_environment("visual_diagnosis")
    for t in tasks[::3]:
        for a in t.evaluation_criteria.actions:
            if a.name in ("record_finding", "escalate_critical_finding"):
                continue
            start = time.perf_counter()
            out = env.toolkit.call(a.name, a.arguments)
            times[a.name].append(time.perf_counter() - start)
            assert out.ok, (t.id, a.name, out.error)
    for name, values in times.items():
        assert statistics.median(values) < 0.005, (name, statistics.median(values))
