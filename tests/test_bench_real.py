"""bench/bench_real.py's choice of frames: a missing folder or frame stops it, with the
path and the remedy, instead of printing an empty table that reads as a measured one."""

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
