"""The joint refinement's tracks from registration A's central views
(plenocal.calib.central_tracks, refine.tracks: central): the renamed database, the points
carried into the other views against hand-computed projections, the alignment that drops a
projection it cannot confirm, and the refinement on them against the truth."""

import sqlite3

import cv2
import numpy as np
import pytest
from test_refine import SHOTS, F, H, W, capture, eq6_of, settings  # noqa: F401

from plenocal.calib import central_tracks as ct
from plenocal.calib import refine as rf
from plenocal.calib.reg_a.sfm import features_a, match_a
from plenocal.calib.track_alignment import AlignSettings
from plenocal.camera import PinholeCamera, pose
from plenocal.verify.gt_errors import complete_errors

K = np.array([[F, 0.0, (W - 1) / 2], [0.0, F, (H - 1) / 2], [0.0, 0.0, 1.0]])


def _cam(x: float) -> PinholeCamera:
    """A camera at (x, 0, 0) looking along +z (internal convention)."""
    return PinholeCamera(K, pose(np.eye(3), np.array([x, 0.0, 0.0])), W, H)


def test_registration_as_database_is_copied_with_its_images_named_as_views(tmp_path):
    src, dst = tmp_path / "a.db", tmp_path / "b.db"
    with sqlite3.connect(src) as db:
        db.execute("CREATE TABLE images (image_id INTEGER, name TEXT)")
        db.executemany("INSERT INTO images VALUES (?, ?)", [(1, "x00_y00.png"),
                                                              (2, "hand00.png")])
    db.close()
    before = src.read_bytes()
    assert ct.rename_central_images(src, dst, "2_2") == 2
    got = sqlite3.connect(dst).execute("SELECT image_id, name FROM images").fetchall()
    assert got == [(1, "x00_y00/2_2.png"), (2, "hand00/2_2.png")]
    assert src.read_bytes() == before
    # a view database's names are not registration A's
    with pytest.raises(ValueError, match="not a database of the central views"):
        ct.rename_central_images(dst, tmp_path / "c.db", "2_2")
    with pytest.raises(FileNotFoundError, match="rule match_central"):
        ct.rename_central_images(tmp_path / "none.db", tmp_path / "d.db", "2_2")


def test_a_point_is_carried_into_every_view_of_the_shots_that_see_it():
    # two shots of three views each (0_0, 1_1 central, 2_2), 10 mm apart within a shot;
    # the point 2 m ahead of the first shot's central view
    cams = {}
    for shot, x0 in (("x00_y00", 0.0), ("x01_y00", 0.1), ("x02_y00", 0.2)):
        for view, dx in (("0_0", -0.01), ("1_1", 0.0), ("2_2", 0.01)):
            cams[f"{shot}/{view}"] = _cam(x0 + dx)
    X = np.array([0.0, 0.0, 2.0])
    # central views' SIFT keypoints (COLMAP's convention: +0.5), A's image ids 7 and 9
    c = np.array([(W - 1) / 2 + 0.5, (H - 1) / 2 + 0.5])
    names = {7: "x00_y00/1_1.png", 9: "x01_y00/1_1.png"}
    keypoints = {"x00_y00/1_1.png": np.array([[5.0, 5.0], c]),
                 "x01_y00/1_1.png": np.array([c - [F * 0.1 / 2.0, 0.0]])}
    points = {4: (X, [(7, 1), (9, 0)])}
    ts, lead = ct.extend_to_views(names, keypoints, points, cams, margin_px=7.0)
    keys = sorted(cams)
    assert ts.names == {i + 1: f"{k}.png" for i, k in enumerate(keys)}
    assert lead == {f"{k}.png": {"x00_y00/1_1": 2, "x01_y00/1_1": 1}.get(k, 0) for k in keys}
    X_, track = ts.points[4]
    assert np.array_equal(X_, X)
    # the shot x02_y00 does not see it: no view of it carries the point
    seen = sorted(ts.names[i][:-4] for i, _ in track)
    assert seen == [f"{s}/{v}" for s in ("x00_y00", "x01_y00") for v in ("0_0", "1_1", "2_2")]
    id_of = {v[:-4]: i for i, v in ts.names.items()}
    for key in seen:
        j = dict(track)[id_of[key]]
        uv = ts.keypoints[f"{key}.png"][j]
        if key.endswith("1_1"):  # SIFT's keypoint, kept where it was
            assert np.array_equal(uv, keypoints[f"{key}.png"][j])
        else:  # by hand: u = cx + F (X - x_cam) / Z, +0.5
            x_cam = cams[key].cam_to_world[0, 3]
            assert np.allclose(uv, [(W - 1) / 2 + F * (0.0 - x_cam) / 2.0 + 0.5,
                                    (H - 1) / 2 + 0.5], atol=1e-9)
    # a point that leaves a view (within the margin of its edge) is not carried into it
    far = np.array([-(W / 2 - 8.0) * 2.0 / F, 0.0, 2.0])  # 8 px inside x00_y00/1_1 left edge
    ts2, _ = ct.extend_to_views({7: "x00_y00/1_1.png"},
                                {"x00_y00/1_1.png": np.array([[8.5, c[1]]])},
                                {1: (far, [(7, 0)])}, cams, margin_px=7.0)
    carried = sorted(ts2.names[i][:-4] for i, _ in ts2.points[1][1])
    assert carried == ["x00_y00/0_0", "x00_y00/1_1"]  # in 2_2 it falls 5.9 px from the edge


def test_carry_every_takes_each_point_into_its_share_of_the_views():
    """refine.carry_every 2 on one shot of five views (central 2_2): point rows 0 and 1 (of
    ids 3 and 8) go into the other views 0_0, 1_1, 3_3, 4_4 (j = 0..3) where (j + row) is
    even: row 0 into j 0 and 2 (0_0, 3_3), row 1 into j 1 and 3 (1_1, 4_4)."""
    views = ("0_0", "1_1", "2_2", "3_3", "4_4")
    cams = {f"x00_y00/{v}": _cam(0.01 * (i - 2)) for i, v in enumerate(views)}
    c = np.array([(W - 1) / 2 + 0.5, (H - 1) / 2 + 0.5])
    names = {1: "x00_y00/2_2.png"}
    keypoints = {"x00_y00/2_2.png": np.array([c, c + [3.0, 0.0]])}
    X = np.array([0.0, 0.0, 2.0])
    points = {3: (X, [(1, 0)]), 8: (X + [3.0 * 2.0 / F, 0.0, 0.0], [(1, 1)])}
    full, _ = ct.extend_to_views(names, keypoints, points, cams, margin_px=7.0)
    half, _ = ct.extend_to_views(names, keypoints, points, cams, margin_px=7.0, stride=2)

    def carried(ts, pid):
        return sorted(ts.names[i][:-4].split("/")[1] for i, _ in ts.points[pid][1])

    assert carried(full, 3) == carried(full, 8) == list(views)
    assert carried(half, 3) == ["0_0", "2_2", "3_3"]
    assert carried(half, 8) == ["1_1", "2_2", "4_4"]
    # each carried observation is the same pixel as with every view
    for pid in (3, 8):
        for i, j in half.points[pid][1]:
            name = half.names[i]
            k = dict(full.points[pid][1])[i]
            assert np.array_equal(half.keypoints[name][j], full.keypoints[name][k])
    assert ct.strided(np.arange(6), 1, 3).tolist() == [False, False, True, False, False, True]
    with pytest.raises(ValueError, match="carry_every"):
        ct.strided(np.arange(3), 0, 0)
    with pytest.raises(ValueError, match="refine.carry_every"):
        rf.RefineSettings(carry_every=0)


def test_a_projection_the_alignment_cannot_confirm_is_dropped_and_sift_kept():
    """Three views of one shot (the same image, as a shot's views nearly are): SIFT's
    keypoint in the central view is the reference; a projection 0.4 px off is moved onto
    the content, one 3 px off (past max_shift_px) is dropped, and a point left with fewer
    than three observations goes."""
    rng = np.random.default_rng(0)
    img = cv2.GaussianBlur((rng.random((H, W)) * 255).astype(np.float32), (0, 0), 1.5)
    img = cv2.normalize(img, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    cams = {f"x00_y00/{v}": _cam(0.0) for v in ("0_0", "1_1", "2_2")}
    names = {1: "x00_y00/0_0.png", 2: "x00_y00/1_1.png", 3: "x00_y00/2_2.png"}
    ref = np.array([150.5, 120.5])
    X = np.array([(ref[0] - 0.5 - K[0, 2]) * 2.0 / F, (ref[1] - 0.5 - K[1, 2]) * 2.0 / F, 2.0])
    ts = ct.TrackSet(names, {"x00_y00/0_0.png": np.array([ref + [0.4, -0.3], ref + [3.0, 0.0]]),
                             "x00_y00/1_1.png": np.array([ref, ref]),
                             "x00_y00/2_2.png": np.array([ref + [3.0, 0.0], ref + [-0.2, 0.1]])},
                     {1: (X, [(1, 0), (2, 0), (3, 1)]), 2: (X, [(1, 1), (2, 1), (3, 0)])}, 2)
    lead = {"x00_y00/0_0.png": 0, "x00_y00/1_1.png": 2, "x00_y00/2_2.png": 0}
    out, stats = ct.aligned_track_set(ts, lead, cams, lambda key: img, AlignSettings(), 1)
    assert stats["projected"] == 4 and stats["dropped"] == 2
    assert sorted(out.points) == [1]  # point 2 kept only its SIFT keypoint and one more
    assert out.points[1][1] == [(1, 0), (2, 0), (3, 1)]
    for name, j in (("x00_y00/0_0.png", 0), ("x00_y00/2_2.png", 1)):
        assert np.allclose(out.keypoints[name][j], ref, atol=0.05), name
    assert np.array_equal(out.keypoints["x00_y00/1_1.png"], ts.keypoints["x00_y00/1_1.png"])


def test_two_track_sets_join_by_image_name_with_their_indices_moved():
    """refine.tracks both: the images matched by name, b's keypoints after a's, b's points
    after a's with their keypoint indices moved past a's (hand-built sets)."""
    a = ct.TrackSet({1: "s/0_0.png", 2: "s/1_1.png"},
                    {"s/0_0.png": np.array([[1.0, 2.0]]),
                     "s/1_1.png": np.array([[3.0, 4.0], [5.0, 6.0]])},
                    {7: (np.array([0.0, 0.0, 1.0]), [(1, 0), (2, 1)])}, 9)
    # b numbers its images otherwise, and has one a lacks
    b = ct.TrackSet({1: "s/1_1.png", 2: "s/2_2.png", 3: "s/0_0.png"},
                    {"s/1_1.png": np.array([[7.0, 8.0]]), "s/2_2.png": np.array([[9.0, 9.0]]),
                     "s/0_0.png": np.array([[0.5, 0.5], [1.5, 1.5]])},
                    {2: (np.array([1.0, 0.0, 2.0]), [(1, 0), (2, 0), (3, 1)])}, 4)
    j = ct.joined(a, b)
    assert j.names == {1: "s/0_0.png", 2: "s/1_1.png", 3: "s/2_2.png"}
    np.testing.assert_array_equal(j.keypoints["s/1_1.png"], [[3, 4], [5, 6], [7, 8]])
    np.testing.assert_array_equal(j.keypoints["s/0_0.png"], [[1, 2], [0.5, 0.5], [1.5, 1.5]])
    np.testing.assert_array_equal(j.keypoints["s/2_2.png"], [[9, 9]])
    assert sorted(j.points) == [7, 8]
    assert j.points[7][1] == [(1, 0), (2, 1)]
    # b's point: s/1_1 keypoint 0 -> 2, s/2_2 (new id 3) 0 -> 0, s/0_0 keypoint 1 -> 2
    assert j.points[8][1] == [(2, 2), (3, 0), (1, 2)]
    for pid, (X, elements) in j.points.items():
        src = a if pid == 7 else b
        np.testing.assert_array_equal(X, next(iter(src.points.values()))[0])
        for i, k in elements:
            assert k < len(j.keypoints[j.names[i]])
    assert j.triangulated == 13
    # the sets given are left as they were
    assert len(a.keypoints["s/1_1.png"]) == 2 and sorted(a.points) == [7]


@pytest.fixture(scope="module")
def database_a(capture, tmp_path_factory):  # noqa: F811
    """Registration A's database of the capture's central views, as rules features_a and
    match_a make it."""
    views, _, db = capture
    root = tmp_path_factory.mktemp("reg_a")
    central = {shot: db.parent / f"{shot}/1_1.png" for shot in SHOTS}
    features_a(central, root / "images", root / "features.db", max_num_features=1500)
    (root / "database.db").write_bytes((root / "features.db").read_bytes())
    match_a(root / "database.db")
    return root / "database.db"


@pytest.fixture(scope="module")
def central_refinement(capture, database_a):  # noqa: F811
    """(Eq. 6 of the capture, its views' image files, the refinement on the central
    views' tracks), shared by the tests that read it."""
    views, rig, db = capture
    images = {name: db.parent / f"{name}.png" for name in views}
    eq6 = eq6_of(views, rig)
    out = rf.refine_calibration(eq6, rig, database_a, settings(tracks="central"),
                                hold_shot="x00_y00", images=images)
    return eq6, images, out


def _assert_towards_the_truth(out: rf.Refinement, eq6: dict, views: dict) -> None:
    """Every view kept, the refinement kept, the centres at least twice as near the truth
    as Eq. 6's, the largest rotation nearer, the focal length within 0.3 %."""
    before = complete_errors(eq6, views)
    assert sorted(out.cameras) == sorted(eq6)
    assert not out.report["rejected"], out.report.get("warnings")
    after = complete_errors(out.cameras, views)
    assert after["centre_rmse_mm"] < 0.5 * before["centre_rmse_mm"]
    assert after["rotation_err_deg"]["max"] < before["rotation_err_deg"]["max"]
    assert abs(after["focal_err_signed_pct"]) < 0.3


def test_the_refinement_on_the_central_views_tracks_moves_the_shots_towards_the_truth(
        capture, database_a, central_refinement):  # noqa: F811
    views, rig, _ = capture
    eq6, _, out = central_refinement
    _assert_towards_the_truth(out, eq6, views)
    align = out.report["alignment"]
    assert align["projected"] > 0 and 0 <= align["dropped"] < align["projected"]
    # every view of every shot carries observations: the points reached the other views
    assert out.report["points"]["used"] >= 100
    with pytest.raises(ValueError, match="images are needed"):
        rf.refine_calibration(eq6, rig, database_a, settings(tracks="central"),
                              hold_shot="x00_y00")


def test_both_track_sets_adjust_the_central_and_the_views_points_together(
        capture, database_a, central_refinement):  # noqa: F811
    views, rig, db = capture
    eq6, images, central = central_refinement
    both = rf.refine_calibration(eq6, rig, database_a, settings(tracks="both"),
                                 hold_shot="x00_y00", images=images, view_database=db)
    _assert_towards_the_truth(both, eq6, views)
    # the views' points come on top of the central ones, each set's alignment reported
    assert both.report["points"]["used"] > central.report["points"]["used"]
    align = both.report["alignment"]
    assert align["central"]["projected"] > 0 and align["views"]["enabled"]
    with pytest.raises(ValueError, match="view database"):
        rf.refine_calibration(eq6, rig, database_a, settings(tracks="both"),
                              hold_shot="x00_y00", images=images)


def test_the_central_tracks_are_the_same_bytes_on_one_and_two_threads(capture, database_a):  # noqa: F811
    views, rig, db = capture
    images = {name: db.parent / f"{name}.png" for name in views}
    eq6 = eq6_of(views, rig)
    runs = [rf.refine_calibration(eq6, rig, database_a, settings(tracks="central",
                                                                 num_threads=n),
                                  hold_shot="x00_y00", images=images) for n in (1, 2)]
    for key, cam in runs[0].cameras.items():
        assert cam.cam_to_world.tobytes() == runs[1].cameras[key].cam_to_world.tobytes()
        assert cam.K.tobytes() == runs[1].cameras[key].K.tobytes()
    assert runs[0].report["alignment"] == runs[1].report["alignment"]

