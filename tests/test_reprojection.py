"""Reprojection error with known cameras (Table I machinery) and the A+SfM baseline, on
synthetic renders whose true cameras are known exactly."""

import cv2  # noqa: F401  (before pycolmap)
import numpy as np
import pytest

from plenocal.camera import PinholeCamera, invert_pose, pose
from plenocal.io import write_image
from plenocal.sfm.colmap import set_pairs
from plenocal.sfm.synthetic import default_scene, render, rig_cameras, view_sets
from plenocal.verify.reprojection import evaluate_sets, reg_a_views, reprojection_stats

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
    views = reg_a_views({"width": W, "height": H, "cameras": {"x00_y00": {"K": K.tolist(),
                                                                          "cam_to_world": M}}},
                        "2_2")
    assert list(views) == ["x00_y00/2_2"]
    np.testing.assert_allclose(views["x00_y00/2_2"].cam_to_world, M)
    assert views["x00_y00/2_2"].width == W


def test_set_pairs():
    names = ["a/0_0.png", "a/0_1.png", "b/0_0.png", "b/0_1.png"]
    assert set_pairs(names) == [("a/0_0.png", "a/0_1.png"), ("a/0_0.png", "b/0_0.png"),
                                ("a/0_1.png", "b/0_1.png"), ("b/0_0.png", "b/0_1.png")]


@pytest.fixture(scope="module")
def sets(shots, tmp_path_factory):
    cams, _ = shots
    root = tmp_path_factory.mktemp("sets")
    sub = {k: cams[k] for k in ("x00_y00", "x02_y01", "hand00", "hand01")}
    vs = view_sets(sub, 3, 0.003)
    scene = default_scene()
    paths = {}
    for name, cam in vs.items():
        paths[name] = root / f"{name}.png"
        write_image(paths[name], render(cam, scene))
    return sub, vs, paths


def test_rig_sets(sets):
    sub, vs, paths = sets
    rig = {"width": W, "height": H, "views": {}}
    for k in ("x00_y00", "hand00"):
        central = vs[f"{k}/1_1"].cam_to_world
        for name, cam in vs.items():
            if name.startswith(k):
                rig["views"][name.split("/")[1]] = {
                    "K": cam.K, "cam_to_central": invert_pose(central) @ cam.cam_to_world}
    imgs = {k: v for k, v in paths.items() if k.startswith(("x00_y00", "hand00"))}
    out = evaluate_sets(rig, imgs, max_num_features=2000)
    assert sorted(out["sets"]) == ["hand00", "x00_y00"]
    assert out["sets"]["hand00"]["num_images"] == 9
    assert out["median_px"] < 0.2
