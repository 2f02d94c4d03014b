"""Writing files so that readers never see half of one, and a failure leaves nothing behind."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Callable


def replace_atomic(path: str | os.PathLike, write: Callable[[Path], None]) -> None:
    """`write(tmp)` then rename over `path`, so readers never see half a file; the temporary file
    (`.NAME.tmp` next to `path`) is removed if anything fails, and the previous file stays."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Write UTF-8 text atomically (see `replace_atomic`)."""
    replace_atomic(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))
