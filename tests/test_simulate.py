"""The simulator's physics (issue 2, item 6); the ground truth: test_groundtruth.py."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml

from plenocal.config import validate_config
from plenocal.grid import MicrolensGrid
from plenocal.io import read_image, to_float
from plenocal.optics import PlenopticOptics
from plenocal.simulate.dataset import make_calib, nearest_lens_map, render_shot, setup_dataset
from plenocal.simulate.raytrace import render_lenslet
from plenocal.simulate.scene import scene_arrays

ROOT = Path(__file__).resolve().parents[1]


def small_sim(width=400, height=300) -> dict:
    cfg = validate_config(yaml.safe_load((ROOT / "tests" / "tiny" / "config.yaml").read_text()))
    sim = copy.deepcopy(cfg["datasets"]["tiny"]["simulate"])
    sim["sensor"].update(width=width, height=height, noise_std=0.0)
    sim["render"]["samples"] = 8
    return sim


def plane_scene(z: float) -> dict:
    w = 0.4
    return {"quads": [{"p0": [-w / 2, -w / 2, z], "u": [w, 0, 0], "v": [0, w, 0],
                       "texture": "astronaut", "texel_m": 0.0002}]}


def optics_of(sim: dict) -> PlenopticOptics:
    from plenocal.simulate.optics_setup import optics_from_config

    return optics_from_config(sim)


def neighbour_shift(img: np.ndarray, grid: MicrolensGrid, half: int = 3) -> float:
    """Median horizontal shift of content between each lens and its right neighbour,
    by sub-pixel NCC over candidate shifts along the lattice row."""
    import cv2

    gray = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY).astype(np.float32)
    inside = grid.inside(2.0)
    shifts = []
    cand = np.arange(1.0, 14.0, 0.02)
    ys, xs = np.mgrid[-half:half + 1, -half:half + 1].astype(np.float32)
    for i in np.flatnonzero(inside)[::7]:
        j = grid.neighbours[i, 0]  # right neighbour, +x
        if j < 0 or not inside[j]:
            continue
        ci, cj = grid.centres[i], grid.centres[j]
        scores = []
        for d in cand:
            # a point at offset x from lens i's micro-image centre appears at x + d in
            # the right neighbour (the content moves with the lens step); compare
            # blocks placed symmetrically so both stay in the unvignetted middle
            a = cv2.remap(gray, xs + np.float32(ci[0] - d / 2), ys + np.float32(ci[1]),
                          cv2.INTER_LINEAR)
            b = cv2.remap(gray, xs + np.float32(cj[0] + d / 2), ys + np.float32(cj[1]),
                          cv2.INTER_LINEAR)
            a = (a - a.mean()).ravel()
            b = (b - b.mean()).ravel()
            scores.append(a @ b / (np.linalg.norm(a) * np.linalg.norm(b) + 1e-9))
        if max(scores) < 0.5:
            continue
        k = int(np.argmax(scores))
        if 0 < k < len(cand) - 1:
            s0, s1, s2 = scores[k - 1], scores[k], scores[k + 1]
            off = 0.5 * (s0 - s2) / (s0 - 2 * s1 + s2)
            shifts.append(cand[k] + off * 0.02)
    return float(np.median(shifts))


@pytest.mark.parametrize("z", [0.5, 0.7])
def test_plane_gives_the_disparity_the_virtual_depth_predicts(z):
    sim = small_sim()
    optics = optics_of(sim)
    calib = make_calib(sim, optics)
    grid = MicrolensGrid(calib, optics.width, optics.height)
    img = render_lenslet(scene_arrays(plane_scene(z)), optics, nearest_lens_map(grid),
                         np.eye(4), 8, 0)
    img8 = np.clip(img * 255, 0, 255).astype(np.uint8)
    measured = neighbour_shift(img8, grid)
    expected = float(optics.micro_image_disparity_px(z))
    assert abs(measured - expected) < 0.1, (measured, expected)


def test_vignetting_darkens_micro_image_borders():
    sim = small_sim()
    optics = optics_of(sim)
    grid = MicrolensGrid(make_calib(sim, optics), optics.width, optics.height)
    img = render_lenslet(scene_arrays(plane_scene(0.6)), optics, nearest_lens_map(grid),
                         np.eye(4), 8, 0).mean(axis=2)
    ys, xs = np.mgrid[0:optics.height, 0:optics.width]
    lm = nearest_lens_map(grid)
    r = np.hypot(xs - lm[..., 0], ys - lm[..., 1]) / grid.diameter
    assert img[r < 0.25].mean() > 4 * img[r > 0.55].mean()


def test_rendering_is_deterministic(tmp_path: Path):
    sim = small_sim(240, 180)
    setup_dataset(sim, tmp_path)
    render_shot(sim, tmp_path, "hand01", tmp_path / "a.png", log=lambda m: None)
    render_shot(sim, tmp_path, "hand01", tmp_path / "b.png", log=lambda m: None)
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "b.png").read_bytes()
    img = to_float(read_image(tmp_path / "a.png"))
    assert img.shape == (180, 240, 3) and img.std() > 0.05


def test_dataset_files(tmp_path: Path):
    sim = small_sim()
    setup_dataset(sim, tmp_path)
    cam = yaml.safe_load((tmp_path / "camera.yaml").read_text())
    assert cam["mla"]["pitch_mm"] == pytest.approx(0.13)
    assert cam["scene"]["near_mm"] == pytest.approx(470)
    from plenocal.raytrix import read_calib

    calib = read_calib(tmp_path / "calib.xml")
    optics = optics_of(sim)
    assert calib.diameter == pytest.approx(optics.micro_image_pitch_px)
    lt = calib.lens_types[0]
    assert lt.depth_min < optics.virtual_depth(0.47) < optics.virtual_depth(0.74) < lt.depth_max
    shots = yaml.safe_load((tmp_path / "truth" / "shots.json").read_text())
    assert len(shots) == 3 * 2 + 4
    # a second setup with the same seed gives the same bytes
    setup_dataset(sim, tmp_path / "again")
    for f in ("calib.xml", "camera.yaml", "truth/scene.json", "truth/shots.json",
              "truth/optics.json"):
        assert (tmp_path / f).read_bytes() == (tmp_path / "again" / f).read_bytes(), f


def test_shots_array_on_the_stage_and_hand_held_orbiting_the_scene():
    from plenocal.simulate.dataset import make_shots

    sim = small_sim()
    centre = np.array([0.01, 0.005, 0.6])
    shots = make_shots(sim, centre)
    step = sim["array"]["step_m"]
    np.testing.assert_allclose(shots["x02_y01"][:3, 3], [2 * step, step, 0.0])
    np.testing.assert_allclose(shots["x02_y01"][:3, :3], np.eye(3))
    dist = np.linalg.norm(centre - [0.01, 0.005, 0.0])
    hh = sim["handheld"]
    for k in range(hh["count"]):
        M = shots[f"hand{k:02d}"]
        R, C = M[:3, :3], M[:3, 3]
        angle = np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1)))
        assert 0 < angle <= hh["max_rotation_deg"] + 1e-9
        # the optical axis passes the scene centre within the position offset
        to_centre = centre - C
        miss = np.linalg.norm(np.cross(R[:, 2], to_centre))
        assert miss <= np.sqrt(3) * hh["max_offset_m"] + 1e-12
        assert abs(R[:, 2] @ to_centre - dist) <= np.sqrt(3) * hh["max_offset_m"]
    assert make_shots(sim, centre)["hand01"].tobytes() == shots["hand01"].tobytes()
