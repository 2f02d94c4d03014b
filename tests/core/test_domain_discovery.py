"""A domain is its folder: the registry, the data build and the held-out suite find it there."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

from envs import registry
from envs.data.build import BUILDERS
from evals.suites import load_suite

REPO = Path(__file__).resolve().parents[2]


def test_every_domain_folder_is_discovered_and_nothing_else():
    folders = sorted(p.name for p in registry.DOMAINS_DIR.iterdir()
                     if p.is_dir() and any(p.glob("*.py")) and not p.name.startswith(("_", ".")))
    undiscovered = [name for name in folders if name not in registry.DOMAINS]
    assert not undiscovered, f"domain folders without an environment.py (not registered): {undiscovered}"
    builtin = [d for d in registry.list_domains() if registry.DOMAINS[d].startswith("envs.domains.")]
    assert builtin == folders and len(builtin) == 10  # the paper's ten domains
    built = [name for name in builtin if (registry.DOMAINS_DIR / name / "build.py").is_file()]
    assert [m for m in BUILDERS if m.startswith("envs.domains.")] == [f"envs.domains.{d}.build" for d in built]
    heldout = [b.select.domain for b in load_suite("gym-heldout").benchmarks]
    assert heldout == registry.list_domains()  # the built-in ones and any a program registers (the tests: ward)


PROBE = """
import envs
from envs import registry
from envs.data.build import BUILDERS
from evals.suites import load_suite

assert envs.__file__.startswith({root!r}), envs.__file__
print("dermatology" in registry.list_domains(), "envs.domains.dermatology.build" in BUILDERS,
      [b.title for b in load_suite("gym-heldout").benchmarks if b.select.domain == "dermatology"],
      "scratch" in registry.list_domains())
"""


def test_a_new_domain_is_its_folder(tmp_path):
    """Adding envs/domains/dermatology/ (environment.py, build.py) and editing nothing else registers
    it, builds it and gives it a held-out benchmark; a folder without environment.py is not a domain."""
    for package in ("envs", "evals"):
        shutil.copytree(REPO / package, tmp_path / package, ignore=shutil.ignore_patterns("__pycache__"))
    domain = tmp_path / "envs" / "domains" / "dermatology"
    domain.mkdir()
    (domain / "environment.py").write_text("def get_environment():\n    raise NotImplementedError\n")
    (domain / "build.py").write_text("def build(offline=False, force=False):\n    return {}\n")
    (tmp_path / "envs" / "domains" / "scratch").mkdir()
    (tmp_path / "envs" / "domains" / "scratch" / "notes.py").write_text("")
    out = subprocess.run([sys.executable, "-c", PROBE.format(root=str(tmp_path))], cwd=tmp_path,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.split() == ["True", "True", "['dermatology", "(test)']", "False"]
