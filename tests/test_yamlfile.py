"""The strict YAML loader (plenocal.io.yamlfile) that reads camera.yaml and the workflow's
config files: a key given twice is refused, naming both lines; what YAML itself reads as
other keys is not."""

from __future__ import annotations

from pathlib import Path

import pytest

from plenocal.io.yamlfile import DuplicateKeyError, check_unique_keys, load_yaml_unique


def test_a_key_given_twice_names_both_lines():
    with pytest.raises(DuplicateKeyError, match=r"c\.yaml: datasets\.d\.views: given twice "
                                                r"\(lines 3 and 4\)"):
        load_yaml_unique("datasets:\n  d:\n    views: 5\n    views: 3\n", "c.yaml")


def test_merge_keys_and_keys_of_other_types_are_not_duplicates():
    """Two merge keys (<<: *a, <<: *b) are both merged by YAML, and 1 and '1' are two
    keys (a review found both refused)."""
    text = "s: &s {x: 1}\nv: &v {y: 2}\nd:\n  <<: *s\n  <<: *v\nk:\n  1: a\n  '1': b\n"
    doc = load_yaml_unique(text)
    assert doc["d"] == {"x": 1, "y": 2} and doc["k"] == {1: "a", "1": "b"}


def test_config_files_read_as_utf8_and_unparsable_ones_left_to_their_reader(tmp_path: Path):
    good = tmp_path / "good.yaml"
    good.write_bytes("place: Zürich\nunit: µm\n".encode())
    bad = tmp_path / "bad.yaml"
    bad.write_text("a: [1,\n")
    check_unique_keys([good, bad, tmp_path / "none.yaml"])
    twice = tmp_path / "twice.json"
    twice.write_text('{"views": 5, "views": 3}')
    with pytest.raises(DuplicateKeyError, match=r"twice\.json: views: given twice"):
        check_unique_keys([good, twice])
