"""views.json (plenocal.convert.viewset): one shot's views as one unit for Snakemake."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from plenocal.convert.viewset import (
    read_view_set,
    remove_stale_views,
    view_set_files,
    view_set_path,
    write_view_set,
)
from plenocal.io.files import write_image

NAMES = ["0_0", "0_1", "1_0", "1_1"]


def _shot(root: Path, cam: str, seed: int = 0) -> Path:
    d = root / cam
    rng = np.random.default_rng(seed)
    for n in NAMES:
        write_image(d / f"{n}.png", rng.integers(0, 255, (6, 8, 3), dtype=np.uint8))
    return d


def test_lists_every_view_with_its_checksum(tmp_path):
    d = _shot(tmp_path, "x00_y00")
    path = write_view_set(d, NAMES)
    assert path == view_set_path(d) == d / "views.json"
    doc = json.loads(path.read_text())
    assert doc["format"] == "plenocal.view_set" and doc["version"] == 1
    assert doc["shot"] == "x00_y00" and list(doc["views"]) == NAMES
    # SHA-256 of the PNG bytes, computed here by hand
    assert doc["views"]["1_0"] == hashlib.sha256((d / "1_0.png").read_bytes()).hexdigest()
    assert read_view_set(path) == {n: d / f"{n}.png" for n in NAMES}


def test_bytes_change_exactly_when_a_view_changes(tmp_path):
    d = _shot(tmp_path, "x00_y00")
    first = write_view_set(d, NAMES).read_bytes()
    assert write_view_set(d, NAMES).read_bytes() == first  # rewritten: the same bytes
    write_image(d / "1_1.png", np.zeros((6, 8, 3), np.uint8))
    assert write_view_set(d, NAMES).read_bytes() != first


def test_keys_of_several_shots(tmp_path):
    sets = [write_view_set(_shot(tmp_path, c, i), NAMES)
            for i, c in enumerate(("x00_y00", "hand01"))]
    files = view_set_files(sets)
    assert sorted(files) == sorted(f"{c}/{n}" for c in ("x00_y00", "hand01") for n in NAMES)
    assert files["hand01/0_1"] == tmp_path / "hand01" / "0_1.png"


def test_a_missing_view_is_refused_when_writing(tmp_path):
    d = _shot(tmp_path, "x00_y00")
    (d / "0_1.png").unlink()
    with pytest.raises(FileNotFoundError, match=r"x00_y00: views 0_1 not found.*convert_views"):
        write_view_set(d, NAMES)
    assert not view_set_path(d).exists()


def test_reading_names_the_file_and_the_remedy(tmp_path):
    d = _shot(tmp_path, "x00_y00")
    path = write_view_set(d, NAMES)
    (d / "1_1.png").unlink()
    with pytest.raises(FileNotFoundError, match=r"views.json: lists views that are not on "
                                                r"disk \(.*1_1.png\).*convert_views"):
        read_view_set(path)
    path.write_text(json.dumps({"format": "plenocal.view_set", "version": 2, "views": {}}))
    with pytest.raises(ValueError, match=r"views.json: not a view set of version 1.*"
                                         r"version 2.*convert_views"):
        read_view_set(path)
    path.write_text(json.dumps({"format": "plenocal.view_set", "version": 1}))
    with pytest.raises(ValueError, match=r"without key 'views'"):
        read_view_set(path)
    with pytest.raises(FileNotFoundError, match=r"hand05/views.json: view set not found"):
        read_view_set(tmp_path / "hand05" / "views.json")


def test_stale_views_of_another_views_setting_are_removed(tmp_path):
    d = _shot(tmp_path, "x00_y00")
    for name in ("0_2.png", "2_2.png", "10_0.png"):
        (d / name).write_bytes(b"x")
    (d / "notes_1_1.png").write_bytes(b"x")  # not a view's name
    write_view_set(d, NAMES)
    gone = remove_stale_views(d, NAMES)
    assert [p.name for p in gone] == ["0_2.png", "10_0.png", "2_2.png"]
    assert sorted(p.name for p in d.iterdir()) == sorted(
        [f"{n}.png" for n in NAMES] + ["notes_1_1.png", "views.json"])
    assert read_view_set(view_set_path(d)) == {n: d / f"{n}.png" for n in NAMES}
    assert remove_stale_views(d, NAMES) == []
