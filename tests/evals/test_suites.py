"""Suites: schema, loading, resolution to imported tasks, the missing-benchmark report.

Imports run the exact commands the missing report prints (PATH replaced by our fixtures) through
the real `hcgym` CLI into a temporary data folder.
"""

import shlex
from pathlib import Path

import pytest
from pydantic import ValidationError

from envs import cli
from evals.suites import SuiteError, TaskSelection, available_suites, load_suite, resolve

FIX = Path(__file__).parents[1] / "fixtures" / "benchmarks"


@pytest.fixture
def data_dir(tmp_path, monkeypatch):
    monkeypatch.setenv("HCGYM_DATA_DIR", str(tmp_path / "data"))
    return tmp_path / "data"


def run_printed_command(missing, benchmark, source, *, command_index=0, image_dir=None):
    """Run the import command the report printed for `benchmark`, with its PATH/... arguments
    replaced by our fixture file (and image folder)."""
    miss = next(m for m in missing if m.name == benchmark)
    argv = shlex.split(miss.commands[command_index])
    assert argv[:3] == ["hcgym", "tasks", "import"]
    paths = [i for i, a in enumerate(argv) if a.startswith("PATH/")]
    argv[paths[0]] = str(source)
    if len(paths) > 1:
        argv[paths[1]] = str(image_dir)
    assert cli.main(argv[1:]) == 0


def test_shipped_suites_validate():
    assert {"paper18", "gym-heldout", "gym-validation"} <= set(available_suites())
    paper = load_suite("paper18")
    names = [b.name for b in paper.benchmarks]
    # the paper's Table "Benchmark results": 16 rows, MMLU-Med aggregating 6 subjects
    assert names == ["medqa", "mmlu_med", "medmcqa", "vqa_rad", "pathvqa", "slake", "pmc_vqa", "vqa_med_2021",
                     "quilt_vqa", "mimic3", "eicu", "liveqa", "medicationqa", "healthsearchqa", "kqa_golden",
                     "kqa_silver"]
    assert len(paper.benchmarks[1].select.metadata["subject"]) == 6
    assert {b.metric for b in paper.benchmarks} == {"accuracy", "vqa_accuracy", "action_coverage", "long_form"}
    validation = load_suite("gym-validation")
    assert sum(b.select.limit for b in validation.benchmarks) == 307
    assert {b.select.domain: b.select.limit for b in validation.benchmarks}["medical_qa"] == 149


def test_resolution_reports_missing_benchmarks_and_imports_bring_them(data_dir):
    empty = resolve("paper18")
    assert empty.items == [] and len(empty.missing) == 16
    report = empty.missing_report()
    assert "16 of 16 benchmarks of suite `paper18` have no tasks yet" in report
    assert "`hcgym tasks import --format pmc-vqa PATH/test_clean.csv --image-dir PATH/images`" in report
    assert f"--output {data_dir / 'imported' / 'medical_qa'}/mmlu_anatomy.json" in report

    run_printed_command(empty.missing, "medqa", FIX / "medqa.jsonl")
    run_printed_command(empty.missing, "mmlu_med", FIX / "anatomy_test.csv", command_index=2)
    run_printed_command(empty.missing, "pmc_vqa", FIX / "pmc_vqa.csv", image_dir=FIX / "vqa_images")
    run_printed_command(empty.missing, "vqa_med_2021", FIX / "vqa_med_2021.txt", image_dir=FIX / "vqa_images")
    run_printed_command(empty.missing, "quilt_vqa", FIX / "quilt_vqa.json", image_dir=FIX / "vqa_images")

    resolved = resolve("paper18")
    counts = {b.spec.name: len(b.items) for b in resolved.benchmarks}
    assert counts == {"medqa": 1, "mmlu_med": 2, "pmc_vqa": 2, "vqa_med_2021": 2, "quilt_vqa": 2}
    assert {m.name for m in resolved.missing} == {"medmcqa", "vqa_rad", "pathvqa", "slake", "mimic3", "eicu", "liveqa",
                                                  "medicationqa", "healthsearchqa", "kqa_golden", "kqa_silver"}
    item = resolved.benchmarks[0].items[0]
    assert (item.benchmark, item.domain, item.split) == ("medqa", "medical_qa", "imported")
    assert item.task_id.startswith("medqa_")
    # VQA tasks land in the vision domain, by the CLI's default for these formats
    assert {i.domain for b in resolved.benchmarks if b.spec.category == "Visual QA" for i in b.items} == {"visual_diagnosis"}


def test_medlfqa_subsets_are_told_apart_by_their_file(data_dir, tmp_path):
    live = tmp_path / "live_qa.jsonl"
    live.write_text((FIX / "medlfqa.jsonl").read_text(encoding="utf-8"), encoding="utf-8")
    missing = resolve("paper18").missing
    run_printed_command(missing, "liveqa", live)
    resolved = resolve("paper18")
    assert [b.spec.name for b in resolved.benchmarks] == ["liveqa"]
    assert "kqa_golden" in {m.name for m in resolved.missing}


def test_single_benchmark_names_and_errors(data_dir, tmp_path):
    single = load_suite("medqa")
    assert [b.name for b in single.benchmarks] == ["medqa"] and single.benchmarks[0].title == "MedQA (USMLE)"
    assert resolve("medqa").missing[0].name == "medqa"
    with pytest.raises(SuiteError, match=r"unknown suite or benchmark 'nope'; suites: gym-calculators, gym-heldout"):
        load_suite("nope")
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: bad\nbenchmarks:\n  - {name: x, title: X, category: c, metric: f1, select: {domain: medical_qa}}\n")
    with pytest.raises(SuiteError, match=r"bad.yaml: benchmarks.0.metric: Input should be"):
        load_suite(str(bad))
    with pytest.raises(SuiteError, match="suite file not found"):
        load_suite(str(tmp_path / "missing.yaml"))
    unknown_domain = tmp_path / "dom.yaml"
    unknown_domain.write_text("name: d\nbenchmarks:\n  - {name: x, title: X, category: c, metric: gym, select: {domain: dentistry, split: test}}\n")
    with pytest.raises(SuiteError, match="unknown domain 'dentistry'"):
        resolve(str(unknown_domain))


def test_gym_suites_resolve_to_the_built_splits():
    validation = resolve("gym-validation")
    assert validation.missing == [] and len(validation.items) == 307
    per_domain = {b.spec.select.domain: len(b.items) for b in validation.benchmarks}
    assert per_domain == {"medical_qa": 149, "visual_diagnosis": 37, "clinical_diagnosis": 25, "drug_interaction": 25,
                          "ehr_management": 25, "triage_emergency": 20, "psychiatry": 20, "obstetrics": 6}
    # drug_interaction has no validation split: a seeded sample of its test split, the same every time
    drug = [i.task_id for i in validation.items if i.domain == "drug_interaction"]
    assert drug == [i.task_id for i in resolve("gym-validation").items if i.domain == "drug_interaction"]
    assert {i.split for i in validation.items if i.domain == "drug_interaction"} == {"test"}
    heldout = resolve("gym-heldout")
    from envs import registry

    # one benchmark per registered domain: the ten built-in ones and the tests' ward domain
    domains = [b.spec.select.domain for b in heldout.benchmarks]
    assert domains == registry.list_domains() and heldout.missing == []
    assert len([d for d in domains if registry.DOMAINS[d].startswith("envs.domains.")]) == 10
    assert {i.split for i in heldout.items} == {"test"}


def test_task_id_pattern_selects_the_demo_calculator_set():
    calculators = resolve("gym-calculators")
    ids = [i.task_id for i in calculators.items]
    # the demo's validation set: triage_emergency test tasks whose id starts with tr_calc_ (44 of them)
    from envs import registry

    expected = sorted(t.id for t in registry.get_tasks("triage_emergency", "test") if t.id.startswith("tr_calc_"))
    assert ids == expected and len(ids) == 44
    assert len(registry.get_tasks("triage_emergency", "test")) > len(ids)  # the pattern did filter
    with pytest.raises(ValidationError, match="task_id_pattern"):
        TaskSelection(domain="triage_emergency", split="test", task_id_pattern="(")
