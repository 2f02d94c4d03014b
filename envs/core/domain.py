"""The domain contract in code: what a domain folder provides to the environment.

See `envs/domains/README.md` for the contract in prose. A domain's `environment.py` exposes:

    def get_environment() -> DomainEnvironment      # a fresh database + toolkit per call
    def get_tasks(split: str | None = None) -> list[Task]

`DomainEnvironment` bundles the policy text, the database, the toolkit (domain tools first,
then shared tools) and an optional safety context used by the reward.
"""

from __future__ import annotations

import copy
import hashlib
import json
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable

from envs.core.db import DB, DataFileError, read_text_file
from envs.core.paths import data_dir
from envs.core.task import Task, load_split, load_tasks
from envs.core.tools import Toolkit


@dataclass
class DomainEnvironment:
    """Everything one episode of a domain needs."""

    name: str
    policy: str
    toolkit: Toolkit
    safety_context: Any = None
    # Called on reset with the task, e.g. to seed episode-specific state from `task.metadata`.
    on_reset: Callable[["DomainEnvironment", Task], None] | None = None
    # Replaces `envs.rewards.score_episode` for this episode (e.g. the pathway score); same signature.
    scorer: Callable[..., Any] | None = None
    extras: dict[str, Any] = field(default_factory=dict)

    @property
    def db(self) -> DB | None:
        return self.toolkit.db

    def db_hash(self) -> str | None:
        db = self.db
        return db.content_hash() if isinstance(db, DB) else None


class DomainTaskStore:
    """Loads a domain's tasks once: authored tasks committed in the domain folder plus tasks the
    data build generated, filtered by the split file(s)."""

    def __init__(self, name: str, package_dir: Path, build_dir: Path) -> None:
        self.name = name
        self.package_dir = package_dir
        self.build_dir = build_dir
        self._tasks: list[Task] | None = None
        self._splits: dict[str, list[str]] | None = None

    def _task_files(self) -> list[Path]:
        files = [self.package_dir / "tasks.json", self.build_dir / "tasks.json"]
        return [f for f in files if f.exists()] + self._imported_files()

    def _imported_files(self) -> list[Path]:
        folder = imported_tasks_dir(self.name)
        return sorted(folder.glob("*.json")) if folder.is_dir() else []

    def all_tasks(self) -> list[Task]:
        if self._tasks is None:
            files = self._task_files()
            if not files:
                raise DataFileError(
                    f"domain {self.name!r}: no tasks found in {self.package_dir / 'tasks.json'} or "
                    f"{self.build_dir / 'tasks.json'} (run `hcgym data build`)"
                )
            tasks: list[Task] = []
            seen: set[str] = set()
            for path in files:
                for task in load_tasks(path, domain=self.name):
                    if task.id in seen:
                        raise DataFileError(f"{path} [task {task.id!r}]: id also defined in another task file")
                    seen.add(task.id)
                    tasks.append(task)
            self._tasks = tasks
        return self._tasks

    def splits(self) -> dict[str, list[str]]:
        if self._splits is None:
            merged: dict[str, list[str]] = {}
            for path in (self.package_dir / "split_tasks.json", self.build_dir / "split_tasks.json"):
                if path.exists():
                    for split, ids in load_split(path).items():
                        merged.setdefault(split, []).extend(ids)
            imported = [t.id for f in self._imported_files() for t in load_tasks(f, domain=self.name)]
            if imported:
                merged.setdefault("imported", []).extend(imported)
            known = {t.id for t in self.all_tasks()}
            for split, ids in merged.items():
                missing = [i for i in ids if i not in known]
                if missing:
                    raise DataFileError(
                        f"domain {self.name!r}: split {split!r} names unknown task ids {missing[:5]}"
                    )
            self._splits = merged
        return self._splits

    def tasks(self, split: str | None = None) -> list[Task]:
        tasks = self.all_tasks()
        if split is None:
            return tasks
        splits = self.splits()
        if split not in splits:
            raise KeyError(f"domain {self.name!r} has no split {split!r} (available: {sorted(splits)})")
        wanted = set(splits[split])
        return [t for t in tasks if t.id in wanted]


def imported_tasks_dir(domain: str) -> Path:
    """Tasks users convert from their own benchmark files (`hcgym tasks import`); split 'imported'."""
    return data_dir() / "imported" / domain


def read_policy(package_dir: Path) -> str:
    path = package_dir / "policy.md"
    if not path.exists():
        raise DataFileError(f"{path}: the domain policy is missing")
    return read_text_file(path, "domain policy").strip()


def write_split(path: Path, splits: dict[str, list[str]]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(splits, indent=1) + "\n", encoding="utf-8")


def write_task_dicts(out: Path, tasks: list[dict], splits: dict[str, list[str]]) -> dict[str, Any]:
    """Validate a build's generated tasks (each a `Task`), write them to `out/tasks.json` and their split to
    `out/split_tasks.json`; the counts for the build summary (tasks, by task type, per split)."""
    for task in tasks:
        Task.model_validate(task)
    (out / "tasks.json").write_text(json.dumps(tasks, ensure_ascii=False, indent=1) + "\n", encoding="utf-8")
    write_split(out / "split_tasks.json", splits)
    return {"tasks": len(tasks), "by_type": dict(sorted(Counter(t["description"]["task_type"] for t in tasks).items())),
            "splits": {k: len(v) for k, v in splits.items()}}


def inputs_fingerprint(paths: Iterable[Path], *texts: str) -> str:
    """SHA-256 over the bytes of the files a build reads (its code, authored data, the shared helpers it
    runs) and `texts` (package versions, parameters): a changed input rebuilds."""
    digest = hashlib.sha256()
    for path in paths:
        digest.update(path.read_bytes())
    for text in texts:
        digest.update(text.encode())
    return digest.hexdigest()


def skip_if_built(out: Path, fingerprint: str, force: bool = False) -> dict | None:
    """What the last build in `out` recorded (`manifest.json`: `{"skipped": "up to date", **summary}`) when it
    was built from inputs with this fingerprint and all its files are still there (and not `force`); else
    None, with `out` created for the build to run."""
    path = out / "manifest.json"
    if not force and path.exists():
        manifest = json.loads(path.read_text())
        if manifest.get("fingerprint") == fingerprint and all((out / f).exists() for f in manifest.get("files", [])):
            return {"skipped": "up to date", **manifest["summary"]}
    out.mkdir(parents=True, exist_ok=True)
    return None


def write_manifest(out: Path, fingerprint: str, summary: dict, files: list[str], **extra: Any) -> None:
    """Record a finished build in `out/manifest.json` (what `skip_if_built` reads): the inputs' fingerprint,
    the summary, the files written, and `extra` entries (e.g. the packages' provenance)."""
    manifest = {"fingerprint": fingerprint, "summary": summary, "files": files, **extra}
    (out / "manifest.json").write_text(json.dumps(manifest, indent=1, sort_keys=True) + "\n", encoding="utf-8")


class BuiltDomain:
    """Entry-point plumbing for a domain whose database `hcgym data build` writes to
    `domain_build_dir(name)/db.json`: the file is parsed once per process (again if it changes),
    the policy read once, and the task store shared. Episodes fork the parsed template.

    Example (a domain's environment.py):
        DOMAIN = BuiltDomain("psychiatry", Path(__file__).parent, PsychiatryDB)
        get_tasks, get_splits = DOMAIN.get_tasks, DOMAIN.get_splits
    """

    def __init__(self, name: str, package_dir: Path, db_class: type[DB]) -> None:
        import threading

        from envs.core.paths import domain_build_dir

        self.name = name
        self.package_dir = package_dir
        self.db_class = db_class
        self._build_dir = domain_build_dir
        self._lock = threading.Lock()
        self._template: tuple[Path, float, DB] | None = None
        self._stores: dict[Path, DomainTaskStore] = {}
        self._policy: str | None = None

    def template(self) -> DB:
        path = self._build_dir(self.name) / "db.json"
        if not path.exists():
            raise DataFileError(f"{path}: {self.name} database not built (run `hcgym data build --only {self.name}`)")
        stamp = path.stat().st_mtime
        with self._lock:
            if self._template is None or self._template[:2] != (path, stamp):
                db = self.db_class.load(path)
                if hasattr(db, "reference_hash"):
                    db.reference_hash()  # computed once, shared by every fork
                self._template = (path, stamp, db)
            return self._template[2]

    def episode_db(self) -> DB:
        """A fresh database for one episode: a fork of the parsed template where the database
        class forks (shared reference tables, copied state), else a full copy of it."""
        template = self.template()
        return template.fork() if hasattr(template, "fork") else copy.deepcopy(template)

    def policy(self) -> str:
        if self._policy is None:
            self._policy = read_policy(self.package_dir)
        return self._policy

    def store(self) -> DomainTaskStore:
        build = self._build_dir(self.name)
        with self._lock:
            if build not in self._stores:
                self._stores[build] = DomainTaskStore(self.name, self.package_dir, build)
            return self._stores[build]

    def get_tasks(self, split: str | None = None) -> list[Task]:
        return self.store().tasks(split)

    def get_splits(self) -> dict[str, list[str]]:
        return self.store().splits()
