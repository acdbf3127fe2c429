"""bench/bench_view_sources.py's two measures, against hand-computed cases: the truth's
patch size of a lens (its disparity between two true cameras) and the softness fitted
between a view and an ideal render."""

import sys
from pathlib import Path
from types import SimpleNamespace

import cv2
import numpy as np

from plenocal.camera import PinholeCamera

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
import bench_view_sources as bvs  # noqa: E402


def _camera(centre_x: float) -> PinholeCamera:
    K = np.array([[1000.0, 0.0, 100.0], [0.0, 1000.0, 80.0], [0.0, 0.0, 1.0]])
    M = np.eye(4)
    M[0, 3] = centre_x  # camera-to-world: looking along +z, shifted along x
    return PinholeCamera(K, M, 200, 160)


def test_oracle_patch_by_hand():
    # a point at z = 1 m under tile centre (120, 90): X = 0.02 m; the camera 1 cm to its
    # right sees it at x = 1000 (0.02 - 0.01) / 1 + 100 = 110, so D = 120 - 110 = 10 px and
    # P = s q T / D = (+1)(2)(8) / 10 = 1.6 px; a tile over no surface has no patch size
    layout = SimpleNamespace(tile_centres=np.array([[120.0, 90.0], [40.0, 20.0]]),
                             width=200, height=160, sign=1.0, q=2.0, tile=8)
    depth = np.zeros((160, 200), np.float32)
    depth[90, 120] = 1.0
    patch = bvs.oracle_patch(layout, depth, _camera(0.0), _camera(0.01))
    assert np.isclose(patch[0], 1.6, rtol=1e-9)
    assert np.isnan(patch[1])
    # the same point twice as far: half the disparity, twice the patch size
    depth[90, 110] = 2.0
    layout.tile_centres[0] = (110.0, 90.0)  # X = 0.02 m again, at z = 2 m: D = 5 px
    assert np.isclose(bvs.oracle_patch(layout, depth, _camera(0.0), _camera(0.01))[0], 3.2)


def test_fitted_softness_recovers_blur_gain_and_noise():
    rng = np.random.default_rng(7)
    ideal = np.full((240, 320), 120.0, np.float32)  # a flat half and a textured half
    ideal[:, 160:] = cv2.GaussianBlur(rng.uniform(0, 255, (240, 160)).astype(np.float32),
                                      (0, 0), 1.5)
    view = 0.8 * cv2.GaussianBlur(ideal, (0, 0), 1.2) + 10.0
    view += rng.normal(0.0, 0.5, view.shape).astype(np.float32)
    sigma, noise = bvs.fitted_softness(view, ideal)
    assert abs(sigma - 1.2) <= 0.05
    assert abs(noise - 0.5) <= 0.1
    # an unblurred, noise-free copy reads as such
    sigma, noise = bvs.fitted_softness(0.8 * ideal + 10.0, ideal)
    assert sigma == 0.0 and noise < 1e-3


def test_view_rules_run_the_central_tracks_again(tmp_path):
    # two SIFT jobs in the kept capture; the central tracks read the views through rule
    # match_central and rule refine (the bench keeps the replaced views' file times, so
    # only the rules named here run again): without them every kind reads as our views
    bench = tmp_path / "results" / bvs.DATASET / "benchmarks" / "view_features"
    bench.mkdir(parents=True)
    for k in range(2):
        (bench / f"part{k}.tsv").write_text("s\n1\n")
    sift = ["view_features_0", "view_features_1"]
    assert bvs.view_rules(tmp_path, {"refine": {"tracks": "central"}}) == [
        *sift, "match_central", "refine"]
    assert bvs.view_rules(tmp_path, {"refine": {"tracks": "both"}}) == [
        *sift, "match_central", "refine"]
    assert bvs.view_rules(tmp_path, {"refine": {"tracks": "views"}}) == sift
