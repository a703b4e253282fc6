"""The one wording for an unknown name: where, what, the near miss and the valid names."""

from __future__ import annotations

from pipeline.errors import unknown_name_message


def test_unknown_name_names_the_near_miss_and_lists_the_valid_names_in_order() -> None:
    message = unknown_name_message("controller", "ctcc", ["pid", "ctc"], where="a.type")
    assert message == "a.type: unknown controller 'ctcc' (did you mean 'ctc'?); valid: pid, ctc"


def test_a_near_miss_in_another_case_is_suggested_as_spelled() -> None:
    assert "(did you mean 'Panda'?)" in unknown_name_message("robot", "PANDA", ["Panda", "ur5"])


def test_without_a_near_miss_or_valid_names_the_message_says_so() -> None:
    assert unknown_name_message("campaign", "x", []) == "unknown campaign 'x'; valid: none"
