"""Build-order dependencies between domains, declared instead of held by comments.

A domain whose build or tools read another domain's BUILT DATA (not its code) declares it at the
top of its `build.py`:

    BUILD_REQUIRES = ("clinical_diagnosis",)   # reads its built ICD-10-CM index

`ordered_builders` puts every builder after the builders it requires (`hcgym data build` runs
them in that order), and the requiring build calls `build_required_domains(BUILD_REQUIRES, ...)`
first, so building one domain alone still finds its inputs. The declaration is read from the
source with `ast` (no import), so ordering never runs a builder's import-time code. The domain
contract test allows an import from one domain into another only where this declares it.
"""

from __future__ import annotations

import ast
import importlib
import importlib.util
from pathlib import Path

DOMAIN_BUILD_MODULE = "envs.domains.{name}.build"


def declared_build_requires(module_name: str) -> tuple[str, ...]:
    """The `BUILD_REQUIRES` names a builder module declares (empty when it declares none).

    Args:
        module_name: Dotted module path of the builder, e.g. "envs.domains.ehr_management.build".
    """
    spec = importlib.util.find_spec(module_name)
    if spec is None or spec.origin is None:
        raise ModuleNotFoundError(f"builder module {module_name!r} not found")
    return build_requires_in_source(Path(spec.origin))


def build_requires_in_source(path: Path) -> tuple[str, ...]:
    """`BUILD_REQUIRES` of a build.py, read with ast; a clear error when it is not a tuple/list of names.

    Args:
        path: The build.py file.
    """
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    for node in tree.body:
        targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(node, ast.AnnAssign) else []
        if any(isinstance(t, ast.Name) and t.id == "BUILD_REQUIRES" for t in targets):
            try:
                value = ast.literal_eval(node.value)
            except ValueError:
                value = None
            if not isinstance(value, (tuple, list)) or not all(isinstance(v, str) for v in value):
                raise ValueError(f"{path}, line {node.lineno}: BUILD_REQUIRES must be a literal tuple of domain "
                                 f"names, e.g. ('clinical_diagnosis',)")
            return tuple(value)
    return ()


def _domain_of(module_name: str) -> str | None:
    parts = module_name.split(".")
    if len(parts) == 4 and parts[:2] == ["envs", "domains"] and parts[3] == "build":
        return parts[2]
    return None


def ordered_builders(builders: list[str]) -> list[str]:
    """`builders` reordered so each domain builder comes after the domain builders it requires; the
    listed order is kept otherwise. A requirement that is not listed, or a cycle, is an error.

    Args:
        builders: Dotted builder module paths, in their preferred order.
    """
    by_domain = {d: m for m in builders if (d := _domain_of(m)) is not None}
    requires = {m: declared_build_requires(m) if _domain_of(m) else () for m in builders}
    for module_name, names in requires.items():
        missing = [n for n in names if n not in by_domain]
        if missing:
            raise ValueError(f"{module_name}: BUILD_REQUIRES names {missing}, which have no builder in the list")
    out: list[str] = []
    visiting: list[str] = []

    def visit(module_name: str) -> None:
        if module_name in out:
            return
        if module_name in visiting:
            cycle = " -> ".join([*visiting[visiting.index(module_name):], module_name])
            raise ValueError(f"BUILD_REQUIRES cycle: {cycle}")
        visiting.append(module_name)
        for name in requires[module_name]:
            visit(by_domain[name])
        visiting.pop()
        out.append(module_name)

    for module_name in builders:
        visit(module_name)
    return out


def build_required_domains(names: tuple[str, ...] | list[str], *, offline: bool = False) -> dict[str, dict]:
    """Build (or find up to date) each required domain, for a build that reads their built data.

    Args:
        names: Domain names, as in the caller's `BUILD_REQUIRES`.
        offline: Passed to each required build (use the package cache only).
    """
    return {name: importlib.import_module(DOMAIN_BUILD_MODULE.format(name=name)).build(offline=offline)
            for name in names}
