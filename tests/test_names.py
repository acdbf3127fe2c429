"""Shot and view names (plenocal.names): the one place that spells and parses them."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from plenocal import names


def test_shots_are_spelled_with_two_digits_row_major():
    assert names.array_shots(3, 2) == ["x00_y00", "x01_y00", "x02_y00",
                                       "x00_y01", "x01_y01", "x02_y01"]
    assert names.handheld_shots(2) == ["hand00", "hand01"]
    assert names.array_position("x12_y03") == (12, 3)
    assert names.array_position("hand07") is None
    assert names.is_array_shot("x01_y00") and not names.is_array_shot("hand01")
    assert names.is_handheld_shot("hand01") and not names.is_handheld_shot("x01_y00")
    for bad in ("x1_y0", "X01_Y00", "hand1", "x01_y00.png", ""):
        assert not names.is_shot(bad)
    with pytest.raises(names.BadName, match="x1_y0"):
        names.array_position("x1_y0")


def test_the_middle_view_is_taken_by_number_not_as_text():
    # as text, "10_x" sorts before "2_x": the middle of 11 x 11 sorted names is 4_4
    for n, centre in ((3, "1_1"), (5, "2_2"), (11, "5_5"), (13, "6_6"), (15, "7_7")):
        assert names.middle_view(names.view_names(n)) == centre
        assert names.middle_view(reversed(names.view_names(n))) == centre
    assert names.middle_view(["2_2"]) == "2_2"  # a hand-held shot's one view
    with pytest.raises(names.BadName):
        names.middle_view([])


def test_views_and_keys_round_trip():
    assert names.view_names(3)[:4] == ["0_0", "0_1", "0_2", "1_0"]
    assert names.central_view(5) == "2_2"
    assert names.parse_view("10_3") == (10, 3)
    key = names.view_key("hand02", "4_1")
    assert key == "hand02/4_1"
    assert names.split_key(key) == ("hand02", "4_1")
    assert names.key_shot(key) == "hand02" and names.key_view(key) == "4_1"
    assert names.file_key("results/d/views/hand02/4_1.png") == key
    assert names.file_key(Path("depth/views/x01_y00/10_3.npy")) == "x01_y00/10_3"
    for bad in ("hand02", "hand02/4-1", "x01_y00/2_2/x", "cam/2_2"):
        assert not names.is_key(bad)
        with pytest.raises(names.BadName, match=re.escape(repr(bad))):
            names.split_key(bad)
    with pytest.raises(names.BadName, match="2x2"):
        names.parse_view("2x2")


def test_patterns_match_what_the_functions_spell():
    shot = re.compile(rf"^({names.SHOT_PATTERN})$")
    view = re.compile(rf"^({names.VIEW_PATTERN})$")
    assert all(shot.match(s) for s in names.array_shots(2, 2) + names.handheld_shots(2))
    assert all(view.match(v) for v in names.view_names(5))


def test_only_ascii_digits_and_whole_names():
    """Issue 34: ``\\d`` matched the digits of other scripts (x٠٠_y٠٠.png passed the
    lenslet-name check, then failed as a MissingInputException), and ``$`` matched before
    a trailing newline."""
    arabic = "x\u0660\u0660_y\u0660\u0660"
    for bad in (arabic, "hand\u0660\u0661", "x00_y00\n", "hand01\n"):
        assert not names.is_shot(bad), repr(bad)
        assert not re.fullmatch(names.SHOT_PATTERN, bad), repr(bad)
    with pytest.raises(names.BadName):
        names.array_position("x00_y00\n")
    for bad in ("\u0661_\u0661", "1_1\n"):
        assert not re.fullmatch(names.VIEW_PATTERN, bad)
        with pytest.raises(names.BadName):
            names.parse_view(bad)
    assert not names.is_key("x00_y00/1_1\n")


def test_views_per_side_must_be_a_whole_number():
    """Issue 34: ``views: 3.0`` gave a bare TypeError here (the config check now refuses it
    first, naming the key: tests/test_config.py)."""
    import numpy as np

    assert names.view_names(np.int64(3)) == names.view_names(3)
    with pytest.raises(names.BadName, match="views"):
        names.view_names(3.0)
