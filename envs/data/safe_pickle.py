"""One restricted reader for every pickle that comes from a package or a user's file.

Some distributed data files are pickles (the drug-NER vocabulary, PathVQA's released split files).
`pickle.loads` on them would run whatever a crafted file asks for, so every pickle in the project is
read here: the opcodes that build plain containers and scalars (dict, list, tuple, str, bytes,
int, float, bool, None) work as usual, and `set`/`frozenset` are the only globals allowed. Any other
global (a class, `os.system`, `numpy` arrays) is refused with an error naming the source, before
anything is constructed from it.
"""

from __future__ import annotations

import io
import pickle
from typing import Any

_ALLOWED_GLOBALS = {("builtins", "set"): set, ("builtins", "frozenset"): frozenset}


class UnsafePickleError(ValueError):
    """A pickle refers to something other than plain data."""


class _PlainUnpickler(pickle.Unpickler):
    def __init__(self, file: io.BytesIO, source: str):
        super().__init__(file)
        self._source = source

    def find_class(self, module: str, name: str) -> Any:
        allowed = _ALLOWED_GLOBALS.get((module, name))
        if allowed is None:
            raise UnsafePickleError(
                f"{self._source}: the pickle refers to {module}.{name}; only plain data "
                "(dict, list, tuple, set, str, bytes, numbers, None) is accepted")
        return allowed

    def persistent_load(self, pid: Any) -> Any:
        raise UnsafePickleError(f"{self._source}: the pickle uses persistent ids; only plain data is accepted")


def load_plain_pickle(data: bytes, *, source: str) -> Any:
    """Unpickle `data` (already decompressed) allowing plain containers and scalars only.

    `source` names the file or package member in every error. Raises UnsafePickleError for code or
    classes, and ValueError naming the source for a damaged stream.
    """
    try:
        return _PlainUnpickler(io.BytesIO(data), source).load()
    except UnsafePickleError:
        raise
    except (pickle.UnpicklingError, EOFError, ValueError, TypeError, IndexError, KeyError, AttributeError) as exc:
        raise ValueError(f"{source}: not a readable pickle ({type(exc).__name__}: {exc})") from exc
