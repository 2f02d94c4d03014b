"""Where built data lives. Nothing third-party is committed; `hcgym data build` writes here."""

from __future__ import annotations

import os
from pathlib import Path

PACKAGE_ROOT = Path(__file__).resolve().parents[1]
DOMAINS_ROOT = PACKAGE_ROOT / "domains"


def data_dir() -> Path:
    """The build output root: $HCGYM_DATA_DIR, else ~/.cache/hcgym."""
    root = os.environ.get("HCGYM_DATA_DIR") or os.path.join(os.path.expanduser("~"), ".cache", "hcgym")
    return Path(root)


def package_cache_dir() -> Path:
    """Downloaded registry package files (wheels/sdists), reused offline."""
    return data_dir() / "packages"


def domain_build_dir(domain: str) -> Path:
    """Built database and generated tasks of one domain."""
    return data_dir() / "domains" / domain
