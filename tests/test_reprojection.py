"""Reprojection error with known cameras (Table I machinery) and the A+SfM baseline, on
synthetic renders whose true cameras are known exactly."""

import os

import cv2  # noqa: F401  (before pycolmap)
import numpy as np
import pytest
from synth.scenes import default_scene, render, render_view_sets, rig_cameras

from plenocal.artifacts.cameras import write_cameras
from plenocal.artifacts.reg_a import RegistrationA
from plenocal.artifacts.rig import RigB
from plenocal.calib.reg_a import colmap as cm
from plenocal.calib.reg_a import viewdb
from plenocal.camera import PinholeCamera, invert_pose, pose
from plenocal.io.files import write_image
from plenocal.verify.reprojection import (
    adjust_points,
    evaluate,
    evaluate_calibration,
    evaluate_sets,
    filter_for_export,
    observation_errors,
    reg_a_views,
    reprojection_stats,
    table_i,
    triangulate,
    triangulation_options,
)

F, W, H = 600.0, 480, 360


@pytest.fixture(scope="module")
def shots(tmp_path_factory):
    root = tmp_path_factory.mktemp("reproj")
    cams = rig_cameras(f=F, width=W, height=H, handheld=3)
    scene = default_scene()
    paths = {}
    for name, cam in cams.items():
        paths[name] = root / f"{name}.png"
        write_image(paths[name], render(cam, scene))
    return cams, paths


def _rot_x(deg):
    a = np.radians(deg)
    return np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])


def test_true_cameras_reproject_small_and_perturbed_larger(shots):
    cams, paths = shots
    true = reprojection_stats(cams, paths)
    assert true["num_images"] == len(cams) == true["num_images_with_points"]
    assert true["num_points3D"] > 300 and true["num_observations"] > 3 * true["num_points3D"]
    assert true["mean_px"] < 0.5 and true["median_px"] < 0.2
    assert true["max_error_px"] == 100.0
    # one camera tilted by 0.3 deg (about 3 px at f = 600) and the focal 1 % off
    bad = dict(cams)
    c = cams["x01_y00"]
    bad["x01_y00"] = PinholeCamera(c.K, pose(c.R @ _rot_x(0.3), c.centre), W, H)
    bad = {k: PinholeCamera(np.diag([1.01, 1.01, 1.0]) @ v.K, v.cam_to_world, W, H)
           for k, v in bad.items()}
    pert = reprojection_stats(bad, paths)
    assert pert["median_px"] > 2 * true["median_px"]
    assert pert["mean_px"] > true["mean_px"] + 0.1


def test_pixel_centre_convention(shots):
    """Half a pixel of principal point on the rotated shots only (the COLMAP convention
    leaking through in one place) must show in the median error."""
    cams, paths = shots
    half = np.array([[0, 0, 0.5], [0, 0, 0.5], [0, 0, 0]])
    shifted = {k: PinholeCamera(v.K + (half if k.startswith("hand") else 0), v.cam_to_world,
                                W, H) for k, v in cams.items()}
    a = reprojection_stats(cams, paths)["median_px"]
    b = reprojection_stats(shifted, paths)["median_px"]
    assert b > a + 0.05


def test_reg_a_and_rig_documents():
    K = np.array([[600.0, 0, 239.5], [0, 600.0, 179.5], [0, 0, 1]])
    M = pose(np.eye(3), np.array([0.1, 0.2, 0.3]))
    reg = RegistrationA(focal_px=600.0, width=W, height=H, mapper="incremental",
                        cameras={"x00_y00": PinholeCamera(K, M, W, H)})
    views = reg_a_views(reg, "2_2")
    assert list(views) == ["x00_y00/2_2"]
    np.testing.assert_allclose(views["x00_y00/2_2"].cam_to_world, M)
    assert views["x00_y00/2_2"].width == W


def test_view_pairs_by_hand():
    names = [f"{s}/{v}.png" for s in ("a", "b", "c") for v in ("0_0", "0_1", "1_1", "0_2")]
    # radius 1 within a shot: 0_0-0_1, 0_0-1_1, 0_1-1_1, 0_1-0_2, 1_1-0_2 (not 0_0-0_2)
    within = [(f"a/{x}.png", f"a/{y}.png") for x, y in
              (("0_0", "0_1"), ("0_0", "1_1"), ("0_1", "0_2"), ("0_1", "1_1"), ("0_2", "1_1"))]
    centres = {"a": np.zeros(3), "b": np.array([1.0, 0, 0]), "c": np.array([3.0, 0, 0])}
    # one neighbour each: a-b (a's and b's nearest), b-c (c's nearest); never a-c
    got = viewdb.view_pairs(names, centres, shot_neighbours=1, view_radius=1,
                            within_shot="grid")
    assert [p for p in got if p[0].startswith("a/") and p[1].startswith("a/")] == within
    across = {(p[0][0], p[1][0]) for p in got if p[0][0] != p[1][0]}
    assert across == {("a", "b"), ("b", "c")}
    assert all(p[0][2:] == p[1][2:] for p in got if p[0][0] != p[1][0])
    assert len(got) == 3 * 5 + 2 * 4
    # None: every pair within a shot and the same view across every two shots
    full = viewdb.view_pairs(names, centres, shot_neighbours=None, view_radius=None,
                             within_shot="grid")
    assert len(full) == 3 * 6 + 3 * 4
    # no shot here has a central view (rows 0-1), so "centre" pairs them as the grid does
    assert viewdb.view_pairs(names, centres, shot_neighbours=1, view_radius=1) == got
    # names without views: exhaustive
    assert viewdb.view_pairs(["x.png", "y.png", "z.png"], None) == [
        ("x.png", "y.png"), ("x.png", "z.png"), ("y.png", "z.png")]


def test_view_pairs_with_the_central_view_by_hand():
    grid3 = [f"{r}_{c}" for r in range(3) for c in range(3)]
    names = [f"{s}/{v}.png" for s in ("a", "b") for v in grid3] + ["c/0_0.png", "c/0_1.png"]
    assert viewdb.central_views(names) == {"a": (1, 1), "b": (1, 1)}  # c: none
    assert viewdb.central_views(["d/1_1.png", "d/1_3.png", "d/3_1.png", "d/3_3.png"]) == {}
    assert viewdb.central_views([f"e/{r}_{c}" for r in (2, 3, 4) for c in (5, 6, 7)]) == {
        "e": (3, 6)}
    got = viewdb.view_pairs(names, None, shot_neighbours=None, view_radius=1)
    within_a = [p for p in got if p[0].startswith("a/") and p[1].startswith("a/")]
    # each of the eight other views with 1_1, and nothing else within the shot
    assert within_a == sorted(tuple(sorted((f"a/{v}.png", "a/1_1.png")))
                              for v in grid3 if v != "1_1")
    across = [p for p in got if p[0][0] != p[1][0]]
    # across shots the same view of every two shots, as with the grid
    assert len(across) == 9 + 2 + 2 and all(p[0][2:] == p[1][2:] for p in across)
    assert [p for p in got if p[0].startswith("c/") and p[1].startswith("c/")] == [
        ("c/0_0.png", "c/0_1.png")]  # no central view: the grid's pairs
    assert len(viewdb.view_pairs(names, None, shot_neighbours=None, view_radius=1,
                                 within_shot="grid")) == 2 * 20 + 1 + 13
    with pytest.raises(ValueError, match="within_shot"):
        viewdb.view_pairs(names, None, within_shot="star")


def test_nearest_shots_ties_by_name():
    c = {"b": np.array([1.0, 0, 0]), "a": np.zeros(3), "c": np.array([-1.0, 0, 0])}
    # a's two neighbours are equally near: the name decides
    assert viewdb.nearest_shots(c, 1) == {("a", "b"), ("a", "c")}


@pytest.fixture(scope="module")
def sets(shots, tmp_path_factory):
    cams, _ = shots
    return render_view_sets(cams, tmp_path_factory.mktemp("sets"))


def test_rig_sets(sets, tmp_path):
    sub, vs, paths = sets
    rig = {"width": W, "height": H, "n_views": 3, "views": {}}
    for k in ("x00_y00", "hand00"):
        central = vs[f"{k}/1_1"].cam_to_world
        for name, cam in vs.items():
            if name.startswith(k):
                rig["views"][name.split("/")[1]] = {
                    "K": cam.K, "cam_to_central": invert_pose(central) @ cam.cam_to_world}
    imgs = {k: v for k, v in paths.items() if k.startswith(("x00_y00", "hand00"))}
    db = tmp_path / "views.db"
    info = viewdb.build_view_database(imgs, db, tmp_path, max_num_features=2000)
    assert info["num_images"] == 18 and info["num_pairs"] == 2 * 8 + 9  # the central view's pairs
    out = evaluate_sets(RigB(rig), db)
    assert sorted(out["sets"]) == ["hand00", "x00_y00"]
    assert out["sets"]["hand00"]["num_images"] == 9
    assert out["median_px"] < 0.2


def test_subset_database_sets_each_camera(sets, tmp_path):
    """A calibration's copy of the view database: only its images, each camera at its
    intrinsics, only the verified pairs among them; one shared camera on request."""
    import pycolmap

    _, vs, paths = sets
    db = tmp_path / "views.db"
    viewdb.build_view_database(paths, db, tmp_path, max_num_features=1000)
    names = [n for n in vs if n.startswith("hand00")]
    cams = {}
    for i, n in enumerate(sorted(names)):  # a principal point of its own per view
        K = vs[n].K.copy()
        K[0, 2] += i
        K[1, 2] -= 0.5 * i
        cams[n] = PinholeCamera(K, vs[n].cam_to_world, W, H)
    os.utime(db, ns=(10**18, 10**18))  # an old, known modification time
    n_pairs = viewdb.subset_database(db, tmp_path / "sub.db", names, cams)
    assert sorted(viewdb.database_names(db)) == sorted(paths)
    # read by several rules: reading must not touch it (Snakemake would rerun them)
    assert db.stat().st_mtime_ns == 10**18
    with pycolmap.Database.open(str(tmp_path / "sub.db")) as d:
        images = {im.name: im for im in d.read_all_images()}
        assert sorted(images) == sorted(f"{n}.png" for n in names)
        for n in names:
            c = d.read_camera(images[f"{n}.png"].camera_id)
            K = cams[n].K
            assert np.allclose(c.params, [K[0, 0], K[1, 1], K[0, 2] + 0.5, K[1, 2] + 0.5])
        assert d.num_verified_image_pairs() == n_pairs
    assert 0 < n_pairs <= 9 * 8 // 2
    viewdb.subset_database(db, tmp_path / "one.db", names, cams[names[0]])
    with pycolmap.Database.open(str(tmp_path / "one.db")) as d:
        assert d.num_cameras() == 1 and d.num_images() == 9


def _triangulated(sets, shots: tuple[str, ...], tmp_path):
    """The views of ``shots`` triangulated with their true cameras fixed (Table I's
    triangulation): the reconstruction and the cameras by COLMAP image name."""
    _, vs, paths = sets
    names = sorted(n for n in vs if n.startswith(shots))
    db = tmp_path / "views.db"
    viewdb.build_view_database({n: paths[n] for n in names}, db, tmp_path,
                               max_num_features=1000)
    sub = tmp_path / "sub.db"
    viewdb.subset_database(db, sub, names, {n: vs[n] for n in names})
    cams = {f"{n}.png": vs[n] for n in names}
    rec = cm.known_pose_reconstruction(sub, cams, update_intrinsics=False)
    triangulate(rec, sub, triangulation_options(100.0, 0.1, 0, 1), 0, cams, tmp_path)
    return rec, cams


def test_observation_errors_match_the_bindings(sets, tmp_path):
    """The errors read back from COLMAP's binary model equal those computed through the
    Python bindings, observation by observation; every registered image keeps its pose."""
    rec, cams = _triangulated(sets, ("x02_y01",), tmp_path)
    want = []
    for image_id in sorted(rec.reg_image_ids()):
        image = rec.image(image_id)
        pts = [(p.xy, p.point3D_id) for p in image.points2D if p.has_point3D()]
        xy = np.array([p[0] for p in pts]) - 0.5
        uv, _ = cams[image.name].project(np.array([rec.point3D(p[1]).xyz for p in pts]))
        want.append(np.linalg.norm(uv - xy, axis=1))
        np.testing.assert_allclose(cm.pinhole_from_colmap(image, image.camera).cam_to_world,
                                   cams[image.name].cam_to_world, atol=1e-9)
    got = observation_errors(rec, cams, tmp_path)
    assert got.size > 300
    np.testing.assert_array_equal(got, np.concatenate(want))


def test_adjust_points_as_colmaps_bundle_adjustment(sets, tmp_path):
    """The points' refinement that replaces COLMAP's bundle adjustment in the triangulation
    (cameras fixed) reaches what Ceres reaches, run to tight tolerances on the same
    reconstruction with every point moved off its optimum."""
    import pycolmap

    rec, cams = _triangulated(sets, ("x00_y00", "x01_y00"), tmp_path)
    rng = np.random.default_rng(0)
    for pid in sorted(rec.point3D_ids()):
        rec.point3D(pid).xyz = rec.point3D(pid).xyz + rng.normal(0, 2e-3, 3)
    theirs = pycolmap.Reconstruction(rec)
    assert adjust_points(rec, cams, tmp_path) == rec.num_points3D() > 200
    config = pycolmap.BundleAdjustmentConfig()
    for image_id in theirs.reg_image_ids():
        config.add_image(image_id)
        config.set_constant_rig_from_world_pose(theirs.image(image_id).frame_id)
    for camera_id in theirs.cameras:
        config.set_constant_cam_intrinsics(camera_id)
    options = pycolmap.BundleAdjustmentOptions()
    options.refine_focal_length = options.refine_extra_params = False
    options.print_summary = False
    solver = options.ceres.solver_options
    solver.function_tolerance = solver.gradient_tolerance = solver.parameter_tolerance = 1e-14
    solver.max_num_iterations = 500
    solver.num_threads = 1
    pycolmap.create_default_bundle_adjuster(options, config, theirs).solve()
    ours_err = observation_errors(rec, cams, tmp_path)
    their_err = observation_errors(theirs, cams, tmp_path)
    assert ours_err.size == their_err.size > 1000
    np.testing.assert_allclose(ours_err, their_err, rtol=0, atol=1e-5)
    moved = max(np.abs(rec.point3D(p).xyz - theirs.point3D(p).xyz).max()
                for p in rec.point3D_ids())
    assert moved < 1e-6


def test_evaluate_calibration_reads_a_cameras_file_as_evaluate(sets, tmp_path):
    """Rule reprojection_calib's one call: a cameras.json evaluated as its cameras are."""
    _, vs, paths = sets
    imgs = {k: v for k, v in paths.items() if k.startswith("x00_y00")}
    db = tmp_path / "views.db"
    viewdb.build_view_database(imgs, db, tmp_path, max_num_features=2000)
    cams = {k: v for k, v in vs.items() if k in imgs}
    write_cameras(tmp_path / "cameras.json", cams)
    doc = evaluate_calibration("complete", tmp_path / "cameras.json", db, "1_1")
    assert doc.pop("calibration") == "complete"
    assert doc == evaluate(cams, db)
    assert doc["num_images"] == 9 and doc["median_px"] < 0.2


def test_the_triangulated_model_holds_the_calibration_and_coloured_points(sets, tmp_path):
    """Rule reprojection_complete's model (calibration/colmap_points): every view with its
    calibrated camera and pose, the points Table I triangulated as COLMAP filters its
    models (every observation within COLMAP's 4 px), each reprojecting into its views as
    Table I measured, coloured from the views; the same bytes twice."""
    import pycolmap

    _, vs, paths = sets
    imgs = {k: v for k, v in paths.items() if k.startswith(("x00_y00", "hand00"))}
    db = tmp_path / "views.db"
    viewdb.build_view_database(imgs, db, tmp_path, max_num_features=2000)
    cams = {k: v for k, v in vs.items() if k in imgs}
    docs = [evaluate(cams, db, model_dir=tmp_path / f"model{k}", images=imgs)
            for k in range(2)]
    assert docs[0] == docs[1] == evaluate(cams, db)
    for name in ("cameras.bin", "images.bin", "points3D.bin"):
        assert ((tmp_path / "model0" / name).read_bytes()
                == (tmp_path / "model1" / name).read_bytes())
    rec = pycolmap.Reconstruction(str(tmp_path / "model0"))
    assert rec.num_reg_images() == len(cams) == 18
    assert 0.9 * docs[0]["num_points3D"] <= rec.num_points3D() <= docs[0]["num_points3D"]
    errs = []
    for image in rec.images.values():
        want = cams[image.name[:-4]]
        got = cm.pinhole_from_colmap(image, rec.camera(image.camera_id))
        np.testing.assert_allclose(got.K, want.K, atol=1e-9)
        np.testing.assert_allclose(got.cam_to_world, want.cam_to_world, atol=1e-9)
        for p2 in image.points2D:
            if p2.has_point3D():
                uv = want.project(rec.points3D[p2.point3D_id].xyz[None])[0]
                errs.append(np.linalg.norm(uv - (np.asarray(p2.xy) - 0.5)))
    errs = np.asarray(errs)
    within = docs[0]["fraction_within_4px"] * docs[0]["num_observations"]
    assert 0.95 * within <= errs.size <= within + 0.5
    assert errs.max() <= 4.0 + 1e-6
    colours = np.array([p.color for p in rec.points3D.values()])
    assert colours.std(axis=0).min() > 5  # the scene's texture, not a flat default


def test_the_points_model_leaves_out_what_colmap_would(sets, tmp_path):
    """filter_for_export: a point moved off its track (every view tens of px away) is
    removed with its observations, as COLMAP removes it from its own models; a point
    moved by a fraction of a pixel stays; the counts returned are what left the model.
    Table I's own figures are over every observation up to 100 px."""
    import pycolmap

    _, vs, paths = sets
    imgs = {k: v for k, v in paths.items() if k.startswith(("x00_y00", "hand00"))}
    db = tmp_path / "views.db"
    viewdb.build_view_database(imgs, db, tmp_path, max_num_features=2000)
    cams = {k: v for k, v in vs.items() if k in imgs}
    evaluate(cams, db, model_dir=tmp_path / "model", images=imgs)
    rec = pycolmap.Reconstruction(str(tmp_path / "model"))
    far, near = sorted(rec.points3D)[:2]
    far_track = rec.points3D[far].track.length()
    depth = np.linalg.norm(rec.points3D[far].xyz - rec.images[
        rec.points3D[far].track.elements[0].image_id].projection_center())
    rec.points3D[far].xyz = rec.points3D[far].xyz + np.array([0.05, 0.0, 0.0]) * depth
    rec.points3D[near].xyz = rec.points3D[near].xyz + np.array([1e-5, 0.0, 0.0]) * depth
    before = rec.num_points3D(), rec.compute_num_observations()
    removed = filter_for_export(rec, 4.0, 0.1)
    assert far not in rec.points3D and near in rec.points3D
    assert removed == (before[0] - rec.num_points3D(), before[1] - rec.compute_num_observations())
    assert removed[0] >= 1 and removed[1] >= far_track


def test_table_i_rows_by_hand():
    evals = {"complete": {"num_images": 9, "mean_px": 0.3, "median_px": 0.2},
             "baseline_sfm": {"num_images": 9, "mean_px": 0.4, "median_px": 0.3}}
    doc = table_i(evals, {"a_sfm_registered": 8},
                  {"num_images": 9, "registered_largest_model": 7, "num_models": 2,
                   "focal_px": 601.5})
    assert doc["baseline_sfm"] == {"num_images": 9, "mean_px": 0.4, "median_px": 0.3,
                                   "num_registered": 8}
    assert doc["sfm_scratch"] == {"num_images": 9, "num_registered": 7, "num_models": 2,
                                  "focal_px": 601.5}
    assert doc["complete"] == evals["complete"] and "num_registered" not in evals[
        "baseline_sfm"]  # the inputs are left as they were
    assert "sfm_scratch" not in table_i(evals, {"a_sfm_registered": 9})


def test_nearest_shots_join_the_groups_that_nearest_neighbours_leave_apart():
    # a 4 x 2 grid, step 1, the gap between columns 1 and 2 a hair wider: each shot's two
    # nearest pair the columns 0-1 and 2-3 among themselves, as registration A's slightly
    # uneven centres split wide-s3's 5 x 2 array in two
    c = {f"x{x:02d}_y{y:02d}": np.array([x + 0.001 * (x >= 2), float(y), 0.0])
         for x in range(4) for y in range(2)}
    pairs = viewdb.nearest_shots(c, 2)
    group = {s: s for s in c}

    def root(s):
        while group[s] != s:
            s = group[s]
        return s

    for a, b in pairs:
        group[root(a)] = root(b)
    assert len({root(s) for s in c}) == 1
    # one link joins the two halves: the shortest, ties by name
    assert ("x01_y00", "x02_y00") in pairs
    assert not {("x01_y01", "x02_y01")} & pairs
