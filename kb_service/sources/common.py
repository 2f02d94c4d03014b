"""What every knowledge-base source module shares: the source record and passage provenance.

Kept apart from `kb_service/sources/__init__.py` (which lists the sources and so imports every
source module) so that the source modules depend on it and never on the package that lists them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterator

from envs.data.registry import Archive, PackageSource


@dataclass(frozen=True)
class DefaultSource:
    name: str
    packages: tuple[PackageSource, ...]
    generator_version: str
    passages: Callable[[dict[str, Archive]], Iterator[dict]]
    description: str = ""
    articles: Callable[[dict[str, Archive]], Iterator[dict]] | None = None

    def spec(self) -> dict:
        return {"packages": {p.name: p.version for p in self.packages}, "generator": self.generator_version}


def provenance(*packages: PackageSource, **extra: str) -> dict[str, str]:
    """Provenance of a passage: the package(s), version(s) and licence(s) it was read from."""
    prov = {
        "package": ", ".join(p.name for p in packages),
        "version": ", ".join(p.version for p in packages),
        "license": " | ".join(p.license for p in packages),
    }
    prov.update({k: v for k, v in extra.items() if v})
    return prov
