"""Ground truth by chief-ray tracing (issue 2, items 5 and 6): the fitted pinholes against
hand-computed structure, the simulator's own patch geometry and its lenslet renders."""

from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from plenocal.artifacts.cameras import read_cameras
from plenocal.config import validate_config
from plenocal.grid import MicrolensGrid
from plenocal.optics import PlenopticOptics
from plenocal.simulate.dataset import make_calib, nearest_lens_map, setup_dataset
from plenocal.simulate.groundtruth import (
    fit_pinhole,
    ground_truth_cameras,
    intersect_rays,
    shot_cameras,
)
from plenocal.simulate.optics_setup import optics_from_config
from plenocal.simulate.raytrace import render_lenslet, render_pinhole
from plenocal.simulate.scene import scene_arrays
from plenocal.viewgeom import make_layout

ROOT = Path(__file__).resolve().parents[1]


def small_sim(width=400, height=300) -> dict:
    cfg = validate_config(yaml.safe_load((ROOT / "tests" / "tiny" / "config.yaml").read_text()))
    sim = copy.deepcopy(cfg["datasets"]["tiny"]["simulate"])
    sim["sensor"].update(width=width, height=height, noise_std=0.0)
    return sim


def optics_of(sim: dict) -> PlenopticOptics:
    return optics_from_config(sim)


def rot_y(deg: float) -> np.ndarray:
    a = math.radians(deg)
    return np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])


def test_intersect_rays_finds_the_common_point():
    rng = np.random.default_rng(0)
    X = np.array([0.1, -0.2, 0.7])
    o = rng.normal(size=(6, 3))
    d = X - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    np.testing.assert_allclose(intersect_rays(o, d), X, atol=1e-12)


def test_fit_pinhole_recovers_a_generic_camera():
    """DLT + RQ on pixel <-> direction pairs gives back K (skew kept when it is real) and
    the camera-to-frame rotation."""
    K = np.array([[900.0, 3.0, 310.0], [0.0, 880.0, 222.0], [0.0, 0.0, 1.0]])
    R = rot_y(12.0) @ np.array([[1, 0, 0], [0, math.cos(0.2), -math.sin(0.2)],
                                [0, math.sin(0.2), math.cos(0.2)]])
    rng = np.random.default_rng(1)
    px = rng.uniform([0, 0], [640, 480], size=(50, 2))
    rays_cam = np.c_[px, np.ones(50)] @ np.linalg.inv(K).T
    dirs = rays_cam @ R.T  # into the frame
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    K_fit, R_fit = fit_pinhole(px, dirs)
    np.testing.assert_allclose(K_fit, K, atol=1e-6)
    np.testing.assert_allclose(R_fit, R, atol=1e-9)


def test_ground_truth_projection_matches_the_patch_geometry():
    """A 3-D point on a tile centre's chief ray projects, with the ground-truth camera,
    onto that tile centre, for every view of a rotated, shifted shot."""
    sim = small_sim()
    sim["mla"]["rotation_rad"] = 0.01
    optics = optics_of(sim)
    grid = MicrolensGrid(make_calib(sim, optics), optics.width, optics.height)
    layout = make_layout(grid, 3, 6)
    pose = np.eye(4)
    pose[:3, :3] = rot_y(7.0)
    pose[:3, 3] = [0.02, -0.01, 0.005]
    cams, worst = shot_cameras(optics, grid, layout, pose)
    assert worst < 1e-6
    for r in range(3):
        for c in range(3):
            o, d = optics.chief_rays(layout.chief_sensor_points(r, c), layout.lens_centres)
            for z in (0.47, 0.6, 0.74):
                X = o + d * (z / d[:, 2:3])  # points at depth z in the camera frame
                Xw = X @ pose[:3, :3].T + pose[:3, 3]
                uv, depth = cams[f"{r}_{c}"].project(Xw)
                np.testing.assert_allclose(uv, layout.tile_centres, atol=1e-6)
                np.testing.assert_allclose(depth, z, rtol=1e-9)


def test_ground_truth_structure_by_hand():
    """Identity rotations, centres L q p / s apart on the main-lens plane (+x with the
    column, +y with the row), principal point shifted by f B / Z0 per step, the
    central view's at the image centre, focal T L / D."""
    sim = small_sim()
    optics = optics_of(sim)
    grid = MicrolensGrid(make_calib(sim, optics), optics.width, optics.height)
    layout = make_layout(grid, 5, 6)
    cams, _ = shot_cameras(optics, grid, layout, np.eye(4))
    # tiny config: F 35 mm at 0.6 m, D 130 um, F_n 2.8, k 5, p 5.5 um
    F, D, p = 0.035, 130e-6, 5.5e-6
    f_mla = 2.8 * D
    s, t = 5 * f_mla / 4, 5 * f_mla
    L = F + F * F / (0.6 - F) + t
    q = (D * (L + s) / (L * p) - 2.0) * math.sin(math.radians(45)) / 5
    assert layout.q == pytest.approx(q, rel=1e-12)
    B = L * q * p / s
    Z0 = F * L / (L - F)
    f = cams["2_2"].K[0, 0]
    assert f == pytest.approx(6 * L / D, rel=1e-9)
    np.testing.assert_allclose(cams["2_2"].K[:2, 2], [(layout.width - 1) / 2,
                                                       (layout.height - 1) / 2], atol=1e-6)
    shift = f * B / Z0
    for r in range(5):
        for c in range(5):
            cam = cams[f"{r}_{c}"]
            assert cam.K[0, 1] == 0.0 and cam.K[1, 1] == pytest.approx(f, rel=1e-9)
            np.testing.assert_allclose(cam.R, np.eye(3), atol=1e-9)
            np.testing.assert_allclose(cam.centre, [(c - 2) * B, (r - 2) * B, 0.0], atol=1e-9)
            np.testing.assert_allclose(cam.K[:2, 2] - cams["2_2"].K[:2, 2],
                                       [(c - 2) * shift, (r - 2) * shift], atol=1e-6)


def test_views_without_cut_border_lenses_keep_their_cameras_centred():
    """Border lenses left out (their micro images cut by the main lens,
    plenocal.convert.bordercut): the views are smaller, symmetric about the axis, and
    every view's camera is the uncut view's moved by the crop: the same focal length,
    rotation and centre, the principal point moved by half the rows removed, so the
    central view's stays at the image centre (registration A's and B's assumption)."""
    sim = small_sim()
    optics = optics_of(sim)
    grid = MicrolensGrid(make_calib(sim, optics), optics.width, optics.height)
    full = make_layout(grid, 5, 6)
    d = grid.border_distance("top")
    inset = float(np.unique(np.round(d[grid.inside(0.0)], 1))[2])  # two lens rows out
    cut = make_layout(grid, 5, 6, insets_px={"top": inset})
    assert cut.width == full.width and cut.height < full.height
    rows = (full.height - cut.height) / 2
    a, _ = shot_cameras(optics, grid, full, np.eye(4))
    b, _ = shot_cameras(optics, grid, cut, np.eye(4))
    np.testing.assert_allclose(b["2_2"].K[:2, 2], [(cut.width - 1) / 2, (cut.height - 1) / 2],
                               atol=1e-6)
    for name in a:
        assert b[name].K[0, 0] == pytest.approx(a[name].K[0, 0], rel=1e-9)
        np.testing.assert_allclose(b[name].K[:2, 2], a[name].K[:2, 2] - [0.0, rows],
                                   atol=1e-6)
        np.testing.assert_allclose(b[name].R, a[name].R, atol=1e-9)
        np.testing.assert_allclose(b[name].centre, a[name].centre, atol=1e-9)


def _bilinear(img: np.ndarray, xy: np.ndarray) -> np.ndarray:
    import cv2

    m = xy.astype(np.float32).reshape(-1, 1, 2)
    return cv2.remap(img, m[..., 0], m[..., 1], cv2.INTER_LINEAR).reshape(len(xy), -1)


def test_lenslet_render_agrees_with_the_ground_truth_render():
    """End to end: the lenslet image read at the sensor points the tile centres sample
    equals the ideal pinhole render of the ground-truth camera at the tile centres (a
    plane in the focus plane, so the micro images are sharp); the camera of another view
    does not fit."""
    sim = small_sim(480, 360)
    optics = optics_of(sim)
    grid = MicrolensGrid(make_calib(sim, optics), optics.width, optics.height)
    layout = make_layout(grid, 3, 6)
    w = 0.4
    scene = scene_arrays({"quads": [{"p0": [-w / 2, -w / 2, 0.6], "u": [w, 0, 0],
                                     "v": [0, w, 0], "texture": "astronaut",
                                     "texel_m": 0.0004}]})
    lenslet = render_lenslet(scene, optics, nearest_lens_map(grid), np.eye(4), 16, 0)
    cams, _ = shot_cameras(optics, grid, layout, np.eye(4))
    errors = {}
    for view in ("0_0", "1_1", "2_1"):
        r, c = (int(x) for x in view.split("_"))
        seen = _bilinear(lenslet, layout.chief_sensor_points(r, c))
        for cam_view in ("0_0", "1_1", "2_1"):
            cam = cams[cam_view]
            ideal, _ = render_pinhole(scene, cam.K, cam.cam_to_world, cam.width, cam.height, 3)
            errors[view, cam_view] = float(np.abs(_bilinear(ideal, layout.tile_centres)
                                                  - seen).mean())
    for view in ("0_0", "1_1", "2_1"):
        assert errors[view, view] < 0.02, errors
        for other in ("0_0", "1_1", "2_1"):
            if other != view:
                assert errors[view, other] > 2 * errors[view, view], errors


def test_ground_truth_cameras_file(tmp_path: Path):
    sim = small_sim(320, 240)
    setup_dataset(sim, tmp_path)
    out = tmp_path / "gt" / "cameras.json"
    ground_truth_cameras(tmp_path, ["hand00", "x00_y00"], 3, 6, None, out, log=lambda m: None)
    cams = read_cameras(out)
    assert sorted(cams) == sorted(f"{s}/{r}_{c}" for s in ("hand00", "x00_y00")
                                  for r in range(3) for c in range(3))
    shots = yaml.safe_load((tmp_path / "truth" / "shots.json").read_text())
    # the central view's pose is the shot's (its centre is the main-lens centre)
    for shot in ("hand00", "x00_y00"):
        M = np.asarray(shots[shot]["cam_to_world"])
        np.testing.assert_allclose(cams[f"{shot}/1_1"].cam_to_world, M, atol=1e-12)
    # the worst chief-ray fit of all shots is the file's
    doc = yaml.safe_load(out.read_text())
    assert 0 <= doc["fit_residual_px"] < 1e-6
    with pytest.raises(KeyError, match="hand09"):
        ground_truth_cameras(tmp_path, ["hand00", "hand09"], 3, 6, None, out,
                             log=lambda m: None)


def test_ground_truth_follows_the_grid_the_views_were_laid_out_on(tmp_path: Path):
    """A set-up whose grid the converter fitted to the micro images (convert.grid auto on a
    frame whose check reads a drift: tspc-like-s96's 2.97 px) lays the views out on that
    lattice: the ground truth takes its size (the views are that size; the cameras were
    the file grid's, 2 px narrower, and Table I stopped), samples its sensor points, and
    traces them through the simulated lenses, the file's. With the lattice moved by a
    pure shift (dx, dy), the central view samples every lens (dx, dy) off its micro
    image's centre: its camera sits off the axis on the main-lens plane by -L/s times the
    shift on the sensor, as a view of offset (dx, dy) does (test_ground_truth_structure_
    by_hand); traced through the moved centres it would stay on the axis. The file's own
    grid given as a separate object gives the same bytes as none."""
    from plenocal.io.raytrix import read_calib  # noqa: PLC0415

    sim = small_sim(320, 240)
    setup_dataset(sim, tmp_path)
    optics = optics_of(sim)
    calib = read_calib(tmp_path / "calib.xml")
    shift = np.array([1.5, -0.8])

    def moved(c, w, h):
        g = MicrolensGrid(c, w, h)
        return MicrolensGrid(c, w, h, lattice=(g.origin + shift, g.A))

    plain, same, off = (tmp_path / n / "cameras.json" for n in ("plain", "same", "off"))
    ground_truth_cameras(tmp_path, ["x00_y00"], 3, 6, None, plain, log=lambda m: None)
    ground_truth_cameras(tmp_path, ["x00_y00"], 3, 6, None, same, log=lambda m: None,
                         grid_of=lambda c, w, h: MicrolensGrid(c, w, h))
    assert same.read_bytes() == plain.read_bytes()
    said = []
    ground_truth_cameras(tmp_path, ["x00_y00"], 3, 6, None, off, log=said.append,
                         grid_of=moved)
    assert any("the views' grid lies up to 1.70 px" in m for m in said), said
    layout = make_layout(moved(calib, optics.width, optics.height), 3, 6, even=True)
    cams = read_cameras(off)
    assert {(c.width, c.height) for c in cams.values()} == {(layout.width, layout.height)}
    M = np.asarray(yaml.safe_load((tmp_path / "truth" / "shots.json").read_text())
                   ["x00_y00"]["cam_to_world"])
    centre = np.linalg.inv(M) @ np.append(cams["x00_y00/1_1"].centre, 1.0)
    x0, y0 = optics.sensor_to_metric(np.float64(100.0), np.float64(100.0))
    x1, y1 = optics.sensor_to_metric(100.0 + shift[0], 100.0 + shift[1])
    want = -optics.L / optics.s * np.array([x1 - x0, y1 - y0])
    np.testing.assert_allclose(centre[:2], want, rtol=1e-6, atol=1e-12)
    assert np.linalg.norm(want) > 1e-5  # a tenth of a millimetre off the axis or more
    plain_centre = np.linalg.inv(M) @ np.append(read_cameras(plain)["x00_y00/1_1"].centre,
                                                1.0)
    np.testing.assert_allclose(plain_centre[:2], 0.0, atol=1e-12)
