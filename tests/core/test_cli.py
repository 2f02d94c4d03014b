import io
import json

from envs.cli import main


def test_tasks_list_show_validate(capsys):
    assert main(["tasks", "list", "--domain", "ward", "--split", "test"]) == 0
    out = capsys.readouterr().out
    assert "ward_choice" in out and "ward_dose" not in out
    assert main(["tasks", "show", "ward_dose", "--domain", "ward"]) == 0
    assert json.loads(capsys.readouterr().out)["correct_answer"] == "375"
    assert main(["tasks", "show", "nope", "--domain", "ward"]) == 1
    assert main(["tasks", "validate", "--domain", "ward"]) == 0
    assert "ward: 3/3 tasks valid" in capsys.readouterr().out


def test_env_info_json(capsys):
    assert main(["env-info", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["ward"]["tasks"] == 3 and "add_allergy" in info["ward"]["tools"]


def test_play_reads_actions_from_the_terminal(monkeypatch, capsys):
    monkeypatch.setattr("sys.stdin", io.StringIO('get_patient(patient_id="P1")\nsubmit_answer(answer="B")\n'))
    assert main(["play", "--domain", "ward", "--task-id", "ward_choice"]) == 0
    out = capsys.readouterr().out
    assert "Ana Ruiz" in out and "=== reward" in out and "[call] submit_answer" in out


def test_tasks_import_reference(tmp_path, capsys):
    from pathlib import Path

    src = Path(__file__).parents[1] / "fixtures" / "reference_format" / "tasks_reference.json"
    out = tmp_path / "tasks.json"
    assert main(["tasks", "import", "--format", "reference", "--domain", "ward", "--output", str(out), str(src)]) == 0
    assert len(json.loads(out.read_text())) == 2
    assert "order_ct_scan" in capsys.readouterr().out


def test_errors_exit_2_with_a_message(capsys):
    assert main(["tasks", "import", "--format", "medqa-typo", "--domain", "ward", "--output", "x", "y"]) == 2
    assert "unknown format" in capsys.readouterr().err


def test_building_the_command_line_does_not_import_the_training_stack():
    """Every `hcgym` command builds the whole parser first: a command that trains nothing (tasks, kb,
    view, serve) must not pay for importing torch, transformers and Ray (~4 s of CPU per process)."""
    import subprocess
    import sys

    probe = ("import sys, envs.cli as cli; cli.build_parser(); "
             "print(','.join(m for m in ('torch', 'transformers', 'ray', 'deepspeed') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, check=True)
    assert out.stdout.strip() == "", f"building the hcgym parser imported {out.stdout.strip()}"
