"""The EHR database file, laid out so one patient can be read without parsing the others.

`db.json` is an ordinary JSON document (`EHRDB.load` reads it) written one patient per line:

    {"clock": "2025-03-05T08:00", "next_order_number": 1, "patients": {
    "EHR-001": {...},
    ...
    "SYN-002694": {...}
    }}

`PatientStore` scans the file once per process for the byte range of every patient's line and
keeps only those offsets (not the 46 MB of text); `load(pid)` reads one line with `os.pread` and
validates it (a fresh `EHRPatient` per call, so episodes never share state). A file in any other
layout (e.g. written by `DB.dump`) is parsed whole once and kept as per-patient JSON instead.
"""

from __future__ import annotations

import json
import os
import threading
from pathlib import Path

from envs.core.db import DataFileError
from envs.core.files import write_text_atomic

from .data_model import EHRDB, EHRPatient

_HEADER_END = b'"patients": {'


def write_db(db: EHRDB, path: Path) -> None:
    """Write the database in the one-patient-per-line layout (keys sorted, so rebuilds are identical)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    head = {"clock": db.clock, "next_order_number": db.next_order_number}
    lines = [json.dumps(head, sort_keys=True, ensure_ascii=False)[:-1] + ", " + _HEADER_END.decode()]
    ids = sorted(db.patients)
    for i, pid in enumerate(ids):
        record = json.dumps(db.patients[pid].model_dump(mode="json"), sort_keys=True, ensure_ascii=False,
                            separators=(",", ":"))
        lines.append(f"{json.dumps(pid)}: {record}{',' if i < len(ids) - 1 else ''}")
    lines.append("}}")
    write_text_atomic(path, "\n".join(lines) + "\n")


class PatientStore:
    """Read-only access to the patients of a built `db.json`, one patient at a time."""

    def __init__(self, path: Path) -> None:
        if not path.exists():
            raise DataFileError(f"{path}: database not built (run `hcgym data build ehr_management`)")
        self.path = path
        stat = path.stat()
        self.stamp = (stat.st_mtime_ns, stat.st_size)
        self._offsets: dict[str, tuple[int, int]] = {}
        self._inline: dict[str, bytes] = {}
        self._fd: int | None = None
        data = path.read_bytes()
        first = data.find(b"\n")
        header = data[:first].rstrip()
        if header.endswith(_HEADER_END):
            meta = json.loads(header[: -len(_HEADER_END)].rstrip().rstrip(b",") + b"}")
            position = first + 1
            while position < len(data):
                end = data.find(b"\n", position)
                end = len(data) if end < 0 else end
                line = data[position:end]
                if line.startswith(b'"'):
                    colon = line.index(b'": ')
                    pid = json.loads(line[: colon + 1])
                    value_start = position + colon + 3
                    value_end = end - (1 if line.endswith(b",") else 0)
                    self._offsets[pid] = (value_start, value_end - value_start)
                position = end + 1
            self._fd = os.open(path, os.O_RDONLY)
        else:  # another layout: parse once, keep each patient's JSON
            raw = json.loads(data)
            meta = {k: v for k, v in raw.items() if k != "patients"}
            self._inline = {pid: json.dumps(p).encode() for pid, p in raw.get("patients", {}).items()}
        self.clock: str = meta.get("clock", EHRDB.model_fields["clock"].default)
        self.next_order_number: int = meta.get("next_order_number", 1)

    def __contains__(self, patient_id: object) -> bool:
        return patient_id in self._offsets or patient_id in self._inline

    def __len__(self) -> int:
        return len(self._offsets) + len(self._inline)

    def ids(self) -> list[str]:
        return sorted([*self._offsets, *self._inline])

    def raw(self, patient_id: str) -> bytes:
        if patient_id in self._offsets:
            offset, length = self._offsets[patient_id]
            return os.pread(self._fd, length, offset)  # type: ignore[arg-type]
        return self._inline[patient_id]

    def load(self, patient_id: str) -> EHRPatient:
        """A fresh, validated copy of one patient's record."""
        return EHRPatient.model_validate_json(self.raw(patient_id))

    def empty_db(self) -> EHRDB:
        """An episode database with the record clock and no chart open yet."""
        return EHRDB(patients={}, clock=self.clock, next_order_number=self.next_order_number)

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def __del__(self) -> None:  # pragma: no cover - interpreter shutdown order varies
        try:
            self.close()
        except Exception:
            pass


_lock = threading.Lock()
_stores: dict[Path, PatientStore] = {}


def patient_store(path: Path) -> PatientStore:
    """The process-wide store of a database file, re-read when the file changes."""
    stat = path.stat() if path.exists() else None
    with _lock:
        store = _stores.get(path)
        if store is None or stat is None or store.stamp != (stat.st_mtime_ns, stat.st_size):
            if store is not None:
                store.close()
            store = PatientStore(path)
            _stores[path] = store
        return store
