import json

from envs.core.actions import parse_action

TOOLS = {"check_dose": None, "submit_answer": None, "get_patient": None}


def names(parsed):
    return [(c.name, c.arguments) for c in parsed.calls]


def test_bare_json_object():
    p = parse_action('{"name": "check_dose", "arguments": {"drug": "a", "dose_mg": 1}}', TOOLS)
    assert p.format == "json" and names(p) == [("check_dose", {"drug": "a", "dose_mg": 1})]


def test_openai_function_with_string_arguments_and_tool_calls_list():
    one = {"type": "function", "function": {"name": "check_dose", "arguments": json.dumps({"drug": "b"})}}
    p = parse_action(json.dumps(one), TOOLS)
    assert p.format == "openai" and names(p) == [("check_dose", {"drug": "b"})]
    many = {"role": "assistant", "content": "checking", "tool_calls": [one, {**one, "function": {"name": "get_patient", "arguments": "{}"}}]}
    p = parse_action(json.dumps(many), TOOLS)
    assert names(p) == [("check_dose", {"drug": "b"}), ("get_patient", {})] and p.message == "checking"


def test_hermes_blocks_in_order_with_message():
    text = ('Let me look.\n<tool_call>\n{"name": "get_patient", "arguments": {"patient_id": "P1"}}\n</tool_call>\n'
            '<tool_call>{"name": "submit_answer", "arguments": {"answer": "B"}}</tool_call>')
    p = parse_action(text, TOOLS)
    assert p.format == "hermes" and p.message == "Let me look."
    assert names(p) == [("get_patient", {"patient_id": "P1"}), ("submit_answer", {"answer": "B"})]


def test_fenced_json_block():
    p = parse_action('Plan:\n```json\n[{"name": "get_patient", "arguments": {"patient_id": "P2"}}]\n```', TOOLS)
    assert p.format == "fenced" and names(p) == [("get_patient", {"patient_id": "P2"})]
    assert p.message == "Plan:"


def test_function_call_syntax_values_are_literals():
    p = parse_action('get_patient(patient_id="P1")\ncheck_dose(drug=\'x\', dose_mg=2.5, route=oral, flag=true)', TOOLS)
    assert p.format == "function"
    assert names(p) == [("get_patient", {"patient_id": "P1"}),
                        ("check_dose", {"drug": "x", "dose_mg": 2.5, "route": "oral", "flag": True})]


def test_function_syntax_only_for_known_tools():
    p = parse_action("I think print(x) and max(a, b) are irrelevant (really).", TOOLS)
    assert p.format == "text" and not p.calls and not p.errors


def test_malformed_structures_are_reported_not_raised():
    p = parse_action("<tool_call>{not json}</tool_call>", TOOLS)
    assert not p.calls and "not valid JSON" in p.errors[0]
    p = parse_action('{"name": "check_dose", "arguments": "{broken"}', TOOLS)
    assert not p.calls and "not valid JSON" in p.errors[0]
    p = parse_action('{"name": "check_dose", "arguments": {', TOOLS)
    assert not p.calls and "looks like a JSON tool call" in p.errors[0]
    p = parse_action("check_dose('positional')", TOOLS)
    assert not p.calls and "keyword arguments" in p.errors[0]
    p = parse_action(None, TOOLS)  # type: ignore[arg-type]
    assert "must be a string" in p.errors[0]


def test_plain_text_and_empty():
    assert parse_action("The answer is B.", TOOLS).format == "text"
    assert parse_action("   ", TOOLS).format == "empty"
    assert parse_action('{"just": "data"}', TOOLS).format == "text"
