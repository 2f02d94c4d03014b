from typing import Literal

import pytest

from envs.core.tools import CompositeToolkit, Toolkit, ToolType, is_tool, parse_google_docstring
from tests.fixtures.ward_domain.environment import WardDB, WardTools, SharedNotes, get_environment


class Kit(Toolkit):
    @is_tool(ToolType.READ)
    def check_dose(self, drug: str, dose_mg: float, route: Literal["oral", "iv"] = "oral",
                   tags: list[str] | None = None, count: int = 1) -> dict:
        """Check a dose against limits.

        Args:
            drug: Generic drug name.
            dose_mg: Dose in mg.
            route: Route of administration.
            tags: Optional labels that
                continue on a second line.
            count: How many doses.
        """
        return {"drug": drug, "dose_mg": dose_mg, "route": route, "count": count}


def test_schema_from_signature_and_docstring():
    schema = Kit().schemas()[0]
    assert schema["type"] == "function"
    fn = schema["function"]
    assert fn["name"] == "check_dose"
    assert fn["description"] == "Check a dose against limits."
    props = fn["parameters"]["properties"]
    assert props["route"]["enum"] == ["oral", "iv"] and props["route"]["default"] == "oral"
    assert props["dose_mg"]["type"] == "number" and props["count"]["type"] == "integer"
    assert props["tags"]["type"] == "array" and props["tags"]["items"] == {"type": "string"}
    assert props["tags"]["description"] == "Optional labels that continue on a second line."
    assert fn["parameters"]["required"] == ["drug", "dose_mg"]


def test_docstring_parser_stops_at_returns():
    desc, args = parse_google_docstring("""Do it.

    More text.

    Args:
        a (int): first.
        b: second.
    Returns:
        c: not an argument.
    """)
    assert desc == "Do it."
    assert args == {"a": "first.", "b": "second."}


def test_arguments_are_typed_and_errors_name_the_argument():
    kit = Kit()
    assert kit.call("check_dose", {"drug": "x", "dose_mg": "5"}).result["dose_mg"] == 5.0
    err = kit.call("check_dose", {"drug": "x", "dose_mg": "lots"}).error
    assert "'dose_mg'" in err and "number" in err
    err = kit.call("check_dose", {"drug": "x"}).error
    assert "missing required argument 'dose_mg' (number)" in err
    err = kit.call("check_dose", {"drug": "x", "dose_mg": 1, "rout": "iv"}).error
    assert "unknown argument 'rout'" in err and "did you mean 'route'" in err
    err = kit.call("check_dose", {"drug": "x", "dose_mg": 1, "route": "rectal"}).error
    assert "'route'" in err and "'oral'" in err
    assert "arguments must be a JSON object" in kit.call("check_dose", ["x"]).error


def test_unknown_tool_suggests_nearest_names():
    err = Kit().call("chek_dose", {}).error
    assert "unknown tool 'chek_dose'" in err and "check_dose" in err


def test_composite_first_wins_and_reports_shadowing():
    env = get_environment()
    kit = env.toolkit
    assert isinstance(kit, CompositeToolkit)
    assert kit.call("get_patient", {"patient_id": "P1"}).result["name"] == "Ana Ruiz"
    assert ("get_patient", "SharedNotes") in kit.shadowed
    assert kit.call("count_patients", {}).result == -1  # the shared tool is still reachable
    assert kit.get_definition("think").tool_type is ToolType.THINK
    assert kit.get_definition("submit_answer").submit


def test_failed_write_leaves_database_unchanged():
    env = get_environment()
    before = env.db_hash()
    outcome = env.toolkit.call("add_allergy", {"patient_id": "P1", "substance": "forbidden", "severity": "severe"})
    assert outcome.error and "cannot record" in outcome.error
    assert env.db_hash() == before
    assert env.toolkit.call("add_allergy", {"patient_id": "P1", "substance": "latex"}).ok
    assert env.db_hash() != before
    assert "latex" in env.db.patients["P1"].allergies


def test_db_hash_is_stable_and_order_independent():
    a = WardDB.model_validate({"patients": {"P1": {"patient_id": "P1", "name": "a", "age": 1, "weight_kg": 1},
                                            "P2": {"patient_id": "P2", "name": "b", "age": 2, "weight_kg": 2}}})
    b = WardDB.model_validate({"patients": {"P2": {"patient_id": "P2", "name": "b", "age": 2, "weight_kg": 2},
                                            "P1": {"patient_id": "P1", "name": "a", "age": 1, "weight_kg": 1}}})
    assert a.content_hash() == b.content_hash()
    b.patients["P1"].age = 3
    assert a.content_hash() != b.content_hash()


def test_tool_needs_description_and_annotations():
    with pytest.raises(TypeError, match="description"):
        class NoDoc(Toolkit):
            @is_tool()
            def f(self, a: int) -> int:
                return a
    with pytest.raises(TypeError, match="no type annotation"):
        class NoHint(Toolkit):
            @is_tool()
            def g(self, a) -> int:
                """Doc."""
                return a


def test_ward_tools_are_collected():
    assert {"get_patient", "dose_for_weight", "add_allergy", "think", "submit_answer"} <= set(WardTools._definitions)
    assert "count_patients" in SharedNotes._definitions


class Failing(Toolkit):
    @is_tool(ToolType.READ)
    def score(self, points: int) -> int:
        """Score points.

        Args:
            points: 0 to 10.
        """
        if points > 10:
            raise ValueError("points must be in 0..10")
        if points == 7:
            raise RuntimeError("a bug in the tool")
        return points

    @is_tool(ToolType.READ)
    def refuse(self) -> str:
        """Always refuses."""
        from envs.core.tools import ToolError

        raise ToolError("not allowed here")


@pytest.mark.parametrize(("name", "args", "kind"), [
    ("score", {"points": 3}, None),
    ("scor", {"points": 3}, "unknown_tool"),
    ("score", {"points": "many"}, "invalid_arguments"),
    ("score", {}, "invalid_arguments"),
    ("refuse", {}, "tool_error"),
    ("score", {"points": 11}, "input_error"),
    ("score", {"points": 7}, "internal_error"),
])
def test_failed_calls_carry_a_structured_error_kind(name, args, kind):
    outcome = Failing().call(name, args)
    assert outcome.error_kind == kind and (outcome.error is None) == (kind is None)
