"""The view database in two steps (rules view_features and view_matches): SIFT without
any calibration, then the matching of the pairs that follow registration A - the same
database, byte for byte, as SIFT and matching in one go."""

import os

import cv2  # noqa: F401  (before pycolmap)
import numpy as np
import pytest
from synth.scenes import default_scene, render, rig_cameras, view_sets

from plenocal.calib.reg_a import viewdb
from plenocal.io.files import write_image


@pytest.fixture(scope="module")
def views(tmp_path_factory):
    root = tmp_path_factory.mktemp("viewdb")
    shots = rig_cameras(f=300.0, width=240, height=180, cols=2, rows=1, handheld=1)
    sets = view_sets(shots, 3, 0.003)
    scene = default_scene()
    paths = {}
    for name, cam in sets.items():
        paths[name] = root / f"{name}.png"
        write_image(paths[name], render(cam, scene, ss=1))
    centres = {k: c.cam_to_world[:3, 3] for k, c in shots.items()}
    return paths, centres


def test_two_steps_give_the_one_step_database(views, tmp_path):
    paths, centres = views
    one = tmp_path / "one.db"
    info = viewdb.build_view_database(paths, one, tmp_path / "w1", shot_centres=centres,
                                      shot_neighbours=1, max_num_features=1000)
    feats = tmp_path / "features.db"
    finfo = viewdb.extract_view_features(paths, feats, tmp_path / "w2", max_num_features=1000)
    os.utime(feats, ns=(10**18, 10**18))
    two = tmp_path / "two.db"
    minfo = viewdb.match_view_database(feats, two, shot_centres=centres, shot_neighbours=1,
                                       work_dir=tmp_path)
    assert one.read_bytes() == two.read_bytes()
    # the features are an input of the matching rule: left untouched
    assert feats.stat().st_mtime_ns == 10**18
    assert viewdb.database_names(feats) == viewdb.database_names(two) == sorted(paths)
    assert finfo["num_images"] == minfo["num_images"] == info["num_images"] == 27
    # 3 shots of 3 x 3 views: 20 neighbouring pairs each; each shot linked to its nearest
    assert minfo["num_pairs"] == info["num_pairs"] == 3 * 20 + 2 * 9
    assert minfo["num_verified_pairs"] == info["num_verified_pairs"] > 3 * 20
    assert finfo["keypoints_mean"] == info["keypoints_mean"] > 100


def test_first_octave_reaches_sift(views, tmp_path):
    """first_octave 0 starts SIFT at the image's own resolution (COLMAP's -1 doubles it
    first): fewer keypoints, none finer than the image's own scale."""
    paths, _ = views
    some = dict(sorted(paths.items())[:2])
    fine = viewdb.extract_view_features(some, tmp_path / "a.db", tmp_path / "a")
    coarse = viewdb.extract_view_features(some, tmp_path / "b.db", tmp_path / "b",
                                          first_octave=0)
    assert fine["first_octave"] == -1 and coarse["first_octave"] == 0
    assert 0 < coarse["keypoints_mean"] < 0.8 * fine["keypoints_mean"]
    assert np.isfinite(coarse["features_s"])


def _dump(db):
    """Every row of every table, in a fixed order."""
    import sqlite3

    con = sqlite3.connect(db)
    try:
        tables = [r[0] for r in con.execute(
            "SELECT name FROM sqlite_master WHERE type='table' ORDER BY name")]
        return {t: sorted(con.execute(f"SELECT * FROM {t}").fetchall()) for t in tables}
    finally:
        con.close()


def test_features_per_shot_merge_into_one_extraction(views, tmp_path):
    """SIFT per shot (28 small jobs instead of one long one) merged: the same rows in
    every table as one extraction of all views; the parts stay untouched."""
    paths, _ = views
    one = tmp_path / "one.db"
    viewdb.extract_view_features(paths, one, tmp_path / "w", max_num_features=1000)
    parts = []
    for shot in sorted({n.split("/")[0] for n in paths}):
        parts.append(tmp_path / f"{shot}.db")
        viewdb.extract_view_features({k: v for k, v in paths.items() if k.startswith(shot)},
                                     parts[-1], tmp_path / shot, max_num_features=1000)
        os.utime(parts[-1], ns=(10**18, 10**18))
    merged = tmp_path / "merged.db"
    info = viewdb.merge_view_features(reversed(parts), merged)
    assert info["num_images"] == len(paths)
    assert _dump(merged) == _dump(one)
    assert all(p.stat().st_mtime_ns == 10**18 for p in parts)
    with pytest.raises(ValueError, match="more than one"):
        viewdb.merge_view_features([parts[0], parts[0]], tmp_path / "twice.db")
