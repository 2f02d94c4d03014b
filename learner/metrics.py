"""What a run records: per-step metrics (metrics.jsonl, TensorBoard, Ray dashboard) and trajectories.

`metrics.jsonl` in the run directory has one JSON object per learner step, with at least
`REQUIRED_KEYS`; validation results join the step they ran after (`val_*` keys). The same
scalars go to TensorBoard (`run_dir/tensorboard`) and, as `ray.util.metrics` gauges and
histograms, to the Ray dashboard / Prometheus endpoint (Ray prefixes the names with `ray_`).

Trajectories are written per step to Parquet (`run_dir/trajectories/step_XXXXXX.parquet`): token
ids, loss mask, sampling log-probs, policy versions, turn spans, reward components and metadata,
plus the teacher's log-probs when TT-OPD ran, so a step can be replayed into the loss for
debugging (`read_samples`, `learner.train.replay_loss`).
"""

from __future__ import annotations

import json
import math
import numbers
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

from actors.types import RolloutSample, TeacherOutput
from envs.core.files import append_durable, read_parquet, replace_atomic, write_text_atomic

VALIDATION_FILE = "validation.jsonl"  # one line per validation pass (learner/rollouts.py)

REQUIRED_KEYS = (
    "step", "reward_mean", "accuracy", "response_length_mean", "turns_mean", "tool_calls_mean",
    "kl_teacher", "kl_ref", "entropy", "grad_norm", "filtered_groups_frac", "teacher_wait_frac",
    "trajectories_per_s",
)


def _mean(values: Sequence[float]) -> float:
    return float(sum(values) / len(values)) if values else 0.0


def rollout_metrics(samples: Sequence[RolloutSample], max_response_tokens: int, prefix: str = "") -> dict[str, float]:
    """Rollout-side statistics of a set of episodes (a training batch or a validation pass).

    Args:
        samples: The episodes.
        max_response_tokens: The response limit (for the clip ratio).
        prefix: Prepended to every key (e.g. "val_").
    """
    if not samples:
        return {}
    lengths = [s.response_tokens for s in samples]
    out = {
        "reward_mean": _mean([s.reward for s in samples]),
        "reward_std": float(math.sqrt(_mean([(s.reward - _mean([x.reward for x in samples])) ** 2 for s in samples]))),
        "env_reward_mean": _mean([float(s.env_reward) for s in samples]),
        "accuracy": _mean([1.0 if s.correct else 0.0 for s in samples]),
        "response_length_mean": _mean(lengths),
        "response_length_max": float(max(lengths)),
        # Clip ratio: episodes cut by the response-token limit (the paper's "clipping").
        "response_clip_ratio": _mean([1.0 if s.metadata.get("truncation") == "response_tokens" else 0.0
                                      for s in samples]),
        "sequence_length_mean": _mean([len(s.input_ids) for s in samples]),
        "turns_mean": _mean([len(s.turns) for s in samples]),
        "tool_calls_mean": _mean([s.num_tool_calls for s in samples]),
        "truncated_frac": _mean([1.0 if s.truncated else 0.0 for s in samples]),
        "max_turns_frac": _mean([1.0 if s.metadata.get("truncation") == "max_turns" else 0.0 for s in samples]),
        "episodes": float(len(samples)),
    }
    components: dict[str, list[float]] = {}
    for s in samples:
        for key, value in s.reward_components.items():
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                components.setdefault(key, []).append(float(value))
    for key, values in components.items():
        out[f"reward_component/{key}"] = _mean(values)
    if max_response_tokens:
        out["response_length_frac_of_max"] = out["response_length_mean"] / max_response_tokens
    return {f"{prefix}{k}": v for k, v in out.items()}


class MetricsSink:
    """Writes step records to metrics.jsonl, TensorBoard and Ray metrics.

    Args:
        run_dir: The run directory.
        tensorboard: Also write TensorBoard event files.
        ray_metrics: Also export `ray.util.metrics` gauges / histograms (needs Ray initialised).
        run_name: Tag value distinguishing runs on a shared dashboard.
    """

    HISTOGRAMS = {
        "response_length": [64, 128, 256, 512, 1024, 2048, 4096, 8192, 12288, 16384],
        # Ray histograms need positive boundaries: counts, not rewards (rewards are gauges).
        "episode_turns": [1, 2, 3, 4, 5, 6, 8, 10],
        "episode_tool_calls": [1, 2, 3, 4, 6, 8, 12, 16],
    }

    def __init__(self, run_dir: str | Path, *, tensorboard: bool = True, ray_metrics: bool = True,
                 run_name: str = "run", resume: bool = False) -> None:
        self.run_dir = Path(run_dir)
        self.run_dir.mkdir(parents=True, exist_ok=True)
        self.path = self.run_dir / "metrics.jsonl"
        if not resume and self.path.exists():
            self.path.unlink()
        self.path.touch()  # a run directory always has one, even before its first step
        self.run_name = run_name
        self._tb = None
        if tensorboard:
            from torch.utils.tensorboard import SummaryWriter

            self._tb = SummaryWriter(log_dir=str(self.run_dir / "tensorboard"))
        self._gauges: dict[str, Any] = {}
        self._hists: dict[str, Any] = {}
        self._ray = ray_metrics

    def truncate_after(self, step: int, log: Callable[[str], None] = print) -> None:
        """On resume: drop the records of steps after the checkpoint from metrics.jsonl and
        validation.jsonl (those steps will be redone), and a last line a crash or a full disk cut
        short (`log` gets a warning naming the file and the line)."""
        for path in (self.path, self.run_dir / VALIDATION_FILE):
            if not path.exists():
                continue
            rows = read_jsonl_rows(path, torn_tail="cut", log=log)
            keep = [json.dumps(row, allow_nan=False) for row in rows if int(row.get("step", 0)) <= step]
            write_text_atomic(path, "".join(line + "\n" for line in keep))

    def validated_steps(self) -> set[int]:
        """The steps validation.jsonl has a row for."""
        path = self.run_dir / VALIDATION_FILE
        return {int(row.get("step", 0)) for row in read_jsonl_rows(path)} if path.exists() else set()

    def _ray_gauge(self, key: str):
        from ray.util.metrics import Gauge

        name = "hcgym_" + "".join(c if c.isalnum() else "_" for c in key)
        if name not in self._gauges:
            self._gauges[name] = Gauge(name, description=f"training metric {key}", tag_keys=("run",))
        return self._gauges[name]

    def observe(self, name: str, values: Iterable[float]) -> None:
        """Feed a Ray histogram (per-episode values: response length, reward)."""
        if not self._ray:
            return
        from ray.util.metrics import Histogram

        if name not in self._hists:
            self._hists[name] = Histogram(f"hcgym_{name}", description=f"per-episode {name}",
                                          boundaries=self.HISTOGRAMS[name], tag_keys=("run",))
        for value in values:
            self._hists[name].observe(float(value), tags={"run": self.run_name})

    def write(self, record: dict[str, Any]) -> None:
        step = int(record["step"])
        # fsynced: on disk before the step's checkpoint becomes `latest` (learner/train.py), so a node
        # that loses power after that does not come back with the row missing. A full disk raises
        # DiskFullError naming the file and leaves no half row behind.
        line = json.dumps(json_record(record), sort_keys=False, allow_nan=False) + "\n"
        append_durable(self.path, line.encode("utf-8"))
        for key, value in record.items():
            if key == "step" or not isinstance(value, (int, float)) or isinstance(value, bool):
                continue
            if not math.isfinite(float(value)):
                continue
            if self._tb is not None:
                self._tb.add_scalar(key, float(value), step)
            if self._ray:
                self._ray_gauge(key).set(float(value), tags={"run": self.run_name})
        if self._tb is not None:
            self._tb.flush()

    def close(self) -> None:
        """Flush and stop the TensorBoard writer and its thread (again: a no-op)."""
        if self._tb is not None:
            self._tb.close()
            self._tb = None


def json_record(record: dict[str, Any]) -> dict[str, Any]:
    """A metrics row as standard JSON: numbers as floats/ints (numpy scalars included), NaN and
    infinities as null (bare `NaN` is not JSON: browsers and most readers refuse the whole line)."""
    out: dict[str, Any] = {}
    for key, value in record.items():
        if isinstance(value, bool) or value is None or isinstance(value, str):
            out[key] = value
        elif isinstance(value, numbers.Integral):
            out[key] = int(value)
        elif isinstance(value, numbers.Real):
            out[key] = float(value) if math.isfinite(float(value)) else None
        else:
            out[key] = value
    return out


def read_metrics(run_dir: str | Path) -> list[dict[str, Any]]:
    """The rows of `metrics.jsonl`; a metric written as null (it was NaN or infinite) reads as NaN."""
    path = Path(run_dir) / "metrics.jsonl"
    if not path.exists():
        raise FileNotFoundError(f"{path}: no metrics.jsonl (is {run_dir} a run directory?)")
    return read_metric_rows(path)


def read_metric_rows(path: Path) -> list[dict[str, Any]]:
    """Rows of a metrics JSONL file (metrics.jsonl, validation.jsonl), nulls read back as NaN.
    A last line still being appended (no newline yet, not a whole record) is not read."""
    rows = read_jsonl_rows(Path(path), torn_tail="skip")
    return [{k: (math.nan if v is None else v) for k, v in row.items()} for row in rows]


def read_jsonl_rows(path: Path, *, torn_tail: str = "error",
                    log: Callable[[str], None] | None = None) -> list[dict[str, Any]]:
    """The JSON objects of an append-only JSONL file, one per line.

    Args:
        path: The file.
        torn_tail: What to do with a last line that is not a whole JSON object (an append a crash
            or a full disk cut short): "error" raises, "skip" leaves it out, "cut" also removes it
            from the file, telling `log` which file and line.

    Raises:
        ValueError: naming the file and the line, for a line before the last that is not a JSON
            object (damage no crash causes), or a torn last line with torn_tail="error".
    """
    data = path.read_bytes()
    lines = data.split(b"\n")
    rows: list[dict[str, Any]] = []
    for number, raw in enumerate(lines, 1):
        if not raw.strip():
            continue
        last = all(not rest.strip() for rest in lines[number:])
        try:
            row = json.loads(raw.decode("utf-8"))
            if not isinstance(row, dict):
                raise ValueError(f"a JSON {type(row).__name__}, not an object")
        except ValueError as exc:  # JSONDecodeError and UnicodeDecodeError are ValueErrors
            what = f"{path} line {number} ({len(raw)} bytes) is not a complete JSON record ({exc})"
            if not last or torn_tail == "error":
                raise ValueError(what) from None
            if torn_tail == "cut":
                good = data[:sum(len(line) + 1 for line in lines[:number - 1])]
                replace_atomic(path, lambda tmp: tmp.write_bytes(good))
                if log is not None:
                    log(f"[resume] warning: {what}: cut short by a crash or a full disk; removed that line")
            break
        rows.append(row)
    return rows


# ---------------------------------------------------------------------------------------------
# Trajectories <-> Parquet
# ---------------------------------------------------------------------------------------------

_JSON_FIELDS = ("turns", "reward_components", "metadata", "episode")
#: Scalar columns derived from the episode record, so a viewer can filter 100K episodes without
#: parsing one JSON document (`read_samples` ignores them: they are recomputed from `episode`).
INDEX_COLUMNS = ("end_reason", "safety_max_severity", "error_kinds")


def episode_index_fields(sample: RolloutSample) -> dict[str, Any]:
    """How the episode ended, its worst safety violation (0 = none) and the kinds of its errors
    (tool-call error kinds from envs.core.trajectory.ErrorKind, plus "parse_error")."""
    from envs.episode import LEGACY_END_REASONS

    record = sample.episode
    truncation = str(sample.metadata.get("truncation") or "")
    # the agent loop's `metadata["end_reason"]` (envs.episode.EndReason); samples written before it
    # existed are mapped from their truncation label
    ended = sample.metadata.get("end_reason") or LEGACY_END_REASONS.get(truncation, truncation)
    if record is None:
        return {"end_reason": ended or "unknown", "safety_max_severity": None, "error_kinds": []}
    severities = [int(v.get("severity") or 0) for v in (record.reward_details.get("violations") or [])
                  if isinstance(v, dict)]
    kinds = {call.error_kind for turn in record.turns for call in turn.tool_calls if call.error_kind}
    if any(turn.parse_errors for turn in record.turns):
        kinds.add("parse_error")
    # "text_answer": a turn without a tool call ended the episode (rollout.text_turn_ends_episode)
    end = ended or record.metadata.get("end_reason") or (
        "answer" if record.submitted_answer is not None else "turn_limit" if record.truncated else "unknown")
    return {"end_reason": end, "safety_max_severity": max(severities, default=0), "error_kinds": sorted(kinds)}


def write_samples(samples: Sequence[RolloutSample], path: str | Path, *, step: int,
                  teacher: dict[str, TeacherOutput] | None = None, accepted: dict[str, bool] | None = None) -> Path:
    """Write episodes (and their teacher log-probs, when given) to one Parquet file.

    Args:
        samples: Episodes.
        path: Output file.
        step: The learner step that consumed them (a column, for filtering).
        teacher: sample id -> teacher output (TT-OPD runs).
        accepted: sample id -> whether dynamic sampling kept its group (default True).
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    teacher = teacher or {}
    accepted = accepted or {}
    rows: dict[str, list] = {name: [] for name in RolloutSample.model_fields}
    rows.update({"step": [], "accepted": [], "teacher_logprobs": [], "teacher_version": [], "teacher_hint": []})
    rows.update({name: [] for name in INDEX_COLUMNS})
    for s in samples:
        for name, value in episode_index_fields(s).items():
            rows[name].append(value)
        data = s.model_dump(mode="json")
        for name in RolloutSample.model_fields:
            value = data[name]
            rows[name].append(json.dumps(value, ensure_ascii=False) if name in _JSON_FIELDS else value)
        t = teacher.get(s.sample_id)
        rows["step"].append(step)
        rows["accepted"].append(bool(accepted.get(s.sample_id, True)))
        rows["teacher_logprobs"].append(t.logprobs if t else None)
        rows["teacher_version"].append(t.teacher_version if t else None)
        rows["teacher_hint"].append(t.hint if t else None)
    schema = pa.schema([
        ("sample_id", pa.string()), ("task_id", pa.string()), ("domain", pa.string()), ("group_id", pa.string()),
        ("seed", pa.int64()), ("prompt_length", pa.int32()), ("input_ids", pa.list_(pa.int32())),
        ("loss_mask", pa.list_(pa.int8())), ("sampling_logprobs", pa.list_(pa.float32())),
        ("policy_versions", pa.list_(pa.int32())), ("turns", pa.string()), ("env_reward", pa.float64()), ("env_correct", pa.bool_()),
        ("reward", pa.float64()),
        ("reward_components", pa.string()), ("correct", pa.bool_()), ("truncated", pa.bool_()),
        ("num_tool_calls", pa.int32()), ("response_tokens", pa.int32()), ("metadata", pa.string()),
        ("episode", pa.string()),
        ("step", pa.int32()), ("accepted", pa.bool_()), ("teacher_logprobs", pa.list_(pa.float32())),
        ("teacher_version", pa.int32()), ("teacher_hint", pa.string()),
        ("end_reason", pa.string()), ("safety_max_severity", pa.int8()), ("error_kinds", pa.list_(pa.string())),
    ])
    table = pa.table({f.name: pa.array(rows[f.name], type=f.type) for f in schema}, schema=schema)
    path = Path(path)
    # Through a temporary file: a full disk or a crash mid-write leaves no half file under the
    # step's name (DiskFullError names the file).
    replace_atomic(path, lambda tmp: pq.write_table(table, str(tmp)))
    return path


def read_samples(path: str | Path) -> tuple[list[RolloutSample], dict[str, dict[str, Any]]]:
    """Read a Parquet file written by `write_samples`.

    Returns:
        (samples, extras) where extras[sample_id] has `step`, `accepted` and, for TT-OPD runs,
        `teacher_logprobs`, `teacher_version`, `teacher_hint`.

    Raises:
        FileNotFoundError: the file is missing.
        ValueError: naming the file, when it is damaged (not readable as Parquet).
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such trajectory file")
    samples, extras = [], {}
    for row in read_parquet(path).to_pylist():
        extra = {k: row.pop(k) for k in ("step", "accepted", "teacher_logprobs", "teacher_version", "teacher_hint")}
        for name in INDEX_COLUMNS:
            row.pop(name, None)
        for name in _JSON_FIELDS:
            if name in row:  # files written before a column existed (e.g. `episode`) still read
                row[name] = json.loads(row[name])
        # float32 storage: the log-probs come back rounded to float32, which is what the learner uses.
        sample = RolloutSample.model_validate(row)
        samples.append(sample)
        extras[sample.sample_id] = extra
    return samples, extras
