"""`hcgym data build`: run every data builder in order.

A builder is a module with `build(offline: bool = False, force: bool = False) -> dict` that
writes its output under `envs.core.paths.data_dir()` deterministically and returns a summary of
counts. A domain's builder is its folder's `build.py` (found with the folder: `envs.registry`); a builder
that is not a domain's is listed in BUILDERS. A domain builder that reads another
domain's built data declares it in its own `BUILD_REQUIRES` and runs after it
(`envs.core.build_order.ordered_builders`), whatever its place in the list. Builders read registry packages only
through `envs.data.registry.open_package`, which hands out a package's wheel after checking it
against its pinned sha256 (a new package is pinned in `registry.SOURCES` first).
"""

from __future__ import annotations

import importlib
import time

from envs.core.build_order import ordered_builders
from envs.registry import DOMAINS, DOMAINS_DIR

#: Every domain folder's `build.py` (by domain name), then the knowledge base.
BUILDERS: list[str] = [f"envs.domains.{path.parent.name}.build" for path in sorted(DOMAINS_DIR.glob("*/build.py"))
                       if path.parent.name in DOMAINS] + ["kb_service.build_default"]


def run_builders(names: list[str] | None = None, *, offline: bool = False, force: bool = False,
                 echo=print) -> dict[str, dict]:
    summaries: dict[str, dict] = {}
    for module_name in ordered_builders(BUILDERS):
        short = module_name.rsplit(".", 2)[-2] if module_name.endswith(".build") else module_name
        if names and short not in names and module_name not in names:
            continue
        start = time.perf_counter()
        module = importlib.import_module(module_name)
        echo(f"[data] {short}: building ...")
        summary = module.build(offline=offline, force=force)
        echo(f"[data] {short}: {summary} ({time.perf_counter() - start:.1f}s)")
        summaries[short] = summary
    return summaries
