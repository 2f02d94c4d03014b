"""The domain contract (envs/domains/README.md), checked for every registered domain.

Runs on a fresh checkout: nothing here needs the data build. Per domain: tool docstrings describe
exactly the arguments of their signatures, the policy is present, the splits are declared, the
environment module follows one of the two documented patterns, and no domain imports another
(except a domain whose build declares it reads that domain's built data, `BUILD_REQUIRES`).
"""

from __future__ import annotations

import ast
import inspect
import sys
import textwrap
from pathlib import Path

import pytest

from envs import registry
from envs.core.build_order import build_requires_in_source, ordered_builders
from envs.core.domain import BuiltDomain, read_policy
from envs.core.tools import Toolkit, is_tool, parse_google_docstring
from envs.data.build import BUILDERS
from envs.integrations.trl import reserved_name_problems

DOMAINS_ROOT = Path(registry.__file__).parent / "domains"
# The domains shipped in envs/domains/ (tests may register fixture domains such as tests/fixtures/ward_domain).
ALL_DOMAINS = [name for name, module in registry.DOMAINS.items() if module == f"envs.domains.{name}.environment"]
# Pattern 2 of the README: the toolkit is composed at reset from other domains' environments.
COMPOSED_DOMAINS = {"cross_domain"}


def _package_dir(domain: str) -> Path:
    return DOMAINS_ROOT / domain


def _toolkit_classes(domain: str) -> list[type[Toolkit]]:
    """Toolkit classes defined in the domain's package (its modules load with the environment module)."""
    registry.domain_module(domain)
    prefix = f"envs.domains.{domain}."
    found = {obj for mod_name, module in list(sys.modules.items()) if mod_name.startswith(prefix) and module
             for obj in vars(module).values()
             if inspect.isclass(obj) and issubclass(obj, Toolkit) and obj.__module__.startswith(prefix)}
    return sorted(found, key=lambda c: c.__qualname__)


def _tool_functions(cls: type[Toolkit]):
    for klass in cls.__mro__:
        for attr, member in vars(klass).items():
            fn = getattr(member, "__func__", member)
            if callable(fn) and hasattr(fn, "__tool_type__"):
                yield f"{klass.__name__}.{attr}", fn


def docstring_problems(fn) -> list[str]:
    """What is wrong with a tool's docstring against its signature (empty when it is right)."""
    description, arg_docs = parse_google_docstring(fn.__doc__)
    params = [name for name, p in inspect.signature(fn).parameters.items()
              if name != "self" and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]
    problems = []
    if not description:
        problems.append("no description line")
    problems += [f"Args names {name!r}, which is not an argument" for name in arg_docs if name not in params]
    problems += [f"argument {name!r} is not described under Args" for name in params if not (arg_docs.get(name) or "").strip()]
    return problems


@pytest.mark.parametrize("domain", ALL_DOMAINS)
def test_tool_docstrings_describe_exactly_their_arguments(domain):
    classes = _toolkit_classes(domain)
    assert classes, f"{domain}: no Toolkit subclass found in envs.domains.{domain}"
    problems = [f"{domain} {where}: {p}" for cls in classes for where, fn in _tool_functions(cls)
                for p in docstring_problems(fn)]
    assert not problems, "\n".join(problems)


def test_docstring_check_catches_a_stale_and_a_missing_argument():
    def tool(self, patient_id: str, dose_mg: float) -> dict:
        """Order a dose.

        Args:
            patient_id: The patient identifier.
            dose: Renamed to dose_mg without updating this line.
        """

    assert docstring_problems(tool) == ["Args names 'dose', which is not an argument",
                                        "argument 'dose_mg' is not described under Args"]


def reserved_tool_names(classes: list[type[Toolkit]]) -> list[str]:
    """Tools whose names a trainer integration reserves (TRL's environment_factory turns every public
    method into a tool, except `reset` / `get_reward` and its own members): one line per tool."""
    return [f"{cls.__name__}: {p}" for cls in classes for p in reserved_name_problems(sorted(cls._definitions))]


@pytest.mark.parametrize("domain", ALL_DOMAINS)
def test_tool_names_are_not_reserved(domain):
    from envs.shared import shared_toolkits

    classes = _toolkit_classes(domain) + [type(t) for t in shared_toolkits()]
    problems = reserved_tool_names(classes)
    assert not problems, "\n".join(problems)


def test_reserved_tool_name_check_names_the_tool():
    class Clashing(Toolkit):
        @is_tool()
        def reset(self, patient_id: str) -> str:
            """Reset a patient's chart.

            Args:
                patient_id: The patient identifier.
            """
            return patient_id

        @is_tool()
        def get_reward(self) -> float:
            """The reward."""
            return 0.0

        @is_tool()
        def lookup(self, name: str) -> str:
            """Look a name up.

            Args:
                name: The name.
            """
            return name

    problems = reserved_tool_names([Clashing])
    assert len(problems) == 2 and "'get_reward'" in problems[0] and "'reset'" in problems[1], problems


@pytest.mark.parametrize("domain", ALL_DOMAINS)
def test_policy_present(domain):
    policy = read_policy(_package_dir(domain))
    assert policy.startswith("#") and len(policy.split()) >= 50, f"{domain}: policy.md is missing its heading or body"


@pytest.mark.parametrize("domain", ALL_DOMAINS)
def test_splits_declared(domain):
    """Authored splits are committed (`split_tasks.json`); generated ones are written by build.py."""
    package = _package_dir(domain)
    module = registry.domain_module(domain)
    assert callable(getattr(module, "get_splits", None)), f"{domain}: environment.py has no get_splits()"
    build = package / "build.py"
    # envs.core.domain.write_split, or write_task_dicts, which writes the tasks and calls it
    writes_split = build.exists() and any(
        isinstance(node, ast.Call) and getattr(node.func, "id", getattr(node.func, "attr", None)) in ("write_split", "write_task_dicts")
        for node in ast.walk(ast.parse(build.read_text(encoding="utf-8"))))
    assert (package / "split_tasks.json").exists() or writes_split, \
        f"{domain}: neither a committed split_tasks.json nor a build.py that calls write_split or write_task_dicts"


@pytest.mark.parametrize("domain", ALL_DOMAINS)
def test_environment_follows_a_documented_pattern(domain):
    module = registry.domain_module(domain)
    for name in ("get_environment", "get_tasks", "get_splits"):
        assert callable(getattr(module, name, None)), f"{domain}: environment.py has no {name}()"
    if domain in COMPOSED_DOMAINS:
        return
    built = getattr(module, "DOMAIN", None)
    assert isinstance(built, BuiltDomain) and built.name == domain, f"{domain}: no DOMAIN = BuiltDomain({domain!r}, ...)"
    assert module.get_tasks == built.get_tasks and module.get_splits == built.get_splits
    # The toolkit rule: domain tools first, then the shared toolkits (a domain tool wins a clash).
    tree = ast.parse(Path(module.__file__).read_text(encoding="utf-8"))
    composite_calls = [n for n in ast.walk(tree) if isinstance(n, ast.Call) and getattr(n.func, "id", None) == "CompositeToolkit"]
    assert any(isinstance(c.args[-1], ast.Starred) and getattr(c.args[-1].value.func, "id", None) == "shared_toolkits"
               for c in composite_calls if c.args), f"{domain}: no CompositeToolkit(<domain tools>, *shared_toolkits())"


# -- imports between domains -------------------------------------------------------------------------


def _imported_modules(tree: ast.AST, module_parts: tuple[str, ...]) -> list[tuple[int, str]]:
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = list(module_parts[:-node.level])
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            names = [target] + [f"{target}.{a.name}" for a in node.names]
            out += [(node.lineno, n) for n in names]
        elif isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
    return out


def cross_domain_imports(domains_root: Path) -> list[str]:
    """Imports from one domain package into another that its build does not declare in
    `BUILD_REQUIRES`, and any domain import from a shared module beside the domain folders."""
    domains = {p.name for p in domains_root.iterdir() if p.is_dir() and not p.name.startswith(("_", "."))}
    found = []
    for path in sorted(domains_root.rglob("*.py")):
        rel = path.relative_to(domains_root)
        own = rel.parts[0] if len(rel.parts) > 1 else None
        build = domains_root / own / "build.py" if own else None
        allowed = set(build_requires_in_source(build)) if build and build.exists() else set()
        module_parts = ("envs", "domains", *rel.with_suffix("").parts)
        for line, target in _imported_modules(ast.parse(path.read_text(encoding="utf-8")), module_parts):
            parts = target.split(".")
            if parts[:2] != ["envs", "domains"] or len(parts) < 3 or parts[2] not in domains:
                continue
            if parts[2] != own and parts[2] not in allowed:
                found.append(f"{rel}:{line} imports {'.'.join(parts[:3])}")
    return sorted(set(found))


def test_no_domain_imports_another_undeclared():
    found = cross_domain_imports(DOMAINS_ROOT)
    assert not found, ("a domain imports another: move the shared code to envs/core/ (or a shared module beside "
                       "the domain folders), or declare a built-data dependency in BUILD_REQUIRES:\n" + "\n".join(found))


def test_cross_domain_import_check_catches_new_imports(tmp_path):
    def write(rel: str, text: str) -> None:
        path = tmp_path / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(text), encoding="utf-8")

    write("alpha/tools.py", "from envs.domains.beta.safety import helper\n")
    write("beta/safety.py", "def helper():\n    from ..alpha import tools\n")
    write("gamma/build.py", "BUILD_REQUIRES = ('alpha',)\nfrom envs.domains.alpha import knowledge\n")
    write("shared_lib.py", "import envs.domains.gamma.build\n")
    write("alpha/own.py", "from envs.domains.alpha import tools\nfrom envs.core import splits\n")
    assert cross_domain_imports(tmp_path) == ["alpha/tools.py:1 imports envs.domains.beta",
                                              "beta/safety.py:2 imports envs.domains.alpha",
                                              "shared_lib.py:1 imports envs.domains.gamma"]


def test_declared_build_requirements_build_first():
    order = ordered_builders(BUILDERS)
    for module_name in BUILDERS:
        parts = module_name.split(".")
        if parts[:2] == ["envs", "domains"]:
            for required in build_requires_in_source(DOMAINS_ROOT / parts[2] / "build.py"):
                assert order.index(f"envs.domains.{required}.build") < order.index(module_name)


def test_build_requires_cycle_and_bad_value_are_named(tmp_path, monkeypatch):
    bad = tmp_path / "build.py"
    bad.write_text("BUILD_REQUIRES = 'clinical_diagnosis'\n", encoding="utf-8")
    with pytest.raises(ValueError, match=r"build.py, line 1: BUILD_REQUIRES must be a literal tuple"):
        build_requires_in_source(bad)
    from envs.core import build_order

    fake = {"envs.domains.a.build": ("b",), "envs.domains.b.build": ("a",)}
    monkeypatch.setattr(build_order, "declared_build_requires", lambda m: fake[m])
    with pytest.raises(ValueError, match="BUILD_REQUIRES cycle: envs.domains.a.build -> envs.domains.b.build -> envs.domains.a.build"):
        build_order.ordered_builders(list(fake))
