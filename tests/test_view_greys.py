"""The views' grey levels read once per refinement (plenocal.calib.view_greys)."""

import cv2
import numpy as np
import pytest

from plenocal.calib import view_greys as vg


def _views(tmp_path, n=3):
    rng = np.random.default_rng(0)
    files = {}
    for i in range(n):
        path = tmp_path / f"v{i}.png"
        cv2.imwrite(str(path), rng.integers(0, 256, (12, 16, 3), dtype=np.uint8))
        files[f"x00_y00/{i}_0"] = path
    return files


def test_each_view_is_decoded_once_and_reads_as_the_file_does(tmp_path, monkeypatch):
    files = _views(tmp_path)
    greys = vg.ViewGreys(files)
    assert dict(greys) == files  # a mapping of the files, as the refinement's images
    reads = []
    real = vg.read_grey
    monkeypatch.setattr(vg, "read_grey", lambda p: reads.append(p) or real(p))
    for _ in range(2):
        for key in files:
            got = vg.grey_of(greys, key)
            assert np.array_equal(got, cv2.imread(str(files[key]), cv2.IMREAD_GRAYSCALE))
    assert reads == list(files.values())  # each once
    # a plain mapping of files is read every time
    reads.clear()
    vg.grey_of(files, "x00_y00/0_0")
    vg.grey_of(files, "x00_y00/0_0")
    assert len(reads) == 2


def test_an_unreadable_view_names_the_file_and_the_remedy(tmp_path):
    bad = tmp_path / "broken.png"
    bad.write_bytes(b"not a png")
    with pytest.raises(ValueError, match="broken.png: not a readable image.*rerun the conversion"):
        vg.ViewGreys({"x00_y00/0_0": bad}).grey("x00_y00/0_0")
