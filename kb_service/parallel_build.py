"""The bounded-memory index stage on several worker processes (`hcgym kb build --workers N`).

The single-process build (`kb_service.ingest._build_indexes_sharded`) runs its bm25 pass and then
its tantivy pass in one process. Here both run at once in worker processes: the tantivy pass is
one task (`_tantivy_task`, queued first), and the passages are cut into *units*, contiguous
ranges of rows (at most ``shard_docs`` each, at least one per worker), and each worker process
builds the raw shards of the units it takes with its own `ShardedBM25Builder` under
``bm25.raw/unit-NNNNN/``, cutting them by its share of the memory budget, and writes each shard's
source/category ids under ``docmeta.parts/unit-NNNNN/``. The main process then adopts every
unit's raw shards in document order into one builder, whose `save` computes the global
statistics exactly as the single-process build does (so every weight, and every ranking, is the
same bit for bit) and weighs the shards in the same workers.

Memory: the main process keeps what it holds when indexing starts plus `INDEX_HEADROOM_BYTES`;
each worker gets an equal share of the rest of the budget, its own interpreter and libraries
included, and cuts its shards at what its share leaves above what it holds once started.

Resumable as the single-process build: the unit plan is recorded in the index progress file,
each unit's builder commits shard by shard (a rerun continues every unit after its last commit),
the adoption and each weighted shard are committed, and the tantivy pass commits every eighth of
the passages (``tantivy.progress.json``, written by its worker only). Workers die with the main process
(PR_SET_PDEATHSIG), so a killed build leaves no worker writing into the staging folder.
"""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import time
import traceback
from collections import deque
from array import array
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

from kb_service.schema import IngestError
from kb_service.store import indexed_text

UNITS_DIR = "bm25.raw"
PARTS_DIR = "docmeta.parts"


def machine_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def plan_units(n: int, workers: int, shard_docs: int) -> list[list[int]]:
    """Contiguous document ranges [start, end) covering 0..n-1: at most `shard_docs` documents each
    and at least `workers` of them (when there are that many documents), as equal as possible."""
    count = max(min(workers, n), -(-n // shard_docs))
    bounds = [n * i // count for i in range(count + 1)]
    return [[bounds[i], bounds[i + 1]] for i in range(count)]


def peak_rss_own_bytes() -> int:
    """This process's own peak RSS (VmHWM). Unlike ru_maxrss, which Linux starts at the peak of
    the process a child was started from, VmHWM counts only this process's address space."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def _die_with_parent() -> None:
    """SIGKILL this worker when the process that started it dies (Linux prctl PR_SET_PDEATHSIG)."""
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):
        pass
    if os.getppid() == 1:  # the parent died before the prctl took effect
        os._exit(1)


# ------------------------------------------------------------------------------------------ worker side
def _worker_main(conn, share_bytes: int | None, headroom: int, min_working: int) -> None:
    _die_with_parent()
    from kb_service.shards import KILL_ENV, process_rss_bytes, release_memory

    # The tests' kill points (kb_service.shards.kill_point) fire in the main process, which counts the
    # commits the workers report; a worker killing itself would look like a crash, not an interruption.
    os.environ.pop(KILL_ENV, None)
    import kb_service.analysis  # noqa: F401  (what a unit task needs, imported before measuring)
    from bm25s.scoring import _select_idf_scorer  # noqa: F401

    release_memory()
    held = process_rss_bytes()
    working = None if share_bytes is None else share_bytes - held - headroom
    if working is not None and working < min_working:
        conn.send(("fatal", os.getpid(),
                   f"memory_budget_mb: a bm25 worker holds {held >> 20} MB once started and its share of the budget "
                   f"is {share_bytes >> 20} MB, which leaves {max(working, 0) >> 20} MB to build with (at least "
                   f"{min_working >> 20} MB needed); give a larger budget or fewer workers"))
        return
    conn.send(("ready", os.getpid(), held))
    while True:
        try:
            task = conn.recv()
        except EOFError:
            return
        if task is None:
            break
        kind, key, args = task
        try:
            if kind == "unit":
                result = _build_unit(*args, working=working, send=conn.send)
            elif kind == "tantivy":
                result = _tantivy_task(*args, working=working, send=conn.send)
            elif kind == "weigh":
                from kb_service.shards import weigh_shard

                t0 = time.perf_counter()
                weigh_shard(*args)
                release_memory()
                result = (time.perf_counter() - t0, process_rss_bytes())
            else:
                raise ValueError(f"unknown task kind {kind!r}")
        except BaseException as exc:  # reported to the main process, which stops the build
            conn.send(("error", key, f"{type(exc).__name__}: {exc}", traceback.format_exc()))
            return
        conn.send(("done", key, result))
    conn.send(("peak", os.getpid(), peak_rss_own_bytes()))


def _build_unit(store: str, staging: str, unit: int, start: int, end: int, shard_docs: int, context: dict,
                batch: int, *, working: int | None, send: Callable[[tuple], None]) -> dict:
    """Raw shards of documents start..end-1 (store rows start+1..end), resumed after the unit's last commit."""
    from kb_service.analysis import analyze
    from kb_service.shards import ShardedBM25Builder, process_rss_bytes

    name = f"unit-{unit:05d}"
    parts_dir = Path(staging) / PARTS_DIR / name
    local: dict[str, dict[str, int]] = {"sources": {}, "categories": {}}
    pending_src, pending_cat = array("i"), array("i")

    def commit_meta(shard: int, _offset: int, num_docs: int) -> None:
        # Ids local to this part, with the part's own name lists (in order of first appearance);
        # the main process renumbers them in the corpus's order of first appearance.
        if len(pending_src) != num_docs:
            raise RuntimeError(f"{name} shard {shard}: {len(pending_src)} passages of filter ids for {num_docs}")
        part = parts_dir / f"part-{shard:05d}.npz"
        with open(part.with_suffix(".tmp"), "wb") as fh:
            np.savez(fh, source_ids=np.array(pending_src, dtype=np.int32),
                     category_ids=np.array(pending_cat, dtype=np.int32),
                     names=np.array(json.dumps({k: list(v) for k, v in local.items()})))
        os.replace(part.with_suffix(".tmp"), part)
        del pending_src[:], pending_cat[:]
        local["sources"], local["categories"] = {}, {}

    def committed(shard: int, spec: dict) -> None:
        send(("shard", unit, {**spec, "offset": start + int(spec["offset"]), "rss": process_rss_bytes()}))

    builder = ShardedBM25Builder(Path(staging) / UNITS_DIR / name, shard_docs, memory_bytes=working, resume=True,
                                 context={**context, "unit": [start, end]}, on_commit=commit_meta,
                                 after_commit=committed)
    if builder.fresh:
        import shutil

        shutil.rmtree(parts_dir, ignore_errors=True)
    else:
        for stale in parts_dir.glob("part-*"):
            if not stale.name.endswith(".npz") or int(stale.name[5:10]) >= builder.committed_shards:
                stale.unlink()
        if builder.n_docs:
            send(("echo", f"[kb] bm25 {name}: resuming after {builder.committed_shards} committed shard(s) "
                                 f"(passages {start + 1:,}-{start + builder.n_docs:,})"))
            send(("rows", builder.n_docs))
    parts_dir.mkdir(parents=True, exist_ok=True)
    conn = sqlite3.connect(f"file:{store}?mode=ro", uri=True)
    try:
        last = start + builder.n_docs  # rowid of the last document done
        while last < end:
            rows = conn.execute("SELECT rowid, source, title, content, category FROM passages "
                                "WHERE rowid > ? AND rowid <= ? ORDER BY rowid LIMIT ?", (last, end, batch)).fetchall()
            if not rows:
                break
            for _rowid, source, title, content, category in rows:
                pending_src.append(local["sources"].setdefault(source, len(local["sources"])))
                pending_cat.append(local["categories"].setdefault(category, len(local["categories"])))
                builder.add(analyze(indexed_text(title, content)))
            last = rows[-1][0]
            send(("rows", len(rows)))
    finally:
        conn.close()
    shards = builder.finish_raw()
    if builder.n_docs != end - start:
        raise RuntimeError(f"{store}: {name} got {builder.n_docs} passages to index, rows {start + 1}-{end} hold "
                           f"{end - start}")
    return {"unit": unit, "shards": [{**s, "raw": f"{name}/{s['dir']}", "offset": start + int(s["offset"])}
                                     for s in shards]}


TANTIVY_PROGRESS = "tantivy.progress.json"


def tantivy_rows_done(staging: Path) -> int:
    """Passages the tantivy index under `staging` has committed (its progress file; 0 without one)."""
    try:
        return int(json.loads((Path(staging) / TANTIVY_PROGRESS).read_text(encoding="utf-8"))["rows"])
    except (OSError, ValueError, KeyError, TypeError):
        return 0


def _tantivy_task(store: str, staging: str, n: int, batch: int, min_heap_per_thread: int, *, working: int | None,
                  send: Callable[[tuple], None]) -> dict:
    """The tantivy pass of the build, in a worker alongside the bm25 units: committed every eighth
    of the passages, its progress in ``tantivy.progress.json`` (written here only), resumed from it.
    Its indexing heap is half the worker's working memory (tantivy's RSS runs to about twice its
    heap while it serialises a segment), up to 256 MB, one thread below 120 MB."""
    import shutil

    from kb_service.engines import TantivyBuilder, write_json
    from kb_service.shards import process_rss_bytes, release_memory

    staging_path = Path(staging)
    if working is None:
        heap, threads = 256_000_000, None
    else:
        threads = 1 if working < 4 * min_heap_per_thread * 2 else 2
        heap = int(min(256_000_000, max(min_heap_per_thread * threads + (1 << 20), working // 2)))
    done = tantivy_rows_done(staging_path)
    if done == 0:
        shutil.rmtree(staging_path / "tantivy", ignore_errors=True)
    else:
        send(("echo", f"[kb] tantivy: resuming after {done:,} committed passages"))
    every = max(1000, -(-n // 8))
    tv = TantivyBuilder(staging_path / "tantivy", heap_bytes=heap, threads=threads, reuse=done > 0)
    conn = sqlite3.connect(f"file:{store}?mode=ro", uri=True)
    try:
        last = done
        while True:
            rows = conn.execute("SELECT rowid, source, title, content, category FROM passages WHERE rowid > ? "
                                "ORDER BY rowid LIMIT ?", (last, batch)).fetchall()
            if not rows:
                break
            for rowid, source, title, content, category in rows:
                tv.add(rowid - 1, indexed_text(title, content), source, category)
                if rowid % every == 0 and rowid < n:
                    tv.writer.commit()
                    write_json(staging_path / TANTIVY_PROGRESS, {"rows": rowid})
                    send(("tantivy", rowid, every, process_rss_bytes()))
            last = rows[-1][0]
    finally:
        conn.close()
    if last != n:
        raise RuntimeError(f"{store}: the tantivy pass read up to row {last}, the store holds {n}")
    tv.close()
    del tv
    release_memory()
    write_json(staging_path / TANTIVY_PROGRESS, {"rows": n})
    return {"rows": n, "heap": heap}


# ------------------------------------------------------------------------------------------ main side
class WorkerDied(RuntimeError):
    pass


class WorkerPool:
    """`workers` spawned processes that build units and weigh shards (`kb_service.shards.WeighPool`).

    One pipe per worker and no shared queue: a queue's lock would start multiprocessing's resource
    tracker, which outlives a killed build and writes warnings after it.

    Args:
        share_bytes: each worker's share of the memory budget (None: no budget).
        on_message: called with ("echo", line), ("rows", count) and ("shard", unit, spec) messages.
    """

    def __init__(self, workers: int, share_bytes: int | None, headroom: int, min_working: int,
                 on_message: Callable[[tuple], None]) -> None:
        import multiprocessing as mp

        ctx = mp.get_context("spawn")  # a fresh interpreter: no copy of this process's memory
        self._on_message = on_message
        self.peaks: dict[int, int] = {}
        self.held: dict[int, int] = {}
        self._procs, self._conns = [], []
        self._idle: list[int] = list(range(workers))
        self._queue: deque = deque()
        self._running: dict[int, object] = {}
        self._finished: dict = {}
        try:
            for i in range(workers):
                parent, child = ctx.Pipe()
                proc = ctx.Process(target=_worker_main, daemon=True, name=f"kb-bm25-worker-{i}",
                                   args=(child, share_bytes, headroom, min_working))
                proc.start()
                child.close()
                self._procs.append(proc)
                self._conns.append(parent)
            for i in range(workers):
                msg = self._recv(i)
                if msg[0] == "fatal":
                    raise ValueError(msg[2])
                self.held[msg[1]] = msg[2]
        except BaseException:
            self.close(wait=False)
            raise

    def _recv(self, i: int) -> tuple:
        try:
            return self._conns[i].recv()
        except (EOFError, OSError):
            proc = self._procs[i]
            proc.join(timeout=5)
            why = " (killed: out of memory?)" if proc.exitcode == -signal.SIGKILL else ""
            raise WorkerDied(f"bm25 worker {proc.name} (pid {proc.pid}) died with exit code {proc.exitcode}{why}; "
                             f"run the build again: it resumes after the shards committed so far") from None

    def submit(self, kind: str, key, args: tuple) -> None:
        """Queue a task; it starts on the next idle worker, in the order submitted."""
        self._queue.append((kind, key, args))
        self._dispatch()

    def _dispatch(self) -> None:
        while self._idle and self._queue:
            i = self._idle.pop(0)
            task = self._queue.popleft()
            self._conns[i].send(task)
            self._running[i] = task[1]

    def _next(self) -> tuple[object, object]:
        """The next task to finish: (key, result); other messages go to `on_message` meanwhile."""
        from multiprocessing.connection import wait

        index = {id(c): i for i, c in enumerate(self._conns)}
        while True:
            if not self._running:
                raise RuntimeError("no task is running")
            for conn in wait([self._conns[i] for i in self._running]):
                i = index[id(conn)]
                msg = self._recv(i)
                if msg[0] == "done":
                    del self._running[i]
                    self._idle.append(i)
                    self._dispatch()
                    return msg[1], msg[2]
                if msg[0] == "error":
                    raise RuntimeError(f"bm25 worker {self._procs[i].name}, task {msg[1]}: {msg[2]}\n{msg[3]}")
                self._on_message(msg)

    def results(self, keys: list) -> Iterator[tuple[object, object]]:
        """Yield (key, result) for the tasks `keys` as each finishes; other tasks' results are kept
        for a later call."""
        pending = set(keys)
        for key in [k for k in self._finished if k in pending]:
            pending.discard(key)
            yield key, self._finished.pop(key)
        while pending:
            key, result = self._next()
            if key in pending:
                pending.discard(key)
                yield key, result
            else:
                self._finished[key] = result

    def run(self, tasks: list[tuple[str, object, tuple]]) -> Iterator[tuple[object, object]]:
        """Run (kind, key, args) tasks; yield (key, result) as each finishes."""
        for kind, key, args in tasks:
            self.submit(kind, key, args)
        yield from self.results([key for _kind, key, _args in tasks])

    def weigh(self, tasks: list[tuple[int, tuple]]) -> Iterator[tuple[int, tuple[float, int]]]:
        for key, result in self.run([("weigh", ("weigh", i), args) for i, args in tasks]):
            yield key[1], result

    def close(self, wait: bool = True) -> None:
        """Stop the workers; with `wait`, collect each one's own peak RSS into `peaks`."""
        for i, conn in enumerate(self._conns):
            try:
                if wait:
                    conn.send(None)
                    while True:
                        msg = conn.recv() if conn.poll(30) else None
                        if msg is None or msg[0] == "peak":
                            break
                    if msg is not None:
                        self.peaks[msg[1]] = msg[2]
            except (EOFError, OSError):
                pass
        for proc, conn in zip(self._procs, self._conns):
            proc.join(timeout=5 if wait else 0.1)
            if proc.is_alive():
                proc.kill()
                proc.join(timeout=5)
            conn.close()


def assemble_docmeta(parts: list[Path], out_dir: Path, n: int) -> dict[str, list[str]]:
    """Write ``source_ids.npy`` / ``category_ids.npy`` / return the names, from the units' parts in
    document order: each part's local ids renumbered in the corpus's order of first appearance
    (a part's names are in its own order of first appearance, so taking the parts in order and each
    part's names in order meets every name where the whole corpus first has it), the numbering of
    the single-process build."""
    from kb_service.engines import write_json

    names: dict[str, dict[str, int]] = {"sources": {}, "categories": {}}
    specs = (("source_ids", "sources", np.int16), ("category_ids", "categories", np.int32))
    tmps = {key: out_dir / f"{key}.npy.tmp" for key, _, _ in specs}
    handles = {key: open(tmps[key], "wb") for key in tmps}
    written = 0
    try:
        for key, _, dtype in specs:
            np.lib.format.write_array_header_1_0(handles[key], {"descr": np.dtype(dtype).str, "fortran_order": False,
                                                                "shape": (n,)})
        for part in parts:
            with np.load(part) as z:
                local = json.loads(str(z["names"]))
                arrays = {key: z[key] for key, _, _ in specs}
            for key, kind, dtype in specs:
                table = names[kind]
                remap = np.array([table.setdefault(name, len(table)) for name in local[kind]], dtype=np.int64)
                if kind == "sources" and len(table) > np.iinfo(np.int16).max:
                    raise IngestError(f"too many distinct sources ({len(table)}); sources name collections, "
                                      f"not documents")
                handles[key].write(remap[arrays[key]].astype(dtype).tobytes() if len(arrays[key]) else b"")
            written += len(arrays["source_ids"])
    finally:
        for fh in handles.values():
            fh.close()
    if written != n:
        raise IngestError(f"{out_dir}: the index parts hold {written} passages, the store {n}")
    for key, tmp in tmps.items():
        os.replace(tmp, out_dir / f"{key}.npy")
    result = {kind: list(table) for kind, table in names.items()}
    write_json(out_dir / "names.json", result)
    return result
