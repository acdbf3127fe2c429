"""plenocal.malloc: the SIFT jobs' allocator settings fault in fewer pages, and change no
number (each case in a fresh process: the settings last for a process's life)."""

from __future__ import annotations

import json
import platform
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(platform.system() != "Linux" or platform.libc_ver()[0] != "glibc",
                                reason="mallopt is glibc's")

PROBE = r"""
import hashlib, json, resource, sys, tempfile
from pathlib import Path
import cv2
import numpy as np
import pycolmap
from plenocal.calib.reg_a import viewdb
from plenocal.malloc import keep_freed_memory

tmp = Path(tempfile.mkdtemp(dir=sys.argv[2]))
rng = np.random.default_rng(3)
views = {}
for k in range(6):  # the default data's view size
    img = cv2.GaussianBlur(rng.integers(0, 256, (502, 666, 3), dtype=np.uint8), (0, 0), 1.5)
    img = cv2.normalize(img, None, 0, 255, cv2.NORM_MINMAX)
    views[f"s/0_{k}"] = tmp / f"v{k}.png"
    cv2.imwrite(str(views[f"s/0_{k}"]), img)
taken = keep_freed_memory() if sys.argv[1] == "kept" else None
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
viewdb.extract_view_features(views, tmp / "f.db", tmp / "w", num_threads=1)
faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before
h = hashlib.sha256()
with pycolmap.Database.open(str(tmp / "f.db")) as db:
    for im in sorted(db.read_all_images(), key=lambda i: i.name):
        h.update(np.ascontiguousarray(db.read_keypoints(im.image_id)).tobytes())
        h.update(np.ascontiguousarray(db.read_descriptors(im.image_id).data).tobytes())
print(json.dumps({"taken": taken, "faults": faults, "features": h.hexdigest()}))
"""


def _run(mode: str, tmp: Path) -> dict:
    out = subprocess.run([sys.executable, "-c", PROBE, mode, str(tmp)], capture_output=True,
                         text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_the_kept_heap_faults_in_fewer_pages_and_sift_finds_the_same_features(tmp_path):
    """The view database's SIFT (rule view_features' function) on six views: each view's
    scale space faulted in fresh pages (about 20,000 a view); with the heap kept, a
    seventh as many. The keypoints and descriptors are the same bytes."""
    default, kept = _run("default", tmp_path), _run("kept", tmp_path)
    assert default["taken"] is None and kept["taken"] is True
    assert kept["features"] == default["features"]
    assert kept["faults"] < 0.4 * default["faults"], (kept, default)
