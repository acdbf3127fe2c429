"""Eq. 5: the scale between registrations A and B on synthetic depth maps with a known
ratio, invalid pixels and outliers."""

from __future__ import annotations

import numpy as np
import pytest

from plenocal.calib import scale


def maps(r: float, seed: int, outliers: float = 0.05):
    rng = np.random.default_rng(seed)
    d1 = rng.uniform(0.4, 0.9, size=(60, 80))  # SfM units
    d2 = d1 * r  # metres
    d1 = d1.copy()
    d2 = d2.copy()
    d1[:5] = 0.0  # invalid in A
    d2[:, :4] = 0.0  # invalid in B
    n = int(outliers * d1.size)
    idx = rng.choice(d1.size, n, replace=False)
    d2.flat[idx[: n // 2]] *= 50.0  # far outliers (beyond the 90th percentile)
    d2.flat[idx[n // 2:]] *= 0.01  # near outliers (below the 10th percentile)
    return d1, d2


def test_valid_mask_keeps_the_middle_deciles():
    d = np.arange(0, 101, dtype=float).reshape(1, -1)  # 0 invalid, 1..100
    m = scale.valid_mask(d, 10, 90)
    kept = d[m]
    assert not m[0, 0]
    assert kept.min() == pytest.approx(np.percentile(np.arange(1, 101), 10), abs=1.0)
    assert kept.max() <= 91 and kept.min() >= 10
    assert np.isnan(d).sum() == 0
    assert not scale.valid_mask(np.zeros((3, 3))).any()


def test_eq5_recovers_a_known_ratio_despite_outliers():
    d1, d2 = maps(0.37, 0)
    out = scale.shot_ratio(d1, d2, 10, 90)
    assert out["r"] == pytest.approx(0.37, rel=1e-9)
    assert out["median"] == pytest.approx(0.37, rel=1e-9)
    assert 0.5 * d1.size < out["n"] < 0.8 * d1.size
    # without the percentile window the outliers would spoil the mean
    raw = d2[(d1 > 0) & (d2 > 0)] / d1[(d1 > 0) & (d2 > 0)]
    assert abs(raw.mean() / 0.37 - 1) > 0.1


def test_combine_mean_median_and_spread():
    ratios = {"a": {"r": 1.0, "median": 1.0, "n": 10}, "b": {"r": 1.1, "median": 1.05, "n": 9},
              "c": {"r": 2.0, "median": 1.9, "n": 8}}
    out = scale.combine(ratios)
    assert out["r"] == pytest.approx(4.1 / 3)
    assert out["r_median"] == pytest.approx(1.1)
    assert out["r_median_of_ratios"] == pytest.approx(1.05)
    assert out["spread"]["min"] == 1.0 and out["spread"]["max"] == 2.0
    assert out["spread"]["std"] == pytest.approx(np.std([1.0, 1.1, 2.0], ddof=1))
    assert out["spread"]["relative"] == pytest.approx(1.0 / (4.1 / 3))
    assert out["n_pixels"] == {"a": 10, "b": 9, "c": 8}


def test_files_and_errors(tmp_path):
    pairs = {}
    for i, cam in enumerate(["x00_y00", "x01_y00"]):
        d1, d2 = maps(0.5, i)
        np.save(tmp_path / f"{cam}_a.npy", d1.astype(np.float32))
        np.save(tmp_path / f"{cam}_b.npy", d2.astype(np.float32))
        pairs[cam] = (tmp_path / f"{cam}_a.npy", tmp_path / f"{cam}_b.npy")
    lines = []
    out = scale.scale_from_files(pairs, 10, 90, log=lines.append)
    assert out["r"] == pytest.approx(0.5, rel=1e-6)
    assert set(out["r_i"]) == {"x00_y00", "x01_y00"} and len(lines) == 2
    with pytest.raises(ValueError, match="differ in size"):
        scale.shot_ratio(np.ones((3, 3)), np.ones((3, 4)), name="x")
    with pytest.raises(ValueError, match="no pixel is valid"):
        scale.shot_ratio(np.ones((3, 3)), np.zeros((3, 3)), name="x")
    with pytest.raises(FileNotFoundError, match="depth rule"):
        scale.load_depth(tmp_path / "missing.npy")


def test_estimate_scale_is_the_typed_record_of_eq5(tmp_path):
    from plenocal.artifacts.scale import ScaleResult

    rng = np.random.default_rng(5)
    pairs = {}
    for i, r in enumerate((0.02, 0.021, 0.019)):
        d1 = rng.uniform(20.0, 40.0, (30, 40))
        np.save(tmp_path / f"a{i}.npy", d1)
        np.save(tmp_path / f"b{i}.npy", d1 * r)
        pairs[f"x{i:02d}_y00"] = (tmp_path / f"a{i}.npy", tmp_path / f"b{i}.npy")
    res = scale.estimate_scale(pairs, 10, 90, estimator="median")
    assert isinstance(res, ScaleResult)
    assert res.r == pytest.approx(0.02) and res.r_median == pytest.approx(0.02)
    assert res.r_used == res.r_median and res.percentiles == (10, 90)
    assert sorted(res.r_i) == sorted(pairs)
