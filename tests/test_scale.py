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
    assert not m[0, 0]
    # percentiles of 1..100 by linear interpolation: 1 + 0.1 * 99 = 10.9 and 90.1
    np.testing.assert_array_equal(d[m], np.arange(11, 91))
    # NaN, infinite and negative depths are invalid and leave the window where it was
    bad = np.concatenate([d, [[np.nan, np.inf, -np.inf, -5.0]]], axis=1)
    m = scale.valid_mask(bad, 10, 90)
    np.testing.assert_array_equal(bad[m], np.arange(11, 91))
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


def _lattice(step_sfm: float, cols: int, rows: int, seed: int = 0, noise: float = 0.0):
    """Array shots' camera-to-world poses on a turned, shifted lattice (SfM units)."""
    import cv2  # noqa: PLC0415

    rng = np.random.default_rng(seed)
    R = cv2.Rodrigues(np.array([0.1, -0.3, 0.2]))[0]
    o = np.array([0.3, -0.2, 1.5])
    out = {}
    for c in range(cols):
        for r in range(rows):
            M = np.eye(4)
            M[:3, 3] = o + step_sfm * (R @ np.array([c, r, 0.0])) + rng.normal(0, noise, 3)
            out[f"x{c:02d}_y{r:02d}"] = M
    return out


def test_the_stage_step_over_a_lattice_gives_the_scale_exactly():
    poses = _lattice(0.37, 7, 3)
    poses["hand00"] = np.eye(4)  # hand-held shots are not on the lattice: skipped
    out = scale.array_step_scale(poses, 0.01)
    assert out["r"] == pytest.approx(0.01 / 0.37, rel=1e-12)
    assert out["n_shots"] == 21 and out["fit_rms_pct_of_step"] < 1e-9
    # one row only: its axis alone
    row = {k: v for k, v in poses.items() if k.endswith("_y00")}
    assert scale.array_step_scale(row, 0.01)["r"] == pytest.approx(0.01 / 0.37, rel=1e-12)
    assert scale.array_step_scale({"x00_y00": np.eye(4)}, 0.01) is None
    # noisy positions: near, and the fit's residual says how far from a lattice
    noisy = scale.array_step_scale(_lattice(0.37, 7, 3, noise=0.003), 0.01)
    assert noisy["r"] == pytest.approx(0.01 / 0.37, rel=5e-3)
    assert 0.1 < noisy["fit_rms_pct_of_step"] < 3.0


def test_the_merge_takes_the_step_where_it_is_known_and_warns_where_they_disagree(tmp_path):
    d1, d2 = maps(0.02, 3)
    a, b = tmp_path / "a.npy", tmp_path / "b.npy"
    np.save(a, d1)
    np.save(b, d2)
    pairs = {"x00_y00": (a, b)}
    poses = _lattice(0.5, 3, 2)
    auto = scale.estimate_scale(pairs, reference="auto", array_poses=poses, step_m=0.0101)
    assert auto.chosen == "array_step" and auto.r_used == pytest.approx(0.0202)
    assert auto.r_eq5 == pytest.approx(0.02, rel=1e-3) and auto.warnings == ()
    off = scale.estimate_scale(pairs, reference="auto", array_poses=poses, step_m=0.011)
    assert len(off.warnings) == 1 and "+10.00 %" in off.warnings[0]
    assert scale.estimate_scale(pairs, reference="eq5", array_poses=poses,
                                step_m=0.011).r_used == pytest.approx(0.02, rel=1e-3)
    none = scale.estimate_scale(pairs, reference="auto")
    assert none.chosen == "eq5" and none.r_array_step is None
    with pytest.raises(ValueError, match="array.step_mm"):
        scale.estimate_scale(pairs, reference="array_step")
    # and the file keeps all of it
    from plenocal.artifacts.scale import read_scale, write_scale  # noqa: PLC0415

    write_scale(tmp_path / "scale.json", off)
    back = read_scale(tmp_path / "scale.json")
    assert back.r_used == pytest.approx(off.r_used, rel=1e-9) and back.warnings == off.warnings
    assert back.array_step["spacing_sfm"] == pytest.approx(0.5)
