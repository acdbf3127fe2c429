"""The joint refinement of every view under the rig (plenocal.calib.refine, issue 32), on
synthetic renders whose true cameras are known exactly: 2 x 2 array shots and two
hand-held shots, each a 3 x 3 set of parallel views 3 mm apart (tests/synth/scenes.py)."""

import cv2  # noqa: F401  (before pycolmap)
import numpy as np
import pytest
from synth.scenes import default_scene, render, rig_cameras, view_sets

from plenocal.artifacts.rig import RigB
from plenocal.calib import refine as rf
from plenocal.calib import rig_model as rm
from plenocal.calib import track_sets as tsets
from plenocal.calib.reg_a import viewdb
from plenocal.calib.scale import array_step_scale
from plenocal.camera import PinholeCamera, invert_pose, pose
from plenocal.io.files import write_image
from plenocal.verify.gt_errors import complete_errors

F, W, H = 420.0, 320, 240
SHOTS = ("x00_y00", "x01_y00", "x00_y01", "x01_y01", "hand00", "hand01")
BASELINE = 0.003


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    """(true views, the rig of their sets, the view database of their matches)."""
    root = tmp_path_factory.mktemp("refine")
    shots = rig_cameras(f=F, width=W, height=H, cols=2, rows=2, handheld=2)
    shots = {k: shots[k] for k in SHOTS}
    views = view_sets(shots, 3, BASELINE)
    scene = default_scene()
    paths = {}
    for name, cam in views.items():
        paths[name] = root / f"{name}.png"
        write_image(paths[name], render(cam, scene))
    db = root / "views.db"
    viewdb.build_view_database(paths, db, root, max_num_features=1500)
    return views, rig_of(views, "x00_y00"), db


def rig_of(views: dict[str, PinholeCamera], shot: str, baseline_scale: float = 1.0) -> RigB:
    """The true rig (every view relative to the central one), its baselines scaled."""
    central = views[f"{shot}/1_1"].cam_to_world
    doc = {"model": "exact", "n_views": 3, "width": W, "height": H, "focal_px": F,
           "views": {}}
    for name, cam in views.items():
        if name.startswith(shot + "/"):
            M = invert_pose(central) @ cam.cam_to_world
            M[:3, 3] *= baseline_scale
            doc["views"][name.split("/")[1]] = {"K": cam.K, "cam_to_central": M}
    return RigB(doc)


def _rot(axis, deg):
    return cv2.Rodrigues(np.asarray(axis, float) / np.linalg.norm(axis) * np.radians(deg))[0]


def eq6_of(views: dict[str, PinholeCamera], rig: RigB, seed: int = 1) -> dict[str, PinholeCamera]:
    """Eq. 6 with every shot's pose off its truth (1 mm, 0.1 deg), the shots' centres
    spread as the truth's (Eq. 5's scale right), the rig as given."""
    rng = np.random.default_rng(seed)
    true = {shot: views[f"{shot}/1_1"].cam_to_world for shot in SHOTS}
    moved = {shot: pose(_rot(rng.normal(size=3), 0.1) @ M[:3, :3],
                        M[:3, 3] + rng.normal(size=3) * 0.001 / np.sqrt(3))
             for shot, M in true.items()}
    spread = rm.spread({s: M[:3, 3] for s, M in true.items()})
    c = np.mean([M[:3, 3] for M in moved.values()], axis=0)
    k = spread / rm.spread({s: M[:3, 3] for s, M in moved.items()})
    out = {}
    for shot, M in moved.items():
        M[:3, 3] = c + k * (M[:3, 3] - c)
        for view, (K, B) in rig.view_poses().items():
            out[f"{shot}/{view}"] = PinholeCamera(K, M @ B, W, H)
    return out


def shot_moved(cams: dict[str, PinholeCamera], rig: RigB, shot: str, dx_m: float,
               turn_deg: float = 0.0) -> dict[str, PinholeCamera]:
    """``cams`` with every view of ``shot`` moved ``dx_m`` along x and turned ``turn_deg``
    about y, as a whole (its rig kept)."""
    out = dict(cams)
    for view in rig.view_poses():
        c = cams[f"{shot}/{view}"]
        M = c.cam_to_world.copy()
        M[:3, :3] = _rot([0, 1, 0], turn_deg) @ M[:3, :3]
        M[0, 3] += dx_m
        out[f"{shot}/{view}"] = PinholeCamera(c.K, M, W, H)
    return out


def settings(**kw) -> rf.RefineSettings:
    """The refinement on the view database's matches (refine.tracks: views) unless ``kw``
    says otherwise (tests/test_central_tracks.py: central)."""
    return rf.RefineSettings(**{"max_points": 4000, "min_angle_deg": 0.1, "num_threads": 1,
                                "tracks": "views", **kw})


def test_refinement_moves_the_shots_towards_the_truth_and_keeps_every_view(capture):
    views, rig, db = capture
    eq6 = eq6_of(views, rig)
    before = complete_errors(eq6, views)
    for kw in ({"rig": "hold"}, {"rig": "scale"}, {"rig": "scale_pp"}):
        out = rf.refine_calibration(eq6, rig, db, settings(**kw), hold_shot="x00_y00")
        assert sorted(out.cameras) == sorted(eq6)
        after = complete_errors(out.cameras, views)
        assert after["centre_rmse_mm"] < 0.5 * before["centre_rmse_mm"], kw
        assert after["rotation_err_deg"]["max"] < before["rotation_err_deg"]["max"], kw
        obs = out.report["observations"]
        assert obs["after"]["mean_px"] < obs["before"]["mean_px"], kw


def test_a_rig_held_constant_keeps_its_sensor_poses_bit_for_bit(capture):
    views, rig, db = capture
    out = rf.refine_calibration(eq6_of(views, rig), rig, db,
                                settings(rig="hold"), hold_shot="x00_y00")
    assert sorted(out.sensors_before) == sorted(out.sensors_after)
    for cid, params in out.sensors_before.items():
        assert np.array_equal(params, out.sensors_after[cid])
    # and every shot's views keep the rig's relative poses
    c = out.cameras
    for shot in SHOTS:
        central = c[f"{shot}/1_1"].cam_to_world
        for view, (_, B) in rig.view_poses().items():
            rel = invert_pose(central) @ c[f"{shot}/{view}"].cam_to_world
            assert np.abs(rel - B).max() < 1e-9


def test_a_wrong_rig_is_pulled_back_towards_the_truth_when_refined(capture):
    views, rig, db = capture
    wrong = rig_of(views, "x00_y00", baseline_scale=1.05)
    eq6 = eq6_of(views, wrong)
    out = rf.refine_calibration(eq6, wrong, db, settings(rig="scale"),
                                hold_shot="x00_y00")
    refined = rm.rig_views_from_cameras(out.cameras, "x00_y00")
    true = rig.view_poses()

    def baseline_err(poses) -> float:
        return max(abs(np.linalg.norm(poses[v][:3, 3]) - np.linalg.norm(true[v][1][:3, 3]))
                   for v in true if v != "1_1")

    assert baseline_err({v: B for v, (_, B) in wrong.view_poses().items()}) > 1e-4
    assert baseline_err(refined) < 0.3 * baseline_err(
        {v: B for v, (_, B) in wrong.view_poses().items()})


def test_a_held_focal_length_is_registration_as_bit_for_bit(capture):
    """``focal: hold``: every view keeps Eq. 6's focal length (registration A's) to the
    bit, while the shots still move towards the truth."""
    views, rig, db = capture
    eq6 = eq6_of(views, rig)
    out = rf.refine_calibration(eq6, rig, db, settings(focal="hold"), hold_shot="x00_y00")
    assert sorted(out.cameras) == sorted(eq6)
    assert all(out.cameras[k].K[0, 0] == eq6[k].K[0, 0] and
               out.cameras[k].K[1, 1] == eq6[k].K[1, 1] for k in eq6)
    assert "focal" not in out.report["passes"]
    before, after = complete_errors(eq6, views), complete_errors(out.cameras, views)
    assert after["centre_rmse_mm"] < 0.5 * before["centre_rmse_mm"]


def test_held_frames_keep_every_shots_pose_as_eq6_gives_it(capture):
    """``frames: hold``: every shot's central view stays where Eq. 6 put it (only what
    refine.rig frees and the points move), and no view is lost."""
    views, rig, db = capture
    eq6 = eq6_of(views, rig)
    out = rf.refine_calibration(eq6, rig, db, settings(frames="hold", focal="hold"),
                                hold_shot="x00_y00")
    assert sorted(out.cameras) == sorted(eq6)
    for shot in SHOTS:
        moved = out.cameras[f"{shot}/1_1"].cam_to_world - eq6[f"{shot}/1_1"].cam_to_world
        assert np.abs(moved).max() < 1e-12, shot


def test_a_free_rig_moves_its_sensors_and_the_shots_towards_the_truth(capture):
    """``rig: free``: each sensor's pose is refined (they leave B's), every view is kept,
    and the shots' centres and turns come nearer the truth than Eq. 6's."""
    views, rig, db = capture
    eq6 = eq6_of(views, rig)
    out = rf.refine_calibration(eq6, rig, db, settings(rig="free"), hold_shot="x00_y00")
    assert sorted(out.cameras) == sorted(eq6)
    assert any(not np.array_equal(out.sensors_before[k], out.sensors_after[k])
               for k in out.sensors_before)
    before, after = complete_errors(eq6, views), complete_errors(out.cameras, views)
    assert after["centre_rmse_mm"] < 0.5 * before["centre_rmse_mm"]
    assert after["rotation_err_deg"]["max"] < 0.5 * before["rotation_err_deg"]["max"]


def test_settings_are_checked():
    with pytest.raises(ValueError, match="refine.rig"):
        rf.RefineSettings(rig="loose")
    with pytest.raises(ValueError, match="refine.focal"):
        rf.RefineSettings(focal="free")
    for bad in (0, -0.5, "median"):
        with pytest.raises(ValueError, match="refine.loss_scale_px"):
            rf.RefineSettings(loss_scale_px=bad)
    with pytest.raises(ValueError, match="refine.scale"):
        rf.RefineSettings(scale="eq5")


def test_the_stages_step_is_fitted_to_the_refined_array_shots(capture):
    """Eq. 6 spread 1 % wider than the truth (the merge's r off, as registration A's
    array shots' errors put it): refine.scale merge keeps that scale, auto gives the
    refined array shots the stage's step, and so nearly the truth's scale (the four
    refined shots' own errors: 0.17 % on this 2 x 2 array, 0.005 % median on the
    simulator's arrays)."""
    views, rig, db = capture
    centre = {s: views[f"{s}/1_1"].centre for s in SHOTS}
    step = float(np.linalg.norm(centre["x01_y00"] - centre["x00_y00"]))
    assert np.linalg.norm(centre["x00_y01"] - centre["x00_y00"]) == pytest.approx(step)
    eq6 = eq6_of(views, rig)
    mean = np.mean([c.centre for c in eq6.values()], axis=0)
    wide = {k: PinholeCamera(c.K, pose(c.R, mean + 1.01 * (c.centre - mean)), W, H)
            for k, c in eq6.items()}

    def step_of(cams) -> float:  # the lattice spacing of the array shots' central views
        fit = array_step_scale({s: cams[f"{s}/1_1"].cam_to_world for s in SHOTS}, 1.0)
        return fit["spacing_sfm"]

    # Eq. 6's shots 1 mm off and 1 % wide: a refinement moves them past the 2 % gate
    kw = {"max_shift_pct": 5.0}
    kept = rf.refine_calibration(wide, rig, db, settings(scale="merge", **kw),
                                 hold_shot="x00_y00")
    fitted = rf.refine_calibration(wide, rig, db, settings(scale="auto", **kw),
                                   hold_shot="x00_y00", step_m=step)
    assert not fitted.report["rejected"], fitted.report["warnings"]
    assert fitted.report["array_step_fit"]["n_shots"] == 4
    assert "fitted to the 4 refined array shots" in fitted.report["scale_source"]
    assert kept.report["array_step_fit"] is None
    assert step_of(fitted.cameras) == pytest.approx(step, rel=1e-9)
    scale_err = {name: abs(complete_errors(out.cameras, views)["residual_scale_err_pct"])
                 for name, out in (("merge", kept), ("auto", fitted))}
    assert scale_err["merge"] > 0.8, scale_err
    assert scale_err["auto"] < 0.3 * scale_err["merge"], scale_err
    # without a step (the merge took Eq. 5's r) auto is merge
    plain = rf.refine_calibration(wide, rig, db, settings(scale="auto", **kw),
                                  hold_shot="x00_y00")
    assert plain.report["array_step_fit"] is None
    assert all(np.array_equal(plain.cameras[k].cam_to_world, kept.cameras[k].cam_to_world)
               for k in kept.cameras)


def test_the_robust_loss_scale_follows_the_median_error_or_is_given():
    before = np.array([0.4, 0.1, 0.2, 3.0, 0.3])  # median 0.3 px
    assert rf.loss_scale_of(rf.RefineSettings(loss_scale_px="auto"), before) == pytest.approx(
        rf.AUTO_LOSS_SCALE * 0.3)
    assert rf.loss_scale_of(rf.RefineSettings(loss_scale_px=0.5), before) == 0.5
    with pytest.raises(ValueError, match="loss_scale_px"):
        rf.loss_scale_of(rf.RefineSettings(), np.zeros(0))


def test_a_wrong_focal_length_is_pulled_back_towards_the_truth(capture):
    """Registration A's focal length 1 % off (every view and the rig built with it): the
    focal pass on every view brings it back, and the shots with it."""
    views, rig, db = capture
    off = 1.01

    def scaled(K):
        K = np.array(K, dtype=float)
        K[0, 0] *= off
        K[1, 1] *= off
        return K

    doc = {**rig.doc, "focal_px": F * off,
           "views": {v: {"K": scaled(K), "cam_to_central": M}
                     for v, (K, M) in rig.view_poses().items()}}
    wrong = RigB(doc)
    eq6 = eq6_of(views, wrong)
    out = rf.refine_calibration(eq6, wrong, db, settings(), hold_shot="x00_y00")
    assert out.report["settings"]["focal"] == "refine"
    refined = out.report["focal_px"]["refined"]
    assert abs(refined / F - 1.0) < 0.25 * (off - 1.0), refined
    assert all(abs(c.K[0, 0] - refined) < 1e-9 for c in out.cameras.values())
    assert (complete_errors(out.cameras, views)["rotation_err_deg"]["max"]
            < complete_errors(eq6, views)["rotation_err_deg"]["max"])


def test_a_refinement_that_moves_a_shot_far_is_rejected(capture):
    views, rig, _ = capture
    eq6 = eq6_of(views, rig)
    moved = shot_moved(eq6, rig, "hand01", 0.005)  # one shot slid 5 mm sideways
    out = rf.shot_shifts(eq6, moved, list(SHOTS), "1_1", 2.0)
    assert out["rejected"] and "hand01" in out["warnings"][0]
    assert out["max_shift_mm"] > 3.0 and out["limit_mm"] < out["max_shift_mm"]
    # a rigid motion of the whole array is the gauge, not a shift
    turned = {k: PinholeCamera(c.K, pose(_rot([0, 1, 0], 2.0), [0.01, 0, 0]) @ c.cam_to_world,
                               W, H) for k, c in eq6.items()}
    ok = rf.shot_shifts(eq6, turned, list(SHOTS), "1_1", 2.0)
    assert not ok["rejected"] and ok["max_shift_mm"] < 1e-6 and ok["warnings"] == []


def test_a_shot_moved_far_but_tied_to_the_others_is_a_correction(capture):
    """Registration A can place one shot badly (tele-s36: a hand-held shot 8.5 mm off);
    the refinement that moves it back, tied to the shots that stayed by many points, is
    kept. Points shared only among the moved shots, or too few, do not hold it."""
    views, rig, _ = capture
    eq6 = eq6_of(views, rig)
    moved = shot_moved(eq6, rig, "hand01", 0.005)
    tied = [frozenset({"hand01", "x00_y00"})] * 150 + [frozenset({"x00_y00", "x01_y00"})] * 9
    out = rf.shot_shifts(eq6, moved, list(SHOTS), "1_1", 2.0, tied, 100)
    assert not out["rejected"] and out["corrected_shots"] == {"hand01": 150}
    assert len(out["warnings"]) == 1 and "hand01" in out["warnings"][0]
    assert "kept" in out["warnings"][0]
    assert out["shot_ties"]["hand01"] == 150 and out["shot_ties"]["x01_y00"] == 9
    few = rf.shot_shifts(eq6, moved, list(SHOTS), "1_1", 2.0, tied[:99], 100)
    assert few["rejected"] and few["corrected_shots"] == {}
    assert "only 99 of its points" in few["warnings"][0]
    # two shots that moved together, tied to each other only: nothing holds them
    both = shot_moved(moved, rig, "hand00", 0.005)
    pair = [frozenset({"hand00", "hand01"})] * 500
    assert rf.shot_shifts(eq6, both, list(SHOTS), "1_1", 2.0, pair, 100)["rejected"]


def test_a_badly_placed_eq6_shot_is_moved_back_and_the_refinement_kept(capture):
    """Eq. 6 with one hand-held shot 8 mm and 0.3 deg off (as registration A placed
    tele-s36's), past a 5 % limit of the array's size: the refinement puts it back and is
    kept, with a warning naming it."""
    views, rig, db = capture
    eq6 = eq6_of(views, rig)
    bad = shot_moved(eq6, rig, "hand01", 0.008, turn_deg=0.3)
    out = rf.refine_calibration(bad, rig, db, settings(rig="scale", max_shift_pct=5.0),
                                hold_shot="x00_y00")
    rep = out.report
    assert not rep["rejected"], rep["warnings"]
    assert list(rep["corrected_shots"]) == ["hand01"], rep["shot_shift_mm"]
    assert any("hand01" in w and "kept" in w for w in rep["warnings"])
    # nearer the truth than the Eq. 6 it started from (this toy array of six shots and
    # 3 mm baselines holds a far-off shot's place less firmly than a capture's 21)
    before, after = complete_errors(bad, views), complete_errors(out.cameras, views)
    assert after["centre_rmse_mm"] < 0.7 * before["centre_rmse_mm"]
    assert after["rotation_err_deg"]["max"] < 0.5 * before["rotation_err_deg"]["max"]


def test_shots_whose_matches_split_into_groups_keep_eq6s_placement_of_the_groups(
        capture, tmp_path):
    """Two groups of shots that share no match (view_matches' pairs can leave the shot
    graph split: each shot matched with its 2 nearest only) each have a rigid motion no
    point fixes, besides the held shot's. With the rig's baselines 5 % off Eq. 6's spread,
    the adjustment rescales each group about a point of its own and the free group slides
    along its axis; its placement must stay Eq. 6's, the adjustment refining within it."""
    views, rig, db = capture
    group = {"x00_y00": 0, "x00_y01": 0, "hand00": 0, "x01_y00": 1, "x01_y01": 1, "hand01": 1}
    split = tmp_path / "split.db"
    viewdb.subset_database(db, split, sorted(views),
                           keep_pair=lambda a, b: group[a.split("/")[0]]
                           == group[b.split("/")[0]])
    wrong = rig_of(views, "x00_y00", baseline_scale=1.05)
    eq6 = eq6_of(views, wrong)
    out = rf.refine_calibration(eq6, wrong, split, settings(rig="scale"),
                                hold_shot="x00_y00")
    rep = out.report
    assert sorted(map(sorted, rep["shot_groups"])) == [
        ["hand00", "x00_y00", "x00_y01"], ["hand01", "x01_y00", "x01_y01"]]
    assert rep["warnings"] and "share no" in rep["warnings"][-1]
    assert not rep["rejected"], rep["warnings"]
    assert rep["max_shift_mm"] < rep["limit_mm"]
    before = complete_errors(eq6, views)["centre_rmse_mm"]
    assert complete_errors(out.cameras, views)["centre_rmse_mm"] < before


def test_observations_aligned_by_their_patches_keep_the_refinement_on_the_truth(capture):
    """refine.align with the views given (plenocal.calib.track_alignment): most observations
    aligned, a small shift from SIFT's keypoints on these sharp renders (where SIFT places
    them well: the gain is on soft views, BENCHMARKS.md), the shots as near the truth, and
    the focal length within this small capture's noise (0.12 % with SIFT's keypoints, 0.18 %
    aligned)."""
    views, rig, db = capture
    images = {name: db.parent / f"{name}.png" for name in views}
    eq6 = eq6_of(views, rig)
    plain = rf.refine_calibration(eq6, rig, db, settings(), hold_shot="x00_y00")
    out = rf.refine_calibration(eq6, rig, db, settings(), hold_shot="x00_y00", images=images)
    assert plain.report["alignment"]["enabled"] is False
    align = out.report["alignment"]
    assert align["enabled"] is True
    assert align["aligned_share"] > 0.5, align
    assert 0.0 < align["shift_median_px"] < 0.3, align
    assert sorted(out.cameras) == sorted(eq6)
    before, after = complete_errors(plain.cameras, views), complete_errors(out.cameras, views)
    assert abs(after["focal_err_signed_pct"]) < 0.3
    assert after["centre_rmse_mm"] <= 1.1 * before["centre_rmse_mm"]
    assert (after["rotation_err_deg"]["max"]
            < complete_errors(eq6, views)["rotation_err_deg"]["max"])
    obs = out.report["observations"]
    assert obs["after"]["median_px"] < plain.report["observations"]["after"]["median_px"]
    with pytest.raises(ValueError, match="no image file"):
        rf.refine_calibration(eq6, rig, db, settings(), hold_shot="x00_y00",
                              images=dict(list(images.items())[1:]))


def test_the_refined_cameras_are_the_same_bytes_on_one_and_two_threads(capture):
    """The adjustments' normal equations by sparse Cholesky (refine.LINEAR_SOLVER): Ceres'
    threads do not change the cameras' bytes, and two threads give the same bytes twice.
    Ceres' Schur complement, COLMAP's choice, sums on several threads in the order they
    finish and gave other bytes run to run. (The OpenMP threads pycolmap's CHOLMOD starts
    with are the process's, the same for the three runs.)"""
    views, rig, db = capture
    eq6 = eq6_of(views, rig)
    runs = [rf.refine_calibration(eq6, rig, db, settings(num_threads=n), hold_shot="x00_y00")
            for n in (1, 2, 2)]
    for out, n in zip(runs, (1, 2, 2), strict=True):
        assert {p["linear_solver"] for p in out.report["passes"].values()} == {
            rf.LINEAR_SOLVER}
        assert {p["threads"] for p in out.report["passes"].values()} == {n}
    for out in runs[1:]:
        assert sorted(out.cameras) == sorted(runs[0].cameras)
        # refine.focal_sd (on by default): its figures written the same too, though COLMAP's
        # covariance moves its last bits from run to run (refine_uncertainty.SIGNIFICANT)
        assert "std_pct" in out.report["focal_px"]["std"]
        assert out.report["focal_px"] == runs[0].report["focal_px"]
        for key, cam in runs[0].cameras.items():
            assert cam.K.tobytes() == out.cameras[key].K.tobytes(), key
            assert cam.cam_to_world.tobytes() == out.cameras[key].cam_to_world.tobytes(), key


def test_the_focal_lengths_deviation_leaves_the_cameras_alone_and_grows_with_fewer_points(
        capture):
    """refine.focal_sd: the focal pass's covariance gives each sensor's focal length a
    standard deviation (the rig ties them: one value to 1 %), the same bytes of cameras as
    without it, and a larger deviation from a third of the points (``max_points`` 500 of
    the 1,401 used: about sqrt(3) = 1.7x for independent observations; 1.84x, 0.27 ->
    0.50 %, when written)."""
    views, rig, db = capture
    eq6 = eq6_of(views, rig)
    plain = rf.refine_calibration(eq6, rig, db, settings(focal_sd=False), hold_shot="x00_y00")
    assert "std" not in plain.report["focal_px"]
    out = rf.refine_calibration(eq6, rig, db, settings(focal_sd=True), hold_shot="x00_y00")
    for key, cam in plain.cameras.items():
        assert cam.K.tobytes() == out.cameras[key].K.tobytes(), key
        assert cam.cam_to_world.tobytes() == out.cameras[key].cam_to_world.tobytes(), key
    std = out.report["focal_px"]["std"]
    assert std["sensors"] == 9 and 0 < std["std_pct"] < 1.0
    lo, hi = std["sensors_range_pct"]
    assert hi < 1.01 * lo
    # each written to four significant digits (refine_uncertainty.SIGNIFICANT)
    assert std["std_pct"] == pytest.approx(std["per_px_noise_pct"] * std["sigma_px"],
                                           rel=1e-3)
    few = rf.refine_calibration(eq6, rig, db, settings(focal_sd=True, max_points=500),
                                hold_shot="x00_y00")
    ratio = few.report["focal_px"]["std"]["std_pct"] / std["std_pct"]
    assert 1.3 < ratio < 2.6, ratio


def test_the_focal_lengths_deviation_from_every_third_point_is_the_whole_problems(
        capture, monkeypatch):
    """refine.focal_sd on a thinned copy (plenocal.calib.refine_uncertainty.thinned): every
    third point's covariance, scaled by the share of the observations it holds, gives the
    whole problem's deviation within a tenth (on the simulator's captures every fourth and
    every eighth point gave it to 0.001 % of the focal length), the same cameras, and
    figures written without the time taken (refine.json the same bytes run after run)."""
    from plenocal.calib import refine_uncertainty as ru

    views, rig, db = capture
    eq6 = eq6_of(views, rig)
    whole = rf.refine_calibration(eq6, rig, db, settings(focal_sd=True), hold_shot="x00_y00")
    std = whole.report["focal_px"]["std"]
    assert std["points_every"] == 1 and "seconds" not in std
    monkeypatch.setattr(ru, "MAX_OBSERVATIONS", std["observations"] // 3 + 1)
    third = rf.refine_calibration(eq6, rig, db, settings(focal_sd=True), hold_shot="x00_y00")
    thin = third.report["focal_px"]["std"]
    assert thin["points_every"] == 3
    assert 0.25 < thin["observations"] / std["observations"] < 0.42
    assert thin["std_pct"] == pytest.approx(std["std_pct"], rel=0.1)
    assert thin["sigma_px"] == std["sigma_px"]
    for key, cam in whole.cameras.items():
        assert cam.K.tobytes() == third.cameras[key].K.tobytes(), key
        assert cam.cam_to_world.tobytes() == third.cameras[key].cam_to_world.tobytes(), key


def test_the_thinned_copy_keeps_every_kth_point_and_leaves_the_reconstruction_alone():
    """Hand-made: seven points seen twice each; every third point (by id) is ids 1, 4, 7."""
    import cv2  # noqa: F401  (before pycolmap: DESIGN.md)
    import pycolmap

    from plenocal.calib import refine_uncertainty as ru

    rec = pycolmap.Reconstruction()
    rec.add_camera_with_trivial_rig(pycolmap.Camera.create_from_model_id(
        1, pycolmap.CameraModelId.SIMPLE_PINHOLE, 100.0, 64, 48))
    for image_id in (1, 2):
        image = pycolmap.Image(name=f"{image_id}.png", camera_id=1, image_id=image_id,
                               keypoints=np.array([[float(i), 2.0] for i in range(7)]))
        rec.add_image_with_trivial_frame(image, pycolmap.Rigid3d())
    for i in range(7):
        track = pycolmap.Track()
        track.add_element(1, i)
        track.add_element(2, i)
        rec.add_point3D(np.array([0.0, 0.0, 1.0 + i]), track)
    out, kept, total = ru.thinned(rec, 3)
    assert sorted(out.point3D_ids()) == [1, 4, 7]
    assert (kept, total) == (6, 14)
    assert rec.num_points3D() == 7
    assert ru.points_every(14, most=6) == 3 and ru.points_every(6, most=6) == 1
    assert ru.points_every(0) == 1
    assert ru.significant(0.103481340952) == 0.1035
    assert ru.significant(2397.0595) == 2397.0 and ru.significant(0.0) == 0.0


def test_a_covariance_colmap_refuses_leaves_the_refinement_and_says_why(capture, monkeypatch):
    """refine.focal_sd rests on an option COLMAP marks experimental: where its estimator
    raises, the refinement is kept as it is and refine.json says why."""
    import pycolmap

    def refuse(*args, **kwargs):
        raise ValueError("Check failed: image.IsRefInFrame()")

    views, rig, db = capture
    eq6 = eq6_of(views, rig)
    monkeypatch.setattr(pycolmap, "estimate_ba_covariance", refuse)
    out = rf.refine_calibration(eq6, rig, db, settings(focal_sd=True), hold_shot="x00_y00")
    std = out.report["focal_px"]["std"]
    assert std["std_pct"] is None and "IsRefInFrame" in std["why"]
    assert sorted(out.cameras) == sorted(eq6)


def test_a_principal_point_shift_is_the_turn_that_moves_the_image_centre_as_far():
    """Hand-computed: f = 500 px, a shift of (+2, -1) px puts the optical axis's point at
    x = 2 / 500, y = -1 / 500 in normalised coordinates, by a rotation."""
    R = rm.turn_of_shift(np.array([2.0, -1.0]), 500.0)
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-15)
    assert np.isclose(np.linalg.det(R), 1.0)
    x = R @ np.array([0.0, 0.0, 1.0])
    assert np.isclose(x[0] / x[2], 2.0 / 500.0, rtol=0, atol=1e-15)
    assert np.isclose(x[1] / x[2], -1.0 / 500.0, rtol=0, atol=1e-15)
    assert np.allclose(rm.turn_of_shift(np.zeros(2), 500.0), np.eye(3), atol=0)


def _two_shot_rig(tmp_path, shift_px):
    """A 2-view rig (1_1 central, 1_2 3 mm to its right) in two shots, 40 points near the
    optical axes 2 m away, each seen by every image where its principal point is
    ``shift_px`` off the rig's."""
    f, w, h = 500.0, 320, 240
    K = np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1.0]])
    right = np.eye(4)
    right[0, 3] = 0.003
    rig_views = {"1_1": (K, np.eye(4)), "1_2": (K, right)}
    shots = {"x00_y00": pose(np.eye(3), np.zeros(3)),
             "x01_y00": pose(_rot([0, 1, 0], 3.0), np.array([0.05, 0.0, 0.0]))}
    rng = np.random.default_rng(3)
    X = np.column_stack([rng.uniform(-0.08, 0.08, 40), rng.uniform(-0.06, 0.06, 40),
                         rng.uniform(1.9, 2.1, 40)])
    Ks = K.copy()
    Ks[:2, 2] += shift_px
    names, keypoints = {}, {}
    for i, (shot, M) in enumerate(sorted(shots.items())):
        for j, (view, (_, B)) in enumerate(sorted(rig_views.items())):
            name = f"{shot}/{view}.png"
            names[2 * i + j + 1] = name
            uv = PinholeCamera(Ks, M @ B, w, h).project(X)[0]
            keypoints[name] = uv + 0.5  # COLMAP's pixel centres
    points = {k + 1: (X[k], [(image_id, k) for image_id in sorted(names)])
              for k in range(len(X))}
    rec, model = rm.rig_reconstruction_of(names, points, keypoints, rig_views, shots, w, h)
    return rec, model, rig_views, f


def test_turning_the_frames_takes_a_common_principal_point_shift_and_keeps_the_held_one(
        tmp_path):
    """Observations made with every principal point 1.2, -0.7 px off: with the rig's
    principal points they are as far off; with the frames turned by turn_of_shift about the
    held shot, they fit again (to second order over the points' field, 50 times closer),
    and the held frame keeps its pose."""
    shift = np.array([1.2, -0.7])
    rec, model, rig_views, f = _two_shot_rig(tmp_path, shift)
    before = rm.observation_errors(rec, tmp_path)
    assert np.median(before) > 1.2
    held = np.asarray(rec.frame(model.frame_of_shot["x00_y00"]).rig_from_world.matrix())
    rm.turn_frames(rec, model, rm.turn_of_shift(shift, f), "x00_y00")
    after = rm.observation_errors(rec, tmp_path)
    # second order: x^2 |shift| px at normalised x up to 0.1 (the turned shot's points)
    assert after.max() < 0.025 and np.median(after) < 0.005, (after.max(), np.median(after))
    assert np.allclose(rec.frame(model.frame_of_shot["x00_y00"]).rig_from_world.matrix(),
                       held, rtol=0, atol=1e-12)


def test_the_final_pass_starts_where_the_focal_pass_ended(tmp_path):
    """warm_start: after a focal pass that shifted every principal point together, the
    final pass starts from a cost near the focal pass's end (B's principal points back
    alone start it far above), the central view's principal point B's again; with
    frames: hold, B's cameras as they are."""
    shift = np.array([1.2, -0.7])
    rec, model, rig_views, f = _two_shot_rig(tmp_path, shift)
    for v, cid in model.camera_of_view.items():  # the focal pass's end: every point shifted
        p = np.array(rec.camera(cid).params, dtype=float)
        p[2:4] += shift
        p[2] += 0.05 if v == "1_2" else 0.0  # and one view's own offset
        rec.camera(cid).params = p
    assert rm.observation_errors(rec, tmp_path).max() < 0.06
    turn = rf.warm_start(rec, model, rig_views, settings(rig="scale_pp"), f, "x00_y00")
    assert np.isclose(turn, np.degrees(np.hypot(*np.arctan(shift / f))), rtol=1e-3)
    pp = rm.principal_points(rec, model)
    central_b = np.array(rm.colmap_params(rig_views["1_1"][0])[2:4])
    assert np.array_equal(pp["1_1"], central_b)
    assert np.allclose(pp["1_2"] - central_b, [0.05, 0.0], atol=1e-9)  # its own offset kept
    # the focal pass's end again, to the turn's second order (test above)
    assert rm.observation_errors(rec, tmp_path).max() < 0.05 + 0.025
    cold, _, _, _ = _two_shot_rig(tmp_path, shift)
    rm.set_intrinsics(cold, model, rig_views)  # B's principal points back alone
    assert np.median(rm.observation_errors(cold, tmp_path)) > 1.2
    held, _, _, _ = _two_shot_rig(tmp_path, shift)
    assert rf.warm_start(held, model, rig_views, settings(frames="hold"), f, "x00_y00") == 0.0
    assert np.array_equal(rm.principal_points(held, model)["1_2"],
                          np.array(rm.colmap_params(rig_views["1_2"][0])[2:4]))


def test_the_final_pass_stops_at_its_own_cap_and_ends_lower_than_from_bs_cameras(
        capture, monkeypatch):
    """refine.final_iterations caps the final pass (Ceres counts its first evaluation as an
    iteration), max_iterations the focal pass; started where the focal pass ended, the final
    pass ends at a lower cost than from B's cameras set back with the frames as the focal
    pass left them (the start before warm_start), at the same cap."""
    views, rig, db = capture
    eq6 = eq6_of(views, rig)
    out = rf.refine_calibration(eq6, rig, db, settings(final_iterations=2),
                                hold_shot="x00_y00")
    focal, final = out.report["passes"]["focal"], out.report["passes"]["final"]
    assert final["iterations"] <= 3 < focal["iterations"] <= 11
    assert focal["turn_deg"] > 0.0

    def cold(rec, model, views, settings, focal, hold_shot):
        rm.set_intrinsics(rec, model, views)
        return 0.0

    monkeypatch.setattr(rf, "warm_start", cold)
    before = rf.refine_calibration(eq6, rig, db, settings(final_iterations=2),
                                   hold_shot="x00_y00").report["passes"]["final"]
    assert final["initial_cost"] < before["initial_cost"]
    assert final["final_cost"] < before["final_cost"]


def test_track_sets_written_and_read_back_give_the_same_bytes(capture, tmp_path):
    """Rule refine_tracks makes each track set in a job of its own (plenocal.artifacts.
    tracks), rule refine adjusts them: the cameras and the report are the same bytes as
    the refinement that makes its track set in one process, and a damaged folder is
    refused with the rule to rerun."""
    import json  # noqa: PLC0415

    from plenocal.artifacts import tracks as at  # noqa: PLC0415
    from plenocal.io.files import dumps_json  # noqa: PLC0415

    views, rig, db = capture
    images = {name: db.parent / f"{name}.png" for name in views}
    eq6 = eq6_of(views, rig)
    s = settings()
    whole = rf.refine_calibration(eq6, rig, db, s, hold_shot="x00_y00", images=images)
    ts, align, _ = tsets.make_track_set("views", eq6, rig, db, s, images)
    at.write_tracks(tmp_path / "views", "views", ts, align)
    stored = at.read_tracks(tmp_path / "views")
    # refine.json's statistics: the alignment's as written there (dumps_json's digits)
    assert stored.source == at.track_source(tmp_path / "views") == "views"
    assert stored.alignment == json.loads(dumps_json(align))
    assert list(stored.tracks.points) == list(ts.points)
    assert list(stored.tracks.keypoints) == list(ts.keypoints)
    # as rule refine passes them: a function that reads the set (no reference to it
    # outlives the rig reconstruction)
    split = rf.refine_calibration(eq6, rig, None, s, hold_shot="x00_y00", track_sets={
        "views": lambda: (at.read_tracks(tmp_path / "views").tracks, stored.alignment)})
    assert sorted(split.cameras) == sorted(whole.cameras)
    for key, cam in whole.cameras.items():
        assert cam.K.tobytes() == split.cameras[key].K.tobytes(), key
        assert cam.cam_to_world.tobytes() == split.cameras[key].cam_to_world.tobytes(), key
    assert dumps_json(split.report) == dumps_json(whole.report)  # refine.json's bytes
    with pytest.raises(ValueError, match="needs the track sets of central, views"):
        rf.refine_calibration(eq6, rig, None, settings(tracks="both"), hold_shot="x00_y00",
                              track_sets={"views": (stored.tracks, stored.alignment)})
    (tmp_path / "views" / "elements.npy").unlink()
    with pytest.raises(ValueError, match="elements.npy.*rerun rule refine_tracks"):
        at.read_tracks(tmp_path / "views")


def test_the_scale_source_says_what_set_the_written_scale():
    """refine.json's scale_source: under refine.scale: merge, the merge's r (Eq. 5's or the
    stage's step, as rule scale chose), not "Eq. 5" where the merge took the step."""
    from plenocal.calib.refine import RefineSettings, scale_source

    merge = RefineSettings.from_config({"scale": "merge"}, seed=0)
    text = scale_source(merge, None)
    assert text.startswith("the merge's r") and "merge/scale.json's chosen" in text
    step = {"step_m": 0.01, "n_shots": 6}
    auto = RefineSettings.from_config({"scale": "auto"}, seed=0)
    assert scale_source(auto, step).startswith("the stage's step (10 mm) fitted to the 6 ")


def test_the_rig_read_from_cameras_is_centred_on_the_central_view_of_any_size():
    """11 x 11 views (the schema allows 15): the identity sensor is 5_5, not the middle of
    the names sorted as text (4_4)."""
    from plenocal.camera import PinholeCamera
    from plenocal.names import view_names

    K = np.array([[100.0, 0, 50], [0, 100.0, 40], [0, 0, 1]])
    cams = {}
    for v in view_names(11):
        r, c = map(int, v.split("_"))
        M = np.eye(4)
        M[:3, 3] = [(c - 5) * 1e-3, (r - 5) * 1e-3, 0.0]
        cams[f"x00_y00/{v}"] = PinholeCamera(K, M, 100, 80)
    poses = rm.rig_views_from_cameras(cams, "x00_y00")
    assert np.array_equal(poses["5_5"], np.eye(4))
    assert np.allclose(poses["0_0"][:3, 3], [-5e-3, -5e-3, 0.0])
