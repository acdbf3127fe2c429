"""bench/bench_real.py's choice of frames: a missing folder or frame stops it, with the
path and the remedy, instead of printing an empty table that reads as a measured one."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
import bench_real  # noqa: E402


def test_no_shared_frames_stops_with_the_folder(tmp_path, monkeypatch):
    monkeypatch.setattr(bench_real, "REAL", tmp_path / "real")
    with pytest.raises(SystemExit, match="no lenslet frames"):
        bench_real.real_frames(None)


def test_a_frame_not_there_is_named(tmp_path, monkeypatch):
    (tmp_path / "real" / "frames").mkdir(parents=True)
    for name in ("Boys2", "HandTools"):
        (tmp_path / "real" / "frames" / f"{name}.png").write_bytes(b"")
    monkeypatch.setattr(bench_real, "REAL", tmp_path / "real")
    with pytest.raises(SystemExit, match="--frames Handtools: not in"):
        bench_real.real_frames(["Handtools"])
    assert bench_real.real_frames(["HandTools"]) == ["HandTools"]
    assert bench_real.real_frames(None) == ["Boys2", "HandTools"]


_IMPORT_AFTER_NUMBA = """
import sys
sys.path.insert(0, "bench")
import numba
import numpy as np

@numba.njit(parallel=True)
def total(x):
    s = 0.0
    for i in numba.prange(x.size):
        s += x[i]
    return s

total(np.ones(8))  # numba's threads started, as by the simulator's tests
import bench_real  # noqa: F401

@numba.njit
def plus_one(x):
    return x + 1

print(plus_one(1))  # a kernel compiled after the import
"""


def test_importing_the_bench_leaves_the_process_threads_alone():
    """Imported (as above), bench_real once set NUMBA_NUM_THREADS=1 in the importing
    process: every numba kernel compiled after it in that pytest worker then failed
    ("Cannot set NUMBA_NUM_THREADS to a different value once the threads have been
    launched"), the simulator's tests among them. Its one-thread settings are now for its
    own process only."""
    root = Path(__file__).resolve().parents[1]
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    out = subprocess.run([sys.executable, "-c", _IMPORT_AFTER_NUMBA], cwd=root, env=env,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and out.stdout.strip() == "2", out.stderr[-2000:]


def test_a_tlct_that_cannot_run_is_refused_before_any_frame(tmp_path):
    # a missing or non-executable binary showed only as "failed" per round, and on a frame
    # without a TLCT cfg not at all
    binary = tmp_path / "tlct"
    assert "no such file" in bench_real.tlct_problem(binary)
    assert "a folder" in bench_real.tlct_problem(tmp_path)
    binary.write_text("#!/bin/sh\nexit 0\n")
    binary.chmod(0o644)
    assert "not executable" in bench_real.tlct_problem(binary)
    binary.chmod(0o755)
    assert bench_real.tlct_problem(binary) is None
