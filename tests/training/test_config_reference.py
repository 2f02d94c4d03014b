"""The run config's reference page: every leaf setting is described, and docs/config.md is the
page the models generate (`hcgym config reference --output docs/config.md` rewrites it)."""

from __future__ import annotations

from pathlib import Path

from pydantic import Field

from learner.config import RunConfig
from learner.config_reference import (REGENERATE, check_reference, format_type, leaf_settings, render_reference,
                                      undocumented)
from modeling.config_models import ConfigModel

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "config.md"


def test_every_leaf_setting_has_a_description():
    missing = undocumented()
    assert not missing, ("run-config settings without a description (give each a Field(description=...)): "
                         + ", ".join(missing))


def test_reference_page_is_current():
    page = PAGE.read_text(encoding="utf-8") if PAGE.is_file() else ""
    assert page == render_reference(), f"docs/config.md is stale or missing; regenerate it with `{REGENERATE}`"


def test_page_has_one_row_per_leaf_setting():
    page = render_reference()
    settings = leaf_settings()
    rows = [line for line in page.splitlines() if line.startswith("| `")]
    assert len(rows) == len(settings)
    for setting in settings:
        assert f"| `{setting.key}` |" in page, setting.key
    # Sections come from the models: every top-level section of RunConfig has its heading.
    for name, field in RunConfig.model_fields.items():
        if hasattr(field.annotation, "model_fields"):
            assert f"\n## `{name}`\n" in page, name


def test_an_undescribed_setting_is_named():
    class Inner(ConfigModel):
        documented: int = Field(default=1, description="has one")
        bare: float = 0.5

    class Outer(ConfigModel):
        inner: Inner = Field(default_factory=Inner)
        top: str = "x"

    assert undocumented(Outer) == [f"top (Outer in {__name__})", f"inner.bare (Inner in {__name__})"]
    assert [s.key for s in leaf_settings(Outer)] == ["top", "inner.documented", "inner.bare"]


def test_row_shows_type_bounds_and_default():
    page = render_reference()
    assert "| `trainer.batch_size` | `int (>= 1)` | `8` | prompts (groups) per learner step |" in page
    assert "| `model.path` | `str \\| null` | `null` |" in page
    assert format_type(RunConfig.model_fields["model"].annotation) == "ModelConfig"


def test_check_names_a_stale_page_and_the_command(tmp_path):
    stale = tmp_path / "config.md"
    stale.write_text(render_reference().replace("prompts (groups) per learner step", "old text"), encoding="utf-8")
    problems = check_reference(stale)
    assert problems == [f"{stale}: differs from the config models; regenerate it with `{REGENERATE}`"]
    assert check_reference(tmp_path / "absent.md") == [f"{tmp_path / 'absent.md'}: missing; write it with `{REGENERATE}`"]
    fresh = tmp_path / "fresh.md"
    fresh.write_text(render_reference(), encoding="utf-8")
    assert check_reference(fresh) == []


def test_cli_writes_and_checks_the_page(tmp_path, capsys):
    from envs.cli import main

    out = tmp_path / "config.md"
    assert main(["config", "reference", "--output", str(out)]) == 0
    assert out.read_text(encoding="utf-8") == render_reference()
    assert main(["config", "reference", "--check", "--output", str(out)]) == 0
    out.write_text("# hand-edited\n", encoding="utf-8")
    capsys.readouterr()
    assert main(["config", "reference", "--check", "--output", str(out)]) == 1
    assert f"{out}: differs from the config models; regenerate it with `{REGENERATE}`" in capsys.readouterr().err
