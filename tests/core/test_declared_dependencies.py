"""Every third-party module the shipped packages import is declared in pyproject.toml, as a
dependency or in an extra: a module that only arrives as another package's dependency breaks the
day that package drops it, and a fresh install without the extra that happened to bring it fails
at import (visual_diagnosis imported scipy, which only sentence-transformers pulled in)."""

from __future__ import annotations

import ast
import re
import sys
import tomllib
from importlib.metadata import packages_distributions
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = ("envs", "kb_service", "actors", "learner", "modeling", "evals", "viewer")
# Modules whose distribution is not installed in the test venv, with the name it is declared under.
NOT_INSTALLED_HERE = {"vllm": "vllm"}  # the gpu extra; the CPU build lives in .venv-vllm


def _normalise(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def imported_top_level_modules(packages=SHIPPED) -> dict[str, str]:
    """Top-level module -> the first file that imports it (absolute imports, any depth in the file)."""
    found: dict[str, str] = {}
    for package in packages:
        for path in sorted((ROOT / package).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if isinstance(node, ast.Import):
                    names = [alias.name for alias in node.names]
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    names = [node.module]
                else:
                    continue
                for name in names:
                    found.setdefault(name.split(".")[0], str(path.relative_to(ROOT)))
    return found


def declared_distributions() -> set[str]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    requirements = list(project["dependencies"])
    for extra in project.get("optional-dependencies", {}).values():
        requirements += extra
    return {_normalise(re.match(r"[A-Za-z0-9_.\-]+", req).group(0)) for req in requirements}


def undeclared(modules: dict[str, str], declared: set[str]) -> list[str]:
    first_party = set(SHIPPED) | {"tests"}
    distributions = packages_distributions()
    missing = []
    for module, where in sorted(modules.items()):
        if module in sys.stdlib_module_names or module in first_party:
            continue
        names = distributions.get(module) or [NOT_INSTALLED_HERE.get(module, module)]
        if not any(_normalise(name) in declared for name in names):
            missing.append(f"{module} (distribution {names[0]}, imported by {where})")
    return missing


def test_every_imported_third_party_module_is_declared():
    missing = undeclared(imported_top_level_modules(), declared_distributions())
    assert not missing, "imported but not declared in pyproject.toml (dependencies or an extra): " + "; ".join(missing)


def test_the_check_names_an_undeclared_import(tmp_path):
    modules = {"scipy": "envs/domains/visual_diagnosis/render.py", "numpy": "envs/x.py", "json": "envs/y.py"}
    missing = undeclared(modules, {"numpy"})
    assert missing == ["scipy (distribution scipy, imported by envs/domains/visual_diagnosis/render.py)"]
