"""The simulator's physics (issue 2, item 6); the ground truth: test_groundtruth.py."""

from __future__ import annotations

import copy
import dataclasses
import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from plenocal.config import validate_config
from plenocal.grid import MicrolensGrid
from plenocal.io.files import read_image, to_float
from plenocal.io.raytrix import read_calib, write_calib
from plenocal.optics import PlenopticOptics
from plenocal.simulate.dataset import (
    make_calib,
    make_shots,
    nearest_lens_map,
    render_shot,
    setup_dataset,
)
from plenocal.simulate.mla import lens_type_map
from plenocal.simulate.raytrace import prepare_lenslet, render_lenslet, trace_lenslet
from plenocal.simulate.scene import SceneArrays, pack_textures, scene_arrays
from plenocal.simulate.sensor import natural_vignetting, read_out

ROOT = Path(__file__).resolve().parents[1]
# a real pi/2 Raytrix file (shared/fixtures/raytrix-calib/Fujita2.xml), to 6 decimals
FUJITA = {"lens_base_x": (0.0, 1.0), "lens_base_y": (0.866025, 0.5),
          "sub_grid_base": (1.732051, 3.0), "offsets": [(0.0, 0.0), (0.0, 1.0), (0.0, -1.0)]}


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


def neighbour_shift(img: np.ndarray, grid: MicrolensGrid, half: int = 3,
                    cand: np.ndarray | None = None) -> float:
    """Median horizontal shift of content between each lens and its right neighbour,
    by sub-pixel NCC over candidate shifts along the lattice row (default: positive
    shifts, inverted micro images; negative ones: upright micro images)."""
    import cv2

    gray = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY).astype(np.float32)
    inside = grid.inside(2.0)
    shifts = []
    cand = np.arange(1.0, 14.0, 0.02) if cand is None else cand
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


@pytest.mark.parametrize("camera", [
    {},  # the tests' own camera
    # bench_accuracy's tspc-like: a 25 mm main lens, where the physical virtual depth a / s
    # and the file's D / P part by 15-19 %, and the scene's far end fell off the range
    {"main_lens": {"focal_length_mm": 25.0, "focus_distance_m": 0.45},
     "scene": {"near_m": 0.35, "far_m": 0.6}, "mla": {"pitch_um": 300.0, "k": 4.0}},
    # the same with a Galilean MLA: the conventions part the other way (the physical range
    # held this scene too, with 7 % of room at its far end where the new one has 18 %)
    {"main_lens": {"focal_length_mm": 25.0, "focus_distance_m": 0.45},
     "scene": {"near_m": 0.35, "far_m": 0.6},
     "mla": {"pitch_um": 300.0, "k": 4.0, "kind": "galilean"}},
])
def test_single_type_range_covers_the_scene_as_the_converter_reads_it(camera: dict):
    """A single lens type's depth range is the scene's, with a margin, in virtual depths as
    the converter reads them: its candidate patch sizes (P = D / v) hold the exact
    micro-image disparity of the scene's nearest and farthest points, with room to spare
    (a best match at the search's end is not trusted)."""
    from plenocal.convert.patchsize import PatchSizeSettings, type_ranges

    sim = small_sim()
    for key, value in camera.items():
        sim[key].update(value)
    optics = optics_of(sim)
    calib = make_calib(sim, optics)
    assert len(calib.lens_types) == 1
    lo, hi, notes = type_ranges(MicrolensGrid(calib, optics.width, optics.height),
                                PatchSizeSettings())
    assert not notes
    near, far = (abs(float(optics.micro_image_disparity_px(sim["scene"][k])))
                 for k in ("near_m", "far_m"))
    assert lo[0] < 0.95 * far and 1.05 * near < hi[0]
    # the two conventions part on these cameras by more than a few percent
    far_m = sim["scene"]["far_m"]
    ratio = optics.measured_virtual_depth(far_m) / abs(optics.virtual_depth(far_m))
    assert abs(ratio - 1) > 0.02


def test_dataset_files(tmp_path: Path):
    sim = small_sim()
    setup_dataset(sim, tmp_path)
    cam = yaml.safe_load((tmp_path / "camera.yaml").read_text())
    assert cam["mla"]["pitch_mm"] == pytest.approx(0.13)
    assert cam["scene"]["near_mm"] == pytest.approx(470)
    from plenocal.io.raytrix import read_calib

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
    # the optics read back are the optics written; a file without one of them is refused
    from plenocal.simulate.dataset import optics_from_truth

    assert optics_from_truth(tmp_path / "truth" / "optics.json") == optics
    doc = json.loads((tmp_path / "truth" / "optics.json").read_text())
    del doc["mla_f_number"]
    (tmp_path / "old.json").write_text(json.dumps(doc))
    with pytest.raises(ValueError, match="old.json: no mla_f_number.*simulate_setup"):
        optics_from_truth(tmp_path / "old.json")


def test_shots_array_on_the_stage_and_hand_held_orbiting_the_scene():
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


def test_the_hand_held_poses_can_take_another_seeds_turns():
    """simulate.handheld.seed: the scene of one seed shot with another seed's turns and
    offsets (a diagnostic); absent, the poses are the seed's own, as before."""
    sim = small_sim()
    centre = np.array([0.01, 0.005, 0.6])
    other = copy.deepcopy(sim)
    other["seed"] = sim["seed"] + 5
    crossed = copy.deepcopy(sim)
    crossed["handheld"]["seed"] = other["seed"]
    own, theirs, got = (make_shots(s, centre) for s in (sim, other, crossed))
    for name in own:
        want = theirs if name.startswith("hand") else own
        assert got[name].tobytes() == want[name].tobytes(), name
    assert own["hand00"].tobytes() != theirs["hand00"].tobytes()
    same = copy.deepcopy(sim)
    same["handheld"]["seed"] = sim["seed"]
    assert all(make_shots(same, centre)[n].tobytes() == own[n].tobytes() for n in own)


# --- the Raytrix-like camera: multi-focus MLA, turned grid, noise (issue 13) ----------

RAYTRIX_ROTATION = math.pi / 2 + 0.001


def raytrix_sim(width=240, height=200, **mla) -> dict:
    sim = small_sim(width, height)
    sim["mla"].update({"lens_types": 3, "rotation_rad": RAYTRIX_ROTATION, **mla})
    return sim


def texture_plane(z: float, texel: float, texture: np.ndarray | None = None) -> SceneArrays:
    """A fronto-parallel plane at depth z with a seeded random texture (the same detail
    everywhere, so that every lens sees statistically the same content)."""
    if texture is None:
        rng = np.random.default_rng(0)
        texture = cv2.GaussianBlur(rng.random((256, 256)).astype(np.float32), (0, 0), 1.0)
    tex = np.repeat(texture[:, :, None], 3, axis=2)
    w = 0.4
    return SceneArrays(p0=np.array([[-w / 2, -w / 2, z]]), u=np.array([[w, 0.0, 0.0]]),
                       v=np.array([[0.0, w, 0.0]]), normal=np.array([[0.0, 0.0, 1.0]]),
                       tex_id=np.array([0]), texel=np.array([texel]),
                       **pack_textures([tex]))


def test_calib_xml_is_written_as_raytrix_writes_a_turned_multi_focus_mla(tmp_path: Path):
    sim = raytrix_sim()
    setup_dataset(sim, tmp_path)
    calib = read_calib(tmp_path / "calib.xml")
    # the layout of the real pi/2 files: rotation and base vectors turned together
    assert calib.rotation == pytest.approx(RAYTRIX_ROTATION, abs=1e-12)
    for key in ("lens_base_x", "lens_base_y", "sub_grid_base"):
        np.testing.assert_allclose(getattr(calib, key), FUJITA[key], atol=1e-6)
    for mine, real in zip(calib.lens_types, FUJITA["offsets"], strict=True):
        np.testing.assert_allclose(mine.offset, real, atol=1e-6)
    optics = optics_of(sim)
    sharp = [1.0 / optics.type_kappa(i) for i in range(3)]
    ranges = [(t.depth_min, t.depth_max) for t in calib.lens_types]
    assert sharp[0] < sharp[1] < sharp[2]
    for (lo, hi), v in zip(ranges, sharp, strict=True):
        assert lo < v < hi
    # neighbouring types overlap a little; the outer ends open as Raytrix writes them
    assert ranges[0][0] == 1.0 and ranges[2][1] == 100.0
    for a, b in ((0, 1), (1, 2)):
        assert 0 < ranges[a][1] - ranges[b][0] < 0.5
    # the types cover the scene
    v_scene = [optics.virtual_depth(z) for z in (sim["scene"]["near_m"], sim["scene"]["far_m"])]
    assert ranges[0][0] < min(v_scene) and max(v_scene) < ranges[2][1]
    # interleaving: a third of the lenses per type, no two neighbours of one type
    grid = MicrolensGrid(calib, optics.width, optics.height)
    counts = np.bincount(grid.types, minlength=3)
    assert counts.min() >= 0.25 * len(grid)
    nb = grid.neighbours
    has = nb >= 0
    assert has.sum() > 3 * len(grid)
    assert not (grid.types[nb[has]] == np.repeat(grid.types, 6).reshape(-1, 6)[has]).any()
    # datasheet: the three F-numbers, the middle one the reference type's
    cam = yaml.safe_load((tmp_path / "camera.yaml").read_text())
    fns = cam["mla"]["f_numbers"]
    assert len(fns) == 3 and sorted(fns)[1] == sim["mla"]["f_number"]


@pytest.mark.parametrize("type_sharp", [0, 1, 2])
def test_each_lens_type_is_sharpest_at_its_own_depth(tmp_path: Path, type_sharp):
    """Render with the simulator's calib, measure with the types the file gives back:
    at the virtual depth where type i is in focus its micro images are the sharpest, and
    the others lose sharpness in the order of their predicted blur discs."""
    sim = raytrix_sim()
    optics = optics_of(sim)
    calib = make_calib(sim, optics)
    lens_map = nearest_lens_map(MicrolensGrid(calib, optics.width, optics.height))
    v = 1.0 / optics.type_kappa(type_sharp)
    z = float(optics.depth_from_virtual_depth(v))
    img = render_lenslet(texture_plane(z, 0.0003), optics, lens_map, np.eye(4), 16, 0,
                         lens_types=lens_type_map(calib, lens_map)).mean(axis=2)
    write_calib(calib, tmp_path / "calib.xml")
    grid = MicrolensGrid(read_calib(tmp_path / "calib.xml"), optics.width, optics.height)
    lap = cv2.Laplacian(img.astype(np.float32), cv2.CV_32F) ** 2
    ys, xs = np.mgrid[0:optics.height, 0:optics.width]
    sharpness = np.zeros(3)
    for k in range(3):
        vals = [lap[np.hypot(xs - c[0], ys - c[1]) < 0.3 * grid.diameter].mean()
                for c, t, ok in zip(grid.centres, grid.types, grid.inside(), strict=True)
                if t == k and ok]
        assert len(vals) >= 8
        sharpness[k] = np.mean(vals)
    blur = np.array([optics.blur_px(v, k) for k in range(3)])
    assert blur[type_sharp] == pytest.approx(0.0, abs=1e-9)
    assert int(np.argmax(sharpness)) == type_sharp, (sharpness, blur)
    assert sharpness[type_sharp] > 1.2 * np.delete(sharpness, type_sharp).max()
    if type_sharp != 1:  # the middle type's neighbours blur alike (1.9 px both)
        assert list(np.argsort(-sharpness)) == list(np.argsort(blur)), (sharpness, blur)


@pytest.mark.parametrize("rotation", [RAYTRIX_ROTATION, 0.02])
def test_turned_grid_puts_micro_images_where_the_xml_says(tmp_path: Path, rotation):
    """A white plane: every micro image is a symmetric disc around its centre; measured
    centroids sit on the lattice of the written calib.xml, not on an unturned one."""
    sim = raytrix_sim(rotation_rad=rotation)
    optics = optics_of(sim)
    setup_dataset(sim, tmp_path)
    calib = read_calib(tmp_path / "calib.xml")
    grid = MicrolensGrid(calib, optics.width, optics.height)
    white = texture_plane(0.6, 0.001, np.ones((8, 8), dtype=np.float32))
    img = render_lenslet(white, optics, nearest_lens_map(grid), np.eye(4), 16, 0,
                         lens_types=lens_type_map(calib, nearest_lens_map(grid))).mean(axis=2)
    ys, xs = np.mgrid[0:optics.height, 0:optics.width]
    err = []
    for c in grid.centres[grid.inside(1.0)]:
        # intensity centroid under a smooth window centred on the xml's centre
        w = img * np.exp(-((xs - c[0]) ** 2 + (ys - c[1]) ** 2) / (0.2 * grid.diameter) ** 2)
        err.append(np.hypot((xs * w).sum() / w.sum() - c[0], (ys * w).sum() / w.sum() - c[1]))
    assert len(err) >= 30 and np.mean(err) < 0.03 and max(err) < 0.08, (np.mean(err), max(err))
    # the test can fail: an unturned grid misses the micro images
    unturned = MicrolensGrid(dataclasses.replace(calib, rotation=0.0), optics.width,
                             optics.height)
    near = np.linalg.norm(unturned.centres[:, None] - grid.centres[None], axis=2).min(axis=1)
    assert near.max() > 1.0  # 12x the tolerance above


def test_sensor_noise_is_seeded_and_12_bit_data_spans_its_range(tmp_path: Path):
    sim = raytrix_sim(160, 120)
    sim["sensor"].update(bit_depth=12, full_well_e=13500, noise_std=0.001)
    setup_dataset(sim, tmp_path)
    for name in ("a", "b"):
        render_shot(sim, tmp_path, "hand01", tmp_path / f"{name}.png", log=lambda m: None)
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "b.png").read_bytes()
    other = copy.deepcopy(sim)
    other["seed"] += 1
    render_shot(other, tmp_path, "hand01", tmp_path / "c.png", log=lambda m: None)
    assert (tmp_path / "a.png").read_bytes() != (tmp_path / "c.png").read_bytes()
    img = read_image(tmp_path / "a.png")
    assert img.dtype == np.uint16 and (img % 16 == 0).all()  # 12 bits, MSB-aligned
    assert len(np.unique(img)) > 1000  # more levels than 8 bits hold
    # the full 12-bit range: a ramp from black to white, every level once
    ramp = np.linspace(0.0, 1.0, 4096, dtype=np.float32)[None, :, None]
    out = read_out(ramp, np.random.default_rng(0), 0.0, None, 12)
    assert out.min() == 0 and out.max() == 4095 << 4 and len(np.unique(out)) == 4096
    # shot + read noise: the variance of a flat field is x / full_well + sigma^2
    flat = np.full((200, 200, 3), 0.5, dtype=np.float32)
    dn = read_out(flat, np.random.default_rng(1), 0.001, 13500, 12).astype(float) / 65520
    assert dn.std() == pytest.approx(math.sqrt(0.5 / 13500 + 0.001 ** 2), rel=0.05)
    assert dn.mean() == pytest.approx(0.5, abs=1e-3)



def test_compiled_12_bit_readout_gives_the_bits_of_numpy_passes():
    """The 12-bit readout with shot noise runs as one compiled pass: the same uint16 values
    as numpy's whole-image passes of the noise model (the same normals), over and under
    the range, at -0, 0 and 1."""
    x = np.random.default_rng(3).uniform(-0.1, 1.1, (37, 53, 3)).astype(np.float32)
    x[0, 0] = [-0.0, 0.0, 1.0]
    full_well, sigma = 13500.0, 0.00096
    z = np.random.default_rng([7, 1]).standard_normal(x.shape, dtype=np.float32)
    var = np.clip(x, 0.0, None) * np.float32(1.0 / full_well) + np.float32(sigma ** 2)
    dn = np.clip(np.rint((x + np.sqrt(var) * z) * np.float32(4095.0)), 0, 4095)
    expected = dn.astype(np.uint16) << 4
    got = read_out(x, np.random.default_rng([7, 1]), sigma, full_well, 12)
    assert got.dtype == np.uint16 and got.shape == x.shape
    np.testing.assert_array_equal(got, expected)
    assert got.min() == 0 and got.max() == 4095 << 4

def test_vignetting_darkens_the_sensor_edges():
    """cos^4 of the chief ray and a front stop: the sensor's edges are darker than its
    centre, the centre is untouched by the stop."""
    sim = small_sim(2048, 24)
    optics = optics_of(sim)
    grid = MicrolensGrid(make_calib(sim, optics), optics.width, optics.height)
    lens_map = nearest_lens_map(grid)
    cos4 = natural_vignetting(optics, lens_map)
    r = np.hypot(*optics.sensor_to_metric(lens_map[..., 0], lens_map[..., 1]))
    r_lens = r * optics.L / (optics.L + optics.s)
    np.testing.assert_allclose(cos4, np.cos(np.arctan(r_lens / optics.L)) ** 4, rtol=1e-5)
    white = texture_plane(0.6, 0.001, np.ones((8, 8), dtype=np.float32))
    plain = render_lenslet(white, optics, lens_map, np.eye(4), 16, 0).mean(axis=2)
    stopped = render_lenslet(white, optics, lens_map, np.eye(4), 16, 0, stop_distance=0.01,
                             stop_diameter=optics.aperture).mean(axis=2)
    farther = render_lenslet(white, optics, lens_map, np.eye(4), 16, 0, stop_distance=0.02,
                             stop_diameter=optics.aperture).mean(axis=2)
    centre, edge = slice(984, 1064), slice(0, 80)
    assert stopped[:, centre].mean() == pytest.approx(plain[:, centre].mean(), rel=0.02)
    assert stopped[:, edge].mean() < 0.95 * plain[:, edge].mean()
    assert farther[:, edge].mean() < 0.9 * stopped[:, edge].mean()  # a deeper barrel clips more


def test_galilean_micro_images_are_upright():
    """Galilean: the main-lens image lies behind the MLA; a point moves against the lens
    step across neighbouring micro images (upright), by the predicted disparity."""
    sim = small_sim()
    sim["mla"]["kind"] = "galilean"
    optics = optics_of(sim)
    assert optics.galilean and optics.t < 0
    z = float(optics.depth_from_virtual_depth(-4.0))
    assert 0.4 < z < 0.9
    calib = make_calib(sim, optics)
    assert calib.lens_types[0].depth_min > 0  # magnitudes, as the TSPC files write them
    grid = MicrolensGrid(calib, optics.width, optics.height)
    img = render_lenslet(scene_arrays(plane_scene(z)), optics, nearest_lens_map(grid),
                         np.eye(4), 8, 0)
    img8 = np.clip(img * 255, 0, 255).astype(np.uint8)
    expected = float(optics.micro_image_disparity_px(z))
    assert expected < -1.0
    measured = neighbour_shift(img8, grid, cand=np.arange(-14.0, -1.0, 0.02))
    assert abs(measured - expected) < 0.15, (measured, expected)


@pytest.mark.parametrize("kind,ratios,bad_type", [("keplerian", [0.94, 1.3], 2),
                                                  ("galilean", [0.8, 1.1], 0)])
def test_a_lens_type_that_images_no_plane_is_refused(kind, ratios, bad_type):
    sim = raytrix_sim(kind=kind, focal_ratios=ratios)
    with pytest.raises(ValueError, match=f"focal_ratios: lens type {bad_type} "):
        optics_of(sim)


def test_white_image_flat_fields_the_vignetting(tmp_path: Path):
    """The white image carries the falloff of the main lens (cos^4 and the front stop):
    a white plane's shot divided by it is flat from the centre to the edge."""
    from plenocal.simulate.dataset import _trace_shot, render_white, sensor_truth

    sim = raytrix_sim(2048, 24)
    sim["main_lens"]["vignetting"] = {"cos4": True, "stop_distance_mm": 10.0,
                                      "stop_diameter_scale": 1.0}
    sim["sensor"]["bit_depth"] = 12
    setup_dataset(sim, tmp_path)
    render_white(sim, tmp_path, tmp_path / "white.png")
    white = to_float(read_image(tmp_path / "white.png")).mean(axis=2)
    optics = optics_of(sim)
    calib = read_calib(tmp_path / "calib.xml")
    lens_map = nearest_lens_map(MicrolensGrid(calib, optics.width, optics.height))
    shot = _trace_shot(sim, optics, texture_plane(0.6, 0.001, np.full((8, 8), 0.7, np.float32)),
                       lens_map, lens_type_map(calib, lens_map), np.eye(4),
                       sensor_truth(sim)).mean(axis=2)
    r = np.hypot(*(np.mgrid[0:24, 0:2048][::-1] - np.moveaxis(lens_map, 2, 0)))
    core = r < 0.4 * calib.diameter  # every micro image, less its dark rim
    centre, edge = core & (np.arange(2048) > 900) & (np.arange(2048) < 1148), core.copy()
    edge[:, 100:] = False
    assert white[centre].mean() > 0.9
    assert white[edge].mean() < 0.93 * white[centre].mean()  # the falloff is in the image
    flat = shot / np.maximum(white, 1e-3)
    assert flat[edge].mean() == pytest.approx(flat[centre].mean(), rel=0.02)
    assert flat[centre].mean() == pytest.approx(0.7, rel=0.02)


def test_texture_files_read_as_scikit_image_reads_them():
    """The scenes' photographs, read from scikit-image's files with OpenCV (no skimage.io
    import), have the pixels of ``skimage.data.<name>()``: the lenslet images stay the same."""
    import skimage.data

    from plenocal.simulate.scene import TEXTURE_FILES, texture_pixels

    for name in TEXTURE_FILES:
        want = getattr(skimage.data, name)()
        got = texture_pixels(name)
        assert got.dtype == np.uint8 and got.shape == want[:, :, :3].shape, name
        np.testing.assert_array_equal(got, want[:, :, :3], err_msg=name)


def test_textures_are_the_same_bits_whichever_code_opencv_would_pick():
    """The scenes' textures are blurred in numpy's float32 operations, not by OpenCV, whose
    blur takes its code by the CPU (its optimised and baseline paths differ by 1-2 float32
    steps on a third of the texels): the same textures with OpenCV's optimised code on or
    off, and the same Gaussian as OpenCV's blur, to a few float32 steps."""
    import cv2

    from plenocal.simulate.scene import TEXTURE_FILES, gaussian_blur, load_texture

    names = sorted(TEXTURE_FILES)[:3]
    was = cv2.useOptimized()
    try:
        cv2.setUseOptimized(True)
        fast = [load_texture(n) for n in names]
        cv2.setUseOptimized(False)
        plain = [load_texture(n) for n in names]
    finally:
        cv2.setUseOptimized(was)
    for name, a, b in zip(names, fast, plain, strict=True):
        np.testing.assert_array_equal(a, b, err_msg=name)
    img = np.random.default_rng(3).random((60, 70, 3)).astype(np.float32)
    for sigma in (0.7, 1.0, 1.5):
        np.testing.assert_allclose(gaussian_blur(img, sigma),
                                   cv2.GaussianBlur(img, (0, 0), sigma), atol=1e-6)


def test_bounding_boxes_skip_nothing_that_a_ray_hits(tmp_path: Path):
    """The tracers skip what no ray of theirs can hit - a lenslet pixel's rays test only
    the quads its microlens's bundle reaches (_bundle_candidates), an ideal render's
    rays skip a box's faces where they miss the box (quad_groups) - and give the same
    bits as with every quad tested for every ray: lenslet images of a hand-held and an
    array shot (Keplerian and Galilean, with and without a front stop) and an ideal
    render with its depth; the default scene's runs are the background, the slanted
    plane and the three boxes."""
    import json

    from plenocal.simulate.dataset import optics_from_truth
    from plenocal.simulate.raytrace import (
        quad_groups,
        quad_table,
        render_pinhole,
        single_quad_groups,
    )

    sim = small_sim(240, 180)
    setup_dataset(sim, tmp_path)
    truth = tmp_path / "truth"
    scene = scene_arrays(json.loads((truth / "scene.json").read_text()))
    quads = quad_table(scene)
    groups = quad_groups(quads)
    assert [(int(g[0]), int(g[1])) for g in groups] == [(0, 1), (1, 2), (2, 7), (7, 12),
                                                        (12, 17)]
    optics = optics_from_truth(truth / "optics.json")
    grid = MicrolensGrid(read_calib(tmp_path / "calib.xml"), optics.width, optics.height)
    lm = nearest_lens_map(grid)
    shots = json.loads((truth / "shots.json").read_text())
    galilean = dataclasses.replace(optics, kind="galilean")
    for name, opt, stop in [("hand01", optics, 0.0), ("x00_y00", optics, 0.0),
                            ("hand03", optics, 0.01), ("x01_y00", galilean, 0.0)]:
        shot = np.asarray(shots[name]["cam_to_world"])
        kw = {"stop_distance": stop, "stop_diameter": 0.8 * opt.aperture if stop else 0.0}
        fast = render_lenslet(scene, opt, lm, shot, 4, 0, **kw)
        every = render_lenslet(scene, opt, lm, shot, 4, 0, cull=False, **kw)
        np.testing.assert_array_equal(fast, every, err_msg=name)
        assert fast.std() > 0.05, name
        # one set-up for every shot of a camera (render_shots) traces the same image
        setup = prepare_lenslet(scene, opt, lm, 4, 0)
        np.testing.assert_array_equal(trace_lenslet(setup, scene, shot, **kw), fast,
                                      err_msg=name)
    shot = np.asarray(shots["hand01"]["cam_to_world"])
    K = np.array([[300.0, 0, 119.5], [0, 300.0, 89.5], [0, 0, 1]])
    img, z = render_pinhole(scene, K, shot, 240, 180, 2)
    img1, z1 = render_pinhole(scene, K, shot, 240, 180, 2, groups=single_quad_groups(len(quads)))
    np.testing.assert_array_equal(img, img1)
    np.testing.assert_array_equal(z, z1)
    assert (z > 0).mean() > 0.9


def test_bundle_culling_keeps_the_reachable_quads_only():
    """A hand-computed case of _bundle_candidates: L = 40 mm, F = 35 mm (kappa = 1/L -
    1/F = -1/280 per mm), main-lens aperture radius 5 mm, microlens radius 0.1 mm. At
    z = 280 mm the bundle of the lens at (lx, ly) = (0.4, 0) mm is the disc of centre
    -(z / L) lx = -2.8 mm and radius 0 * 5 + 7 * 0.1 = 0.7 mm (x in [-3.5, -2.1] mm): a
    quad over x in [-2.15, 10] mm is reached, one over [-2.0, 10] mm is not; one behind
    the camera never is; a deep quad is kept when its far end's disc reaches it."""
    from plenocal.simulate.raytrace import _bundle_candidates

    def boxes(*rows):
        return np.array(rows, dtype=np.float64)

    mm = 1e-3
    args = (0.4 * mm, 0.0, 40 * mm, 1 / (40 * mm) - 1 / (35 * mm), 5 * mm, 0.1 * mm)
    z = 280 * mm
    b = boxes([-2.15 * mm, 10 * mm, -1 * mm, 1 * mm, z, z],  # reached (edge at -2.1)
              [-2.0 * mm, 10 * mm, -1 * mm, 1 * mm, z, z],  # 0.1 mm beyond the edge
              [-10 * mm, 10 * mm, -10 * mm, 10 * mm, -0.5, -0.1],  # behind the camera
              [-2.0 * mm, 10 * mm, -1 * mm, 1 * mm, z, 0.6])  # the far end reaches it
    cand = np.full(4, -1, dtype=np.int64)
    n = _bundle_candidates(*args, b, cand)
    assert n == 2 and list(cand[:2]) == [0, 3]
    # at z = 600 mm: centre -6 mm, radius |1 - 600/280| 5 + 15 * 0.1 = 7.214 mm
    far = boxes([0.8 * mm, 10 * mm, -1 * mm, 1 * mm, 0.6, 0.6],
                [1.3 * mm, 10 * mm, -1 * mm, 1 * mm, 0.6, 0.6])
    assert _bundle_candidates(*args, far, cand) == 1 and cand[0] == 0


def _small_camera(tmp_path: Path):
    """A 64 x 48 sensor's dataset in ``tmp_path``: (scene arrays, optics, per-pixel lens
    centres, shots' cam_to_world by name)."""
    import json

    from plenocal.simulate.dataset import optics_from_truth

    setup_dataset(small_sim(64, 48), tmp_path)
    truth = tmp_path / "truth"
    scene = scene_arrays(json.loads((truth / "scene.json").read_text()))
    optics = optics_from_truth(truth / "optics.json")
    lm = nearest_lens_map(MicrolensGrid(read_calib(tmp_path / "calib.xml"), optics.width,
                                        optics.height))
    shots = json.loads((truth / "shots.json").read_text())
    return scene, optics, lm, {k: np.asarray(v["cam_to_world"]) for k, v in shots.items()}


def test_fast_math_lenslet_kernel_traces_what_strict_arithmetic_does(tmp_path: Path,
                                                                     monkeypatch):
    """The lenslet kernel is compiled with LLVM's fast-math flags (LENSLET_FASTMATH: fused
    multiply-adds, reciprocals, reassociation; not nnan/ninf): its image equals, to well
    under a float32 step, the one its own source gives with IEEE arithmetic (numba's
    py_func, whose helpers are compiled without fast-math) - for a Keplerian shot and a
    Galilean one through a front stop."""
    from plenocal.simulate import raytrace

    assert {"nnan", "ninf"}.isdisjoint(raytrace.LENSLET_FASTMATH)
    scene, optics, lm, shots = _small_camera(tmp_path)
    galilean = dataclasses.replace(optics, kind="galilean")
    for name, opt, stop in [("x00_y00", optics, 0.0), ("hand02", galilean, 0.01)]:
        shot = shots[name]
        kw = {"stop_distance": stop, "stop_diameter": 0.8 * opt.aperture if stop else 0.0}
        setup = prepare_lenslet(scene, opt, lm, 4, 0)
        fast = trace_lenslet(setup, scene, shot, **kw)
        with monkeypatch.context() as m:
            m.setattr(raytrace, "_render_lenslet", raytrace._render_lenslet.py_func)
            strict = trace_lenslet(setup, scene, shot, **kw)
        assert strict.std() > 0.02, name  # the scene is in the picture
        np.testing.assert_allclose(fast, strict, rtol=0, atol=1e-6, err_msg=name)


def _nearest_quad_hit(scene, o: np.ndarray, d: np.ndarray) -> tuple[int, float, float, float]:
    """The nearest quad the ray ``o + t d`` hits (first of equals), by plain numpy: (quad or
    -1, t, texel coordinates along U and V in metres)."""
    den = scene.normal @ d
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.einsum("qi,qi->q", scene.normal, scene.p0 - o) / den
        r = o + t[:, None] * d - scene.p0
        a = np.einsum("qi,qi->q", r, scene.u) / np.einsum("qi,qi->q", scene.u, scene.u)
        b = np.einsum("qi,qi->q", r, scene.v) / np.einsum("qi,qi->q", scene.v, scene.v)
    ok = (np.abs(den) >= 1e-12) & (t > 1e-9) & (a >= 0) & (a <= 1) & (b >= 0) & (b <= 1)
    if not ok.any():
        return -1, -1.0, 0.0, 0.0
    q = int(np.flatnonzero(ok)[np.argmin(t[ok])])
    return (q, float(t[q]), float(a[q] * np.linalg.norm(scene.u[q])),
            float(b[q] * np.linalg.norm(scene.v[q])))


def test_lenslet_pixels_are_the_mean_of_their_rays_traced_one_by_one(tmp_path: Path):
    """The lenslet kernel handles a pixel's rays lane by lane (generation, each candidate
    quad against all of them, then the colours): every pixel equals the mean of its rays
    traced one at a time here - the kernel's sample pattern through the microlens, the
    main lens and a front stop (a ray they stop adds nothing), the nearest hit among all
    quads by plain numpy, and the texture lookup (:func:`raytrace._shade`)."""
    import math

    from plenocal.simulate import raytrace

    scene, optics, lm, shots = _small_camera(tmp_path)
    shot = shots["hand02"]
    st = prepare_lenslet(scene, optics, lm, 5, 0)
    R, C = shot[:3, :3], shot[:3, 3]
    ns = len(st.jitter)
    rgb = np.empty(3)
    # the main lens alone, then with a front stop that clips more
    for stop_z, stop_half, clipped_by in [(0.0, 0.0, "aperture"), (0.01, 0.4 * optics.aperture,
                                                                   "stop")]:
        img = trace_lenslet(st, scene, shot, stop_distance=stop_z, stop_diameter=2 * stop_half)
        ref = np.zeros(img.shape)
        stopped = {"aperture": 0, "stop": 0}
        for row in range(st.height):
            for col in range(st.width):
                lens = np.array([st.lens_x[row, col], st.lens_y[row, col]])
                t = st.t_types[st.lens_types[row, col]]
                rot = (row * 7919 + col * 104729) % ns
                for k in range(ns):
                    jx, jy = st.jitter[(k + rot) % ns]
                    sensor = -np.array([col + jx - (st.width - 1) / 2,
                                        row + jy - (st.height - 1) / 2]) * st.pixel_size
                    m = lens + st.half_lens * st.disk[k]
                    slope = (lens + (lens - sensor) * t / st.s - m) / t
                    h = m + slope * st.L
                    u = slope - h / st.F
                    if math.hypot(*h) > st.half_aperture:
                        stopped["aperture"] += 1
                        continue
                    if stop_half > 0 and math.hypot(*(h + u * stop_z)) > stop_half:
                        stopped["stop"] += 1
                        continue
                    q, tt, ba, bb = _nearest_quad_hit(scene, R[:, :2] @ h + C,
                                                      R[:, :2] @ u + R[:, 2])
                    raytrace._shade(q, tt, ba, bb, scene.tex_id, scene.texel, scene.atlas,
                                    scene.tex_off, scene.tex_h, scene.tex_w, rgb)
                    ref[row, col] += rgb / ns
        assert stopped[clipped_by] > 0, stopped  # the test was exercised
        assert img.std() > 0.02  # the scene is in the picture
        np.testing.assert_allclose(img, ref, rtol=0, atol=1e-6, err_msg=clipped_by)


def test_pinhole_pixels_are_the_mean_of_their_rays_traced_one_by_one(tmp_path: Path):
    """The pinhole renderer takes a pixel's rays lane by lane too (a group of quads
    skipped where none of them meets its box): every pixel equals the mean of its
    ss x ss rays traced one at a time by a plain-numpy nearest hit, and its depth is
    the z of its centre ray's hit."""
    from plenocal.simulate import raytrace

    scene, _, _, shots = _small_camera(tmp_path)
    shot = shots["hand01"]
    W, H, ss = 40, 30, 2
    K = np.array([[60.0, 0, 19.5], [0, 60.0, 14.5], [0, 0, 1]])
    img, z = raytrace.render_pinhole(scene, K, shot, W, H, ss)
    Kinv, R, C = np.linalg.inv(K), shot[:3, :3], shot[:3, 3]
    rgb = np.empty(3)
    ref, ref_z = np.zeros(img.shape), np.zeros(z.shape)
    for row in range(H):
        for col in range(W):
            for i in range(ss):
                for j in range(ss):
                    ray = R @ Kinv @ [col - 0.5 + (j + 0.5) / ss, row - 0.5 + (i + 0.5) / ss, 1]
                    q, t, ba, bb = _nearest_quad_hit(scene, C, ray)
                    raytrace._shade(q, t, ba, bb, scene.tex_id, scene.texel, scene.atlas,
                                    scene.tex_off, scene.tex_h, scene.tex_w, rgb)
                    ref[row, col] += rgb / ss ** 2
            q, t, _, _ = _nearest_quad_hit(scene, C, R @ Kinv @ [col, row, 1.0])
            ref_z[row, col] = t if q >= 0 else 0.0  # K^-1 (u, v, 1) has camera z 1
    assert img.std() > 0.02 and (z > 0).mean() > 0.9
    np.testing.assert_allclose(img, ref, rtol=0, atol=1e-6)
    np.testing.assert_allclose(z, ref_z, rtol=1e-6, atol=0)


@pytest.mark.parametrize("samples", [1, 6, 12, 13])
def test_the_sample_pattern_is_centred(samples):
    """Every pixel traces the same jitter and disc points: a set off its centre moved
    every pixel's integration and every lens's ray bundle the same way (the views then
    sit 0.15-0.48 px and 0.05-0.09 mm from their true cameras at 12 samples)."""
    from plenocal.simulate.raytrace import sample_pattern

    for seed in range(8):
        jitter, disk = sample_pattern(samples, seed)
        assert jitter.shape == disk.shape == (samples, 2)
        assert np.abs(jitter.mean(axis=0)).max() < 1e-12
        assert np.abs(disk.mean(axis=0)).max() < 1e-12
        assert np.all(np.abs(jitter) <= 0.5) and np.hypot(*disk.T).max() <= 1.0
