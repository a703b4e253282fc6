"""YAML at the edge: duplicate keys and booleans-for-numbers are refused, not guessed."""

from __future__ import annotations

import pytest

from pipeline.errors import ParamsError
from pipeline.yamlio import parse_yaml


def test_a_duplicate_key_is_refused_with_both_lines():
    text = "sim:\n  physics_dt_s: 0.001\n  physics_dt_s: 0.002\n"
    with pytest.raises(ParamsError, match=r"^f\.yaml: duplicate key 'physics_dt_s' "
                       r"\(first at line 2\) at line 3$"):  # fmt: skip
        parse_yaml(text, source="f.yaml", error=ParamsError)


def test_duplicates_in_flow_mappings_and_lists_of_mappings_are_refused():
    for text in ("a: {x: 1, x: 2}\n", "- {k: 1}\n- {k: 1, k: 2}\n"):
        with pytest.raises(ParamsError, match="duplicate key"):
            parse_yaml(text, source="f.yaml", error=ParamsError)


def test_the_same_key_in_different_mappings_and_merge_overrides_are_fine():
    text = "a: {x: 1}\nb: {x: 2}\nbase: &b {k: 1, j: 0}\nc:\n  <<: *b\n  k: 2\n"
    assert parse_yaml(text, source="f.yaml", error=ParamsError) == {
        "a": {"x": 1},
        "b": {"x": 2},
        "base": {"k": 1, "j": 0},
        "c": {"k": 2, "j": 0},
    }


def test_unsafe_tags_stay_refused():
    with pytest.raises(ParamsError, match="not valid YAML"):
        parse_yaml("a: !!python/object/apply:os.system ['true']\n", source="f", error=ParamsError)
