"""The paper's four training-dynamics panels for one or more runs.

(a) validation accuracy, (b) KL (student || teacher, solid; to the reference, dashed),
(c) response length, (d) turns per episode, against the learner step. Several run directories
are overlaid in one figure (ablations).

    hcgym plot runs/demo                     -> runs/demo/training_dynamics.png
    hcgym plot runs/grpo runs/ttopd --output ablation.png
"""

from __future__ import annotations

from pathlib import Path

from learner.metrics import read_metric_rows, read_metrics


def _validation(run_dir: Path) -> list[dict]:
    path = run_dir / "validation.jsonl"
    if not path.exists():
        return []
    return read_metric_rows(path)


def _label(run_dir: Path) -> str:
    config = run_dir / "config.yaml"
    if config.exists():
        import yaml

        name = (yaml.safe_load(config.read_text(encoding="utf-8")) or {}).get("name")
        if name:
            return f"{name} ({run_dir.name})" if name != run_dir.name else name
    return run_dir.name


def plot_runs(run_dirs: list[str | Path], output: str | Path | None = None, labels: list[str] | None = None) -> Path:
    """Draw the four panels for the runs and write a PNG.

    Args:
        run_dirs: Run directories (each with metrics.jsonl; validation.jsonl when validation ran).
        output: PNG path; default `<first run dir>/training_dynamics.png`.
        labels: Legend labels, one per run (default: the run's config name).

    Returns:
        The PNG path.

    Raises:
        FileNotFoundError: A run directory has no metrics.jsonl.
        ValueError: `labels` does not match `run_dirs` in length.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    dirs = [Path(d) for d in run_dirs]
    if not dirs:
        raise ValueError("plot_runs: no run directories")
    if labels is not None and len(labels) != len(dirs):
        raise ValueError(f"plot_runs: {len(labels)} labels for {len(dirs)} runs")
    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5))
    (ax_acc, ax_kl), (ax_len, ax_turns) = axes
    for index, run_dir in enumerate(dirs):
        metrics = read_metrics(run_dir)
        label = labels[index] if labels else _label(run_dir)
        color = f"C{index % 10}"
        steps = [m["step"] for m in metrics]
        val = _validation(run_dir)
        if val:
            ax_acc.plot([v["step"] for v in val], [v["val_accuracy"] for v in val], "o-", color=color, label=label)
        ax_kl.plot(steps, [m.get("kl_teacher", 0.0) for m in metrics], "-", color=color, label=f"{label}: KL(S||T)")
        ax_kl.plot(steps, [m.get("kl_ref", 0.0) for m in metrics], "--", color=color, alpha=0.6,
                   label=f"{label}: KL(S||ref)")
        ax_len.plot(steps, [m["response_length_mean"] for m in metrics], "-", color=color, label=label)
        ax_turns.plot(steps, [m["turns_mean"] for m in metrics], "-", color=color, label=label)
    ax_acc.set_title("(a) validation accuracy")
    ax_acc.set_ylabel("accuracy")
    ax_kl.set_title("(b) KL divergence")
    ax_kl.set_ylabel("KL (nats / token)")
    ax_len.set_title("(c) response length")
    ax_len.set_ylabel("assistant tokens / episode")
    ax_turns.set_title("(d) turns per episode")
    ax_turns.set_ylabel("assistant turns")
    for ax in axes.flat:
        ax.set_xlabel("step")
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    fig.tight_layout()
    out = Path(output) if output else dirs[0] / "training_dynamics.png"
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
