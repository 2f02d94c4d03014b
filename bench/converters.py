"""Converters on full-size inputs: time and peak memory of `envs.converters` on files generated in a
temporary folder at the size of the real releases, each against a baseline measured in the same run.

    python bench/converters.py [--medmcqa-rows 182822] [--labevents-rows 2000000] [--max-stays 200]

Inputs (written by this script in the official layouts, synthetic rows; no dataset is read):
* MedQA: US 4-option train set size, 10,178 JSON lines;
* MedMCQA: train set size, 182,822 JSON lines (Hugging Face 0-3 `cop`);
* MIMIC-III: the seven tables as `.csv.gz`, upper-case headers, 5,000 patients / 6,000 admissions /
  7,000 ICU stays, LABEVENTS of `--labevents-rows` rows (the full release has 27.9 million; 2 million
  keeps the run short on a shared machine and is enough to see whether memory follows the file).

Baselines:
* MedQA / MedMCQA: reading the same file with `json.loads` per line and nothing else (the floor any
  converter pays): the ratio is the converter's cost over plain parsing.
* MIMIC-III: the converter at commit 90ccea4 (`git show`), which kept the lab
  results of every admission while streaming LABEVENTS; both convert the same `--max-stays` stays.

Each measurement runs in its own Python process; peak memory is that process's maximum resident set
size (`resource.getrusage`), so the interpreter and imports are included in every figure.
"""

from __future__ import annotations

import argparse
import csv
import gzip
import json
import random
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
BASELINE_COMMIT = "90ccea4"

MEASURE = textwrap.dedent('''
    import json, resource, sys, time
    sys.path.insert(0, {root!r})
    {setup}
    started = time.perf_counter()
    {body}
    seconds = time.perf_counter() - started
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(json.dumps({{"seconds": seconds, "peak_mb": peak, "count": count}}))
''')


def run(body: str, setup: str = "pass") -> dict:
    """Time `body` (after `setup`, e.g. imports) in a fresh process; it must set `count`."""
    code = MEASURE.format(root=str(ROOT), setup=setup, body=textwrap.dedent(body).strip())
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    if out.returncode != 0:
        raise RuntimeError(out.stderr[-2000:])
    return json.loads(out.stdout.strip().splitlines()[-1])


def write_medqa(path: Path, rows: int, rng: random.Random) -> None:
    with path.open("w", encoding="utf-8") as handle:
        for i in range(rows):
            options = {k: f"option {k} for question {i} " + "x" * rng.randint(5, 30) for k in "ABCD"}
            answer = rng.choice("ABCD")
            stem = f"A {rng.randint(18, 90)}-year-old presents with finding {i}. " + "History detail. " * 20
            handle.write(json.dumps({"question": stem + "Which is the best next step?", "answer": options[answer],
                                     "options": options, "meta_info": "step1", "answer_idx": answer,
                                     "metamap_phrases": ["finding", "history"]}) + "\n")


def write_medmcqa(path: Path, rows: int, rng: random.Random) -> None:
    with path.open("w", encoding="utf-8") as handle:
        for i in range(rows):
            handle.write(json.dumps({"id": f"q{i:08x}", "question": f"Question {i} about topic {rng.randint(0, 999)}?",
                                     "opa": f"a{i}", "opb": f"b{i}", "opc": f"c{i}", "opd": f"d{i}",
                                     "cop": rng.randint(0, 3), "choice_type": "single", "exp": "Explanation. " * 5,
                                     "subject_name": "Medicine", "topic_name": "General"}) + "\n")


def write_mimic(folder: Path, labevents: int, rng: random.Random) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    from envs.converters.ehr import MIMIC3_COLUMNS

    def table(name: str, rows):
        with gzip.open(folder / f"{name}.csv.gz", "wt", encoding="utf-8", newline="", compresslevel=1) as handle:
            writer = csv.writer(handle, quoting=csv.QUOTE_MINIMAL)
            writer.writerow(MIMIC3_COLUMNS[name])
            writer.writerows(rows)

    patients, admissions, stays = 5000, 6000, 7000
    table("PATIENTS", ([i, 1000 + i, rng.choice("MF"), "2100-01-01 00:00:00", "", "", "", 0] for i in range(patients)))
    adm_rows = []
    for i in range(admissions):
        subject = 1000 + (i % patients)
        adm_rows.append([i, subject, 100000 + i, "2150-01-01 08:00:00", "2150-01-20 12:00:00", "", "EMERGENCY",
                         "EMERGENCY ROOM ADMIT", "HOME", "Medicare", "ENGL", "", "MARRIED", "WHITE", "", "",
                         "SEPSIS", 0, 1])
    table("ADMISSIONS", adm_rows)
    stay_rows = []
    for i in range(stays):
        adm = i % admissions
        seconds = rng.randint(3600, 10 * 86400)
        from datetime import datetime, timedelta

        intime = datetime(2150, 1, 2, 9, 0, rng.randint(0, 59)) + timedelta(days=i // admissions * 11)
        outtime = intime + timedelta(seconds=seconds)
        stay_rows.append([i, 1000 + (adm % patients), 100000 + adm, 200000 + i, "metavision", "MICU", "MICU", 50, 50,
                          intime.strftime("%Y-%m-%d %H:%M:%S"), outtime.strftime("%Y-%m-%d %H:%M:%S"),
                          f"{seconds / 86400:.4f}"])
    table("ICUSTAYS", stay_rows)
    items = [(50912, "Creatinine"), (50971, "Potassium"), (50983, "Sodium"), (51222, "Hemoglobin"),
             (50813, "Lactate"), (50902, "Chloride"), (50882, "Bicarbonate"), (51006, "Urea Nitrogen")]
    table("D_LABITEMS", ([i, item, label, "Blood", "Chemistry", ""] for i, (item, label) in enumerate(items)))

    def labs():
        for i in range(labevents):
            adm = rng.randrange(admissions)
            item, _ = items[i % len(items)]
            day, minute = rng.randint(2, 19), rng.randint(0, 1439)
            value = round(rng.uniform(0.5, 5.0), 2)
            yield [i, 1000 + (adm % patients), 100000 + adm, item,
                   f"2150-01-{day:02d} {minute // 60:02d}:{minute % 60:02d}:00", value, value, "mg/dL", ""]

    table("LABEVENTS", labs())
    table("DIAGNOSES_ICD", ([i, 1000 + (i % admissions) % patients, 100000 + (i % admissions), i // admissions + 1,
                             rng.choice(["0389", "5849", "4280", "V4581"])] for i in range(admissions * 3)))
    table("D_ICD_DIAGNOSES", ([i, code, code, f"title {code}"] for i, code in enumerate(["0389", "5849", "4280", "V4581"])))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--medqa-rows", type=int, default=10178)
    parser.add_argument("--medmcqa-rows", type=int, default=182822)
    parser.add_argument("--labevents-rows", type=int, default=2_000_000)
    parser.add_argument("--max-stays", type=int, default=200)
    args = parser.parse_args()
    rng = random.Random(15)
    with tempfile.TemporaryDirectory(prefix="hcgym-bench-converters-") as tmp:
        tmp_path = Path(tmp)
        medqa, medmcqa, mimic = tmp_path / "medqa_train.jsonl", tmp_path / "medmcqa_train.json", tmp_path / "mimic3"
        write_medqa(medqa, args.medqa_rows, rng)
        write_medmcqa(medmcqa, args.medmcqa_rows, rng)
        write_mimic(mimic, args.labevents_rows, rng)
        baseline_ehr = tmp_path / "ehr_before_issue_15.py"
        shown = subprocess.run(["git", "-C", str(ROOT), "show", f"{BASELINE_COMMIT}:envs/converters/ehr.py"],
                               capture_output=True, text=True, check=False)
        baseline_ehr.write_text(shown.stdout if shown.returncode == 0 else "", encoding="utf-8")

        def plain(path: Path) -> str:
            return f"count = sum(1 for line in open({str(path)!r}, encoding='utf-8') if json.loads(line))"

        def converter(fmt: str, path: Path) -> str:
            return (f"result = convert({fmt!r}, {str(path)!r})\n"
                    f"count = len(result.tasks)\nassert not result.errors, result.errors[:3]")

        rows = []
        for name, fmt, path, size in (("MedQA", "medqa", medqa, args.medqa_rows),
                                      ("MedMCQA", "medmcqa", medmcqa, args.medmcqa_rows)):
            base, new = run(plain(path)), run(converter(fmt, path), "from envs.converters import convert")
            rows.append((f"{name} ({size:,} rows, {path.stat().st_size / 1e6:.0f} MB)", "json.loads per line", base, new))
        new = run(f"result = convert('mimic3', {str(mimic)!r}, max_stays={args.max_stays})\ncount = len(result.tasks)",
                  "from envs.converters import convert")
        if baseline_ehr.stat().st_size:
            load_old = (f"import importlib.util; spec = importlib.util.spec_from_file_location('old_ehr', "
                        f"{str(baseline_ehr)!r}); old = importlib.util.module_from_spec(spec); "
                        f"sys.modules['old_ehr'] = old; spec.loader.exec_module(old)")
            base = run(f"result = old.convert_mimic3({str(mimic)!r}, max_stays={args.max_stays})\n"
                       f"count = len(result.tasks)", load_old)
        else:
            base = None
        size = sum(p.stat().st_size for p in mimic.iterdir()) / 1e6
        rows.append((f"MIMIC-III ({args.labevents_rows:,} LABEVENTS rows, {size:.0f} MB gz, --max-stays {args.max_stays})",
                     f"converter at {BASELINE_COMMIT}", base, new))

    print(f"{'input':70s} {'baseline':24s} {'base s':>8s} {'base MB':>8s} {'new s':>8s} {'new MB':>8s} "
          f"{'time x':>7s} {'mem x':>6s} {'tasks':>7s} {'base tasks':>10s}")
    for label, base_name, base, new in rows:
        if base is None:
            print(f"{label:70s} {base_name:24s} (baseline unavailable: git show failed) {new['seconds']:8.2f} "
                  f"{new['peak_mb']:8.0f}")
            continue
        print(f"{label:70s} {base_name:24s} {base['seconds']:8.2f} {base['peak_mb']:8.0f} {new['seconds']:8.2f} "
              f"{new['peak_mb']:8.0f} {new['seconds'] / base['seconds']:7.2f} {new['peak_mb'] / base['peak_mb']:6.2f} "
              f"{new['count']:7d} {base['count']:10d}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
