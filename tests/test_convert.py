"""Converter (issue 3): patch sizes against the optics, view disparity against the
geometry, every Raytrix fixture converts, and the error cases."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest
from synth.lenslets import (
    calib_for_optics,
    lenslet_from_optics,
    lenslet_from_patch_size,
    plane_view,
    random_texture,
)

from plenocal.convert import ConvertError, ConvertSettings, ShotConversion, convert_files
from plenocal.convert.patchsize import estimate_patch_size, weighted_median
from plenocal.convert.quality import summarise, view_quality
from plenocal.convert.setup import decide_setup
from plenocal.convert.shot import mla_contradiction, mla_undecided
from plenocal.grid import MicrolensGrid
from plenocal.io.files import read_image, write_image
from plenocal.io.png import truncation as png_truncation
from plenocal.io.raytrix import LensType, RayCalib, read_calib, write_calib
from plenocal.names import view_names
from plenocal.optics import PlenopticOptics

FIXTURES = sorted(Path("/work/shared/fixtures/raytrix-calib").glob("*.xml"))
if not FIXTURES:  # the fixtures travel with the repository's shared folder
    FIXTURES = sorted((Path(__file__).parents[1] / "shared/fixtures/raytrix-calib").glob("*.xml"))


FIXED_TILE = ConvertSettings(tile_size=6, even_size=False)  # the layout of issue 3's tests


def small_optics(width: int = 400, height: int = 300) -> PlenopticOptics:
    """The default simulated camera (config.yaml), on a small sensor."""
    return PlenopticOptics(focal_length=0.035, focus_distance=0.6, mla_pitch=130e-6,
                           mla_f_number=2.8, k=5.0, pixel_size=5.5e-6, width=width,
                           height=height)


def patch6_shot(calib: RayCalib | None = None):
    """(calib, grid, shot): the small camera's frame with every patch 6 px, converted at
    :data:`FIXED_TILE` (``calib``: another calib.xml for the same sensor)."""
    calib = calib or calib_for_optics(small_optics(480, 300))
    grid = MicrolensGrid(calib, 480, 300)
    return calib, grid, ShotConversion(
        lenslet_from_patch_size(grid, 6.0, random_texture(512, 1.5, 4)), calib, 5, FIXED_TILE)


def plane_lenslet(opt: PlenopticOptics, depth: float, seed: int = 0):
    calib = calib_for_optics(opt)
    grid = MicrolensGrid(calib, opt.width, opt.height)
    texel = 3.0 * depth * opt.pixel_size / opt.focal_length  # ~3 view pixels per texel
    img = lenslet_from_optics(grid, opt, depth, random_texture(512, 1.5, seed), texel)
    return calib, grid, img


def measure_shift(a: np.ndarray, b: np.ndarray, axis: int, search: float = 4.0) -> float:
    """Sub-pixel shift s (pixels) along ``axis`` such that b(x + s) ~ a(x)."""
    a = cv2.cvtColor(a, cv2.COLOR_RGB2GRAY).astype(np.float32)
    b = cv2.cvtColor(b, cv2.COLOR_RGB2GRAY).astype(np.float32)
    m = int(np.ceil(search)) + 2
    ref = a[m:-m, m:-m]
    shifts = np.arange(-search, search + 1e-9, 0.05)
    cost = []
    for s in shifts:
        M = np.float32([[1, 0, s if axis == 0 else 0], [0, 1, s if axis == 1 else 0]])
        w = cv2.warpAffine(b, M, b.shape[::-1], flags=cv2.INTER_CUBIC | cv2.WARP_INVERSE_MAP)
        cost.append(float(((w[m:-m, m:-m] - ref) ** 2).mean()))
    k = int(np.argmin(cost))
    k = min(max(k, 1), len(cost) - 2)
    c0, c1, c2 = cost[k - 1], cost[k], cost[k + 1]
    return float(shifts[k] + 0.05 * 0.5 * (c0 - c2) / (c0 - 2 * c1 + c2))


# ---------------------------------------------------------------------------
# (1) patch size of a fronto-parallel plane = what the optics predict
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("depth", [0.5, 0.6, 0.7])
def test_patch_size_of_a_plane_matches_the_optics(depth):
    opt = small_optics()
    calib, grid, img = plane_lenslet(opt, depth)
    truth = opt.micro_image_disparity_px(depth)
    res = estimate_patch_size(img, grid)
    inner = grid.inside()
    assert abs(np.median(res.patch[inner]) - truth) < 0.05, (np.median(res.patch), truth)
    assert np.mean(np.abs(res.patch[inner] - truth) < 0.2) > 0.95
    assert res.confident[inner].mean() > 0.8
    # the raw match: most lenses right before any smoothing
    assert np.mean(np.abs(res.raw[inner] - truth) < 0.25) > 0.85


def test_block_gains_divide_by_each_types_profile():
    """Hand-computed: profile bins every 0.5 px; offset (3, 4) is radius 5 = bin 10."""
    from plenocal.convert.patchsize import block_gains

    prof = np.ones((2, 12), np.float32)
    prof[1] = np.linspace(1.0, 0.45, 12)  # bin 10 of type 1: 1 - 0.05 * 10 = 0.5
    g = block_gains(prof, np.array([[0.0, 3.0]]), np.array([[0.0, 4.0]]))
    assert g.shape == (2, 1, 2)
    assert np.allclose(g[0], 1.0)
    assert np.allclose(g[1, 0], [1.0, 2.0])


def test_vignetted_weak_texture_keeps_a_large_patch_size():
    """A near plane (P 8.4 px) whose micro images darken towards the rim, at a tenth of
    the texture's contrast: the fall-off's ramps in the two blocks of a pair correlate
    negatively, more the larger the candidate, and pulled the best match down (7.80 px).
    The blocks are matched divided by the measured profile: within 0.1 px."""
    from synth.lenslets import _owner

    from plenocal.convert.patchsize import to_gray
    from plenocal.convert.vignetting import lens_type_profiles

    opt = small_optics(600, 450)
    depth = 0.48
    truth = opt.micro_image_disparity_px(depth)
    calib, grid, img = plane_lenslet(opt, depth)
    _, _, dist = _owner(grid)
    rho = dist / (grid.calib.safe_diameter / 2)
    fall = 1.0 - 0.55 * np.clip((rho - 0.6) / 0.4, 0.0, 1.0) ** 1.5
    g = (0.5 + (img.astype(np.float32) / 255.0 - 0.5) * 0.1) * fall[..., None]
    g += np.random.default_rng(0).normal(0.0, 0.005, g.shape)
    weak = np.clip(np.rint(g * 255.0), 0, 255).astype(np.uint8)
    profiles = lens_type_profiles(to_gray(weak), grid)
    inner = grid.inside()
    plain = estimate_patch_size(weak, grid)
    matched = estimate_patch_size(weak, grid, vignetting=profiles)
    assert matched.confident[inner].mean() > 0.7
    assert abs(np.median(matched.raw[inner & matched.confident]) - truth) < 0.1
    assert np.median(plain.raw[inner & plain.confident]) < truth - 0.3  # the bias it removes


def test_lens_profiles_by_parts_are_the_numbers_of_all_at_once(monkeypatch):
    """The lenses' radial bins sampled a few lenses at a time (memory bounded on any
    sensor) give the same bits as all lenses in one block."""
    from plenocal.convert import vignetting
    from plenocal.convert.patchsize import to_gray

    opt = small_optics(600, 450)
    _, grid, img = plane_lenslet(opt, 0.48)
    grid.types = np.arange(len(grid.types)) % 3  # three lens types: the path by bins
    gray = to_gray(img)
    monkeypatch.setattr(vignetting, "BINS_CHUNK", 7)
    by_parts = vignetting.lens_type_profiles(gray, grid)
    monkeypatch.setattr(vignetting, "BINS_CHUNK", 10 ** 9)
    at_once = vignetting.lens_type_profiles(gray, grid)
    assert len(grid.centres) > 7 * 3
    assert np.array_equal(by_parts[0], at_once[0]) and np.array_equal(by_parts[1], at_once[1])


def test_patch_size_follows_the_content_not_the_middle_of_the_range():
    """Two planes (left half P=4.5, right half P=8): the map has both, not a blend."""
    opt = small_optics(480, 300)
    calib = calib_for_optics(opt)
    grid = MicrolensGrid(calib, 480, 300)
    tex = random_texture(512, 1.5, 3)
    a = lenslet_from_patch_size(grid, 4.5, tex)
    b = lenslet_from_patch_size(grid, 8.0, tex)
    img = a.copy()
    right = grid.centres[:, 0] > 240
    # whole micro images from b for the lenses on the right
    ys, xs = np.mgrid[0:300, 0:480]
    owner_right = np.zeros((300, 480), bool)
    for cx, cy in grid.centres[right]:
        owner_right |= (xs - cx) ** 2 + (ys - cy) ** 2 < (calib.diameter / 2) ** 2
    img[owner_right] = b[owner_right]
    res = estimate_patch_size(img, grid)
    inner = grid.inside()
    far_left = inner & (grid.centres[:, 0] < 200)
    far_right = inner & (grid.centres[:, 0] > 290)
    assert abs(np.median(res.patch[far_left]) - 4.5) < 0.1
    assert abs(np.median(res.patch[far_right]) - 8.0) < 0.1


@pytest.mark.parametrize(("patch", "end", "where"), [(4.5, "smallest", "beyond"),
                                                     (10.0, "largest", "below")])
def test_a_scene_beyond_the_files_depth_range_is_warned_about(patch, end, where):
    """A plane whose patch size lies past the lens type's stated range (sizes 6-9 px) is
    matched at the search's end on every lens and filled: the converter says so, naming
    the file and the remedy. With the range open, as the real files state it, the same
    frame is matched and nothing is said."""
    opt = small_optics(480, 300)
    D = opt.micro_image_pitch_px
    tight = calib_for_optics(opt, depth_range=(D / 9.0, D / 6.0))
    img = lenslet_from_patch_size(MicrolensGrid(tight, 480, 300), patch,
                                  random_texture(512, 1.5, 4))
    grid = MicrolensGrid(replace(tight, source="tight.xml"), 480, 300)
    said = [w for w in estimate_patch_size(img, grid).warnings if "textured lenses" in w]
    assert len(said) == 1, said
    assert f"the {end} patch size searched" in said[0] and where in said[0]
    assert "lens_type depth_range in tight.xml" in said[0]
    opened = MicrolensGrid(calib_for_optics(opt, depth_range=(1.0, 100.0)), 480, 300)
    res = estimate_patch_size(img, opened)
    assert not [w for w in res.warnings if "textured lenses" in w]
    assert abs(np.median(res.patch[opened.inside()]) - patch) < 0.1


# ---------------------------------------------------------------------------
# (2) views of a textured plane shift by q T / P between neighbours
# ---------------------------------------------------------------------------


def test_views_shift_by_the_predicted_disparity():
    opt = small_optics(520, 400)
    depth = 0.55
    calib, grid, img = plane_lenslet(opt, depth, seed=1)
    shot = ShotConversion(img, calib, 5, FIXED_TILE)
    assert shot.mla == "keplerian"  # read from the image: the simulator's micro images invert
    P = opt.micro_image_disparity_px(depth)
    expect = shot.layout.q * shot.layout.tile / P  # u_(h+1) - u_h > 0
    centre = shot.view(2, 2)
    right = shot.view(2, 3)
    below = shot.view(3, 2)
    assert centre.shape == (shot.layout.height, shot.layout.width, 3)
    dx = measure_shift(centre, right, axis=0)
    dy = measure_shift(centre, below, axis=1)
    assert dx == pytest.approx(expect, abs=0.06)
    assert dy == pytest.approx(expect, abs=0.06)
    # two steps: twice the shift
    assert measure_shift(centre, shot.view(2, 4), axis=0, search=7.0) == pytest.approx(
        2 * expect, abs=0.1)
    # disparity.json: paper sign d = u_h - u_(h+1) = -q T / P
    d = shot.disparity()
    assert d["convention"] == "paper"
    assert d["D_min"] <= d["D_max"] < 0
    assert -d["D_max"] == pytest.approx(expect, rel=0.03)
    assert -d["D_min"] == pytest.approx(expect, rel=0.03)
    assert d["q_px"] == pytest.approx(calib.safe_diameter * np.sqrt(0.5) / 5)


def test_views_match_the_ideal_view_of_the_plane():
    """Patch size right -> the rendered view equals the virtual image resampled (no seams)."""
    calib = calib_for_optics(small_optics())
    grid = MicrolensGrid(calib, 400, 300)
    tex = random_texture(512, 1.5, 2)
    P = 6.5
    shot = ShotConversion(lenslet_from_patch_size(grid, P, tex), calib, 5, FIXED_TILE)
    L = shot.layout
    for r, c in ((2, 2), (0, 0), (4, 1)):
        ideal8 = plane_view(calib, L, P, tex, r, c)
        q = view_quality(shot.view(r, c), ideal8, border=L.tile)
        assert q["psnr_db"] > 36, (r, c, q)


@pytest.mark.parametrize("mla", ["keplerian", "galilean"])
@pytest.mark.parametrize("rotation", [0.0, np.pi / 2, 0.0007])
def test_views_upright_for_every_grid_rotation_and_mla_kind(rotation, mla):
    """The view equals the (upright) virtual image whatever the grid's rotation, for both
    MLA kinds; the kind is read from the image."""
    base = calib_for_optics(small_optics())
    calib = RayCalib(**{**base.__dict__, "rotation": rotation})
    grid = MicrolensGrid(calib, 400, 300)
    tex = random_texture(512, 1.5, 6)
    P = 6.0
    shot = ShotConversion(lenslet_from_patch_size(grid, P, tex, mla=mla), calib, 5, FIXED_TILE)
    assert shot.mla == mla
    L = shot.layout
    v = calib.diameter / P
    s = -1.0 if mla == "keplerian" else 1.0
    ys, xs = np.mgrid[0:L.height, 0:L.width].astype(np.float64)
    for r, c in ((2, 2), (0, 4)):
        d = np.stack([xs - L.tile_centres[0, 0], ys - L.tile_centres[0, 1]], -1) * (
            calib.diameter / L.tile)
        y = L.lens_centres[0] + d + s * v * L.offset_image(r, c)
        t = (y / v + 256).astype(np.float32)
        ideal = cv2.remap(tex, t[..., 0], t[..., 1], cv2.INTER_LINEAR)
        ideal8 = np.clip(np.rint(ideal * 255), 0, 255).astype(np.uint8)
        q = view_quality(shot.view(r, c), ideal8, border=L.tile)
        assert q["psnr_db"] > 33, (rotation, mla, r, c, q)


def test_mla_contradiction_warns_only_where_the_other_kind_matches_far_better():
    assert mla_contradiction("galilean", {"keplerian": 0.966, "galilean": 0.193}) == (
        "convert.mla = galilean, but the image matches as keplerian (mean best ZNCC 0.966 "
        "against 0.193 as galilean): the views will be a mosaic of misplaced patches; set "
        "the kind to auto or keplerian (workflow: convert.mla or the dataset's mla; command "
        "line: --mla)")
    assert mla_contradiction("keplerian", {"keplerian": 0.966, "galilean": 0.193}) is None
    # a frame without texture: low and close both ways
    assert mla_contradiction("galilean", {"keplerian": 0.35, "galilean": 0.2}) is None
    assert mla_contradiction("galilean", {"keplerian": float("nan"),
                                          "galilean": float("nan")}) is None


def test_an_mla_kind_the_image_does_not_decide_is_warned_about():
    """auto: a kind read 0.3 or more ahead (the real frames read 0.57-0.78 ahead) is taken
    quietly; closer, or unmeasured, the choice is a coin's throw and the warning names the
    scores and the remedy."""
    assert mla_undecided("keplerian", {"keplerian": 0.966, "galilean": 0.193}) is None
    assert mla_undecided("galilean", {"keplerian": 0.2, "galilean": 0.5}) is None
    note = mla_undecided("keplerian", {"keplerian": 0.096, "galilean": 0.095})
    assert note is not None and "cannot be read from this image" in note
    assert "0.096 against 0.095" in note and "keplerian is assumed" in note
    assert "--mla" in note and "convert.mla" in note
    assert mla_undecided("galilean", {"keplerian": 0.25, "galilean": 0.45}) is not None
    assert mla_undecided("keplerian", {"keplerian": float("nan"),
                                       "galilean": float("nan")}) is not None


def test_a_forced_mla_kind_that_the_image_contradicts_is_warned_about():
    """Set by hand the wrong way, the MLA kind makes a mosaic of the views: the conversion
    warns, with the image's scores. The right kind set by hand, and a camera set-up's kind
    (checked on its central shot: ``check_mla=False``), are not warned about."""
    calib = calib_for_optics(small_optics())
    grid = MicrolensGrid(calib, 400, 300)
    img = lenslet_from_patch_size(grid, 5.0, random_texture(512, 1.5, 8), mla="galilean")

    def mla_warnings(shot):
        return [w for w in shot.warnings if "convert.mla = " in w]

    wrong = ShotConversion(img, calib, 5, replace(FIXED_TILE, mla="keplerian"), source="s")
    (note,) = mla_warnings(wrong)
    assert note.startswith("s: convert.mla = keplerian, but the image matches as galilean")
    assert wrong.disparity()["warnings"] == wrong.warnings
    assert not mla_warnings(ShotConversion(img, calib, 5, replace(FIXED_TILE, mla="galilean")))
    assert not mla_warnings(ShotConversion(img, calib, 5, replace(FIXED_TILE, mla="keplerian"),
                                           check_mla=False))


def test_an_overexposed_frame_is_warned_about():
    """A fifth or more of the frame clipped at full scale: the views carry nothing there
    and the measurements have less to go on (HandTools made 2.5x brighter: 40 %); the real
    frames clip 4 % at most and are not warned about."""
    calib = calib_for_optics(small_optics())
    grid = MicrolensGrid(calib, 400, 300)
    img = lenslet_from_patch_size(grid, 5.0, random_texture(512, 1.5, 8), mla="galilean")
    assert img.dtype == np.uint8

    def clipped_warnings(rows: int) -> list[str]:
        frame = img.copy()
        frame[:rows] = 255
        shot = ShotConversion(frame, calib, 5, replace(FIXED_TILE, mla="galilean"), source="s")
        return [w for w in shot.warnings if "clipped at full scale" in w]

    assert not clipped_warnings(0) and not clipped_warnings(45)  # 15 % of the rows
    (note,) = clipped_warnings(105)
    assert note.startswith("s: 35% of the frame is clipped at full scale")


def test_a_camera_setup_carries_the_mla_warning_and_the_workflow_stops_on_it():
    """In the workflow the kind is checked once, on the shot that decides the camera's
    set-up (rule convert_setup): a kind set in the config that the image clearly
    contradicts stops there (mla_setting_error), naming the frame and the keys; the right
    kind, or one read from the image, does not."""
    from plenocal.convert.setup import mla_setting_error

    calib = calib_for_optics(small_optics())
    grid = MicrolensGrid(calib, 400, 300)
    img = lenslet_from_patch_size(grid, 5.0, random_texture(512, 1.5, 8), mla="galilean")
    setup, shot = decide_setup(img, calib, 5, replace(FIXED_TILE, mla="keplerian"), "x03_y01")
    assert [w for w in setup.warnings
            if w.startswith("x03_y01: convert.mla = keplerian, but the image matches as")]
    assert setup.mla == "keplerian" and setup.mla_source == "setting"
    error = mla_setting_error(setup, shot, "data/d/lenslet/x03_y01.png")
    assert error.startswith("data/d/lenslet/x03_y01.png: convert.mla = keplerian, but the "
                            "image matches as galilean")
    assert "convert.mla or the dataset's mla" in error
    setup, shot = decide_setup(img, calib, 5, replace(FIXED_TILE, mla="galilean"), "x03_y01")
    assert mla_setting_error(setup, shot, "x") is None
    setup, shot = decide_setup(img, calib, 5, replace(FIXED_TILE, mla="auto"), "x03_y01")
    assert setup.mla == "galilean" and mla_setting_error(setup, shot, "x") is None


def test_galilean_disparity_has_the_other_sign():
    """Paper sign (Eq. 1): Keplerian D = -q T / P < 0, Galilean D = +q T / P > 0, and the
    content moves the way the sign says between views (2, 2) and (2, 3)."""
    calib = calib_for_optics(small_optics())
    grid = MicrolensGrid(calib, 400, 300)
    tex = random_texture(512, 1.5, 7)
    for mla, sign in (("keplerian", -1.0), ("galilean", 1.0)):
        shot = ShotConversion(lenslet_from_patch_size(grid, 5.0, tex, mla=mla), calib, 5,
                              FIXED_TILE)
        d = shot.disparity()
        expect = shot.layout.q * shot.layout.tile / 5.0
        assert d["mla"] == mla
        assert sign * d["D_min"] > 0 and sign * d["D_max"] > 0
        assert d["D_max"] == pytest.approx(sign * expect, rel=0.03)
        # u_(h+1) - u_h = -D
        assert measure_shift(shot.view(2, 2), shot.view(2, 3), axis=0) == pytest.approx(
            -sign * expect, abs=0.08)


def test_tile_auto_follows_the_patch_size_and_even_sizes():
    calib = calib_for_optics(small_optics())
    grid = MicrolensGrid(calib, 400, 300)
    tex = random_texture(512, 1.5, 8)
    for P, T in ((5.0, 8), (7.4, 12)):  # ceil(1.5 P)
        shot = ShotConversion(lenslet_from_patch_size(grid, P, tex), calib, 3)
        assert shot.layout.tile == T
        assert shot.layout.width % 2 == 0 and shot.layout.height % 2 == 0
        odd = ShotConversion(lenslet_from_patch_size(grid, P, tex), calib, 3,
                             ConvertSettings(even_size=False))
        assert odd.layout.width - shot.layout.width in (0, 1)
        assert odd.layout.height - shot.layout.height in (0, 1)
        assert odd.layout.width % 2 == 1 and odd.layout.height % 2 == 1
        # both centred on the optical axis: the even layout is the odd one shifted by
        # half a pixel, its axis between the two middle pixels
        for L in (shot.layout, odd.layout):
            axis = (np.array([(grid.width - 1) / 2, (grid.height - 1) / 2])
                    - L.lens_centres[0]) * L.tile / calib.diameter + L.tile_centres[0]
            assert axis == pytest.approx([(L.width - 1) / 2, (L.height - 1) / 2], abs=1e-9)


@pytest.mark.parametrize("bits", [10, 12, 14])
def test_16_bit_images_are_scaled_to_their_real_range(bits):
    calib = calib_for_optics(small_optics())
    grid = MicrolensGrid(calib, 400, 300)
    img8 = lenslet_from_patch_size(grid, 5.0, random_texture(256, 1.5, 9))
    full = (1 << bits) - 1
    img16 = np.rint(img8.astype(np.float64) * full / 255).astype(np.uint16)
    a = ShotConversion(img8, calib, 3, FIXED_TILE)
    b = ShotConversion(img16, calib, 3, FIXED_TILE)
    assert b.bits == bits
    diff = np.abs(a.view(1, 1).astype(int) - b.view(1, 1).astype(int))
    assert diff.max() <= 1, diff.max()
    # stated depth; a value above it is refused with the key named
    c = ShotConversion(img16, calib, 3, ConvertSettings(tile_size=6, bit_depth=16))
    assert c.bits == 16 and c.view(1, 1).mean() < a.view(1, 1).mean() / 3
    with pytest.raises(ConvertError, match="convert.bit_depth"):
        ShotConversion(img16 | np.uint16(1 << bits), calib, 3,
                       ConvertSettings(tile_size=6, bit_depth=bits))


def test_settings_errors_name_the_key():
    with pytest.raises(ConvertError, match="convert.tile_size"):
        ConvertSettings.from_config({"tile_size": "big"})
    with pytest.raises(ConvertError, match="convert.mla"):
        ConvertSettings.from_config({"mla": "plenoptic"})
    with pytest.raises(ConvertError, match="convert.bit_depth"):
        ConvertSettings.from_config({"bit_depth": 20})
    # the command line's --set reaches the converter without the workflow's validation
    with pytest.raises(ConvertError, match=r"convert.disparity_percentiles = \[98, 2\]: "
                                           "the low percentile first"):
        ConvertSettings.from_config({"disparity_percentiles": [98, 2]})


# ---------------------------------------------------------------------------
# (3) every fixture calibration drives a conversion
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("path", FIXTURES, ids=[p.stem for p in FIXTURES])
def test_every_fixture_converts(path):
    calib = read_calib(path)
    D = calib.diameter
    W, H = int(round(12 * D)), int(round(10 * D))
    grid = MicrolensGrid(calib, W, H)
    mid = calib.lens_types[len(calib.lens_types) // 2]
    P = D / (0.5 * (mid.depth_min + min(mid.depth_max, 10.0)))
    img = lenslet_from_patch_size(grid, P, random_texture(512, 1.5, 0), texture_scale=0.5)
    shot = ShotConversion(img, calib, 5)
    names = [name for name, _ in shot.views()]
    assert len(names) == 25 and names[0] == "0_0" and names[-1] == "4_4"
    view = shot.view(2, 2)
    assert view.shape == (shot.layout.height, shot.layout.width, 3)
    assert view.dtype == np.uint8
    assert shot.layout.width % 2 == 0 and shot.layout.height % 2 == 0  # even_size (YUV 4:2:0)
    assert np.all(np.isfinite(shot.used_patch))
    assert abs(np.median(shot.used_patch) - P) < 0.05 * P
    assert view.std() > 10  # content, not an empty or black frame
    d = shot.disparity()
    assert d["width"] == shot.layout.width and d["n_views"] == 5
    # lenses of a type whose range excludes P are filled from their neighbours
    assert d["patch_size_px"]["confident_share"] > 0.3
    pic = shot.patch_picture()
    assert pic.shape[0] == shot.layout.height and pic.dtype == np.uint8
    # each pixel its nearest lens's colour (filled lenses darker), black where no lens
    # lies within reach: by hand, with a mask
    from plenocal.convert.shot import colour_range
    from plenocal.viewgeom import nearest_slots

    idx = nearest_slots(shot.layout, keep=1)[0][0]
    lo, hi = colour_range(shot.used_patch)
    level = np.clip(np.rint((shot.used_patch - lo) / max(hi - lo, 1e-6) * 255), 0, 255)
    lut = cv2.applyColorMap(np.arange(256, dtype=np.uint8)[:, None], cv2.COLORMAP_VIRIDIS)
    rgb = lut[:, 0][level.astype(np.uint8)][:, ::-1].astype(np.float32)
    rgb[~shot.patch.confident[shot.layout.lens_index]] *= 0.55
    want = np.zeros(idx.shape + (3,), np.uint8)
    want[idx >= 0] = rgb[idx[idx >= 0]].astype(np.uint8)
    assert np.array_equal(pic[:, :shot.layout.width], want)


def test_patch_picture_colours_are_not_squeezed_by_an_outlier():
    """One wrong lens at 40 px among sizes 10-12 px: the colour range is the map's
    1st-99th percentile, so the others keep the whole scale (the range by hand: numpy's
    linear percentile of 0..98 evenly over 10..12 plus 40)."""
    from plenocal.convert.shot import colour_range

    patch = np.append(np.linspace(10.0, 12.0, 99), 40.0)
    lo, hi = colour_range(patch)
    # 1st percentile: position 0.99 of 99 gaps -> 10 + 0.99 * 2 / 98; 99th: position 98.01
    # -> between 12 (index 98) and 40 (index 99) at 0.01
    assert math.isclose(lo, 10.0 + 0.99 * 2.0 / 98.0, rel_tol=1e-12)
    assert math.isclose(hi, 12.0 + 0.01 * 28.0, rel_tol=1e-12)
    assert hi < 12.5  # not 40


def test_conversion_is_deterministic():
    calib = calib_for_optics(small_optics())
    grid = MicrolensGrid(calib, 400, 300)
    img = lenslet_from_patch_size(grid, 5.0, random_texture(256, 1.5, 4))
    a = ShotConversion(img, calib, 3)
    b = ShotConversion(img, calib, 3)
    assert np.array_equal(a.used_patch, b.used_patch)
    assert np.array_equal(a.view(0, 2), b.view(0, 2))


def test_views_are_the_same_by_band_thread_and_group(monkeypatch):
    """Issue 35: the views are rendered band by band for all views at once
    (ShotConversion.render_views), on threads, in groups under a memory budget; a band's
    plan holds the same numbers as those rows of the whole view's, and every way of
    rendering gives the same bytes (single views included)."""

    calib = calib_for_optics(small_optics(480, 300))
    grid = MicrolensGrid(calib, 480, 300)
    img = lenslet_from_patch_size(grid, 6.0, random_texture(512, 1.5, 5))
    shot = ShotConversion(img, calib, 5, FIXED_TILE)
    whole = shot.plans_for_rows()
    band = shot.plans_for_rows(slice(17, 45))
    for w, b in zip(whole, band, strict=True):
        for name in ("map_x", "map_y", "off_x", "off_y", "tile_weight"):
            assert np.array_equal(getattr(w, name)[:, 17:45], getattr(b, name)), name
    monkeypatch.setattr("plenocal.convert.shot.PLAN_ROWS", 16)  # 4 bands here
    assert shot.layout.height > 3 * 16
    names = view_names(5)
    one = shot.render_views(names, threads=1)
    two = shot.render_views(names, threads=2)
    grouped = {k: v for g in shot.view_groups(threads=2, budget_bytes=1) for k, v in g.items()}
    assert list(grouped) == list(names)
    for name in names:
        assert one[name].dtype == np.uint8 and one[name].shape == (
            shot.layout.height, shot.layout.width, 3)
        assert np.array_equal(one[name], two[name]), name
        assert np.array_equal(one[name], grouped[name]), name
    assert np.array_equal(shot.view(0, 4), one["0_4"])
    # 16-bit views: the same picture to 1/255 (rounded once to 16 bits, not to 8)
    deep = shot.render_views(["0_0"], dtype=np.uint16)["0_0"]
    assert deep.dtype == np.uint16
    assert np.abs(deep / 65535.0 * 255.0 - one["0_0"]).max() <= 1.0


def test_remap_takes_maps_of_any_number_of_rows():
    """cv2.remap refuses maps of 2^15 - 1 rows or more (the per-lens maps of a 40-MP
    Raytrix R42 frame: about 39,000 lenses); plenocal.convert.exact.remap slices them."""
    import cv2

    from plenocal.convert.exact import remap

    rng = np.random.default_rng(0)
    src = rng.random((60, 80)).astype(np.float32)
    mx = (rng.random((40000, 3)) * 79).astype(np.float32)
    my = (rng.random((40000, 3)) * 59).astype(np.float32)
    with pytest.raises(cv2.error):
        cv2.remap(src, mx, my, cv2.INTER_LINEAR)
    got = remap(src, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    assert got.shape == (40000, 3)
    part = cv2.remap(src, mx[32766:32800], my[32766:32800], cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE)
    assert np.array_equal(got[32766:32800], part)


def test_views_from_the_stored_analysis_are_the_same(tmp_path):
    """Rule convert stores a shot's measurements (analysis.npz) and rule convert_views
    renders the other views from them: the same views as one conversion, deterministic
    bytes, and an analysis of another image refused with the remedy."""
    from plenocal.convert.analysis import read_analysis, write_analysis

    calib = calib_for_optics(small_optics())
    grid = MicrolensGrid(calib, 400, 300)
    img = lenslet_from_patch_size(grid, 5.0, random_texture(256, 1.5, 4))
    whole = ShotConversion(img, calib, 3)
    write_analysis(tmp_path / "a.npz", whole.analysis)
    write_analysis(tmp_path / "b.npz", whole.analysis)
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "b.npz").read_bytes()
    stored = read_analysis(tmp_path / "a.npz")
    assert stored.mla == whole.mla and stored.patch.warnings == whole.patch.warnings
    split = ShotConversion(img, calib, 3, analysis=stored)
    for (name, a), (_, b) in zip(whole.views(), split.views(), strict=True):
        assert np.array_equal(a, b), name
    assert split.disparity() == whole.disparity()
    # measured on another grid (one lens fewer): refused, naming the remedy
    other = ShotConversion(img[:, :-40], calib, 3)
    with pytest.raises(ConvertError, match=r"lenses.*rerun rule convert"):
        ShotConversion(img, calib, 3, analysis=other.analysis)
    (tmp_path / "c.npz").write_bytes(b"not a zip")
    with pytest.raises(ConvertError, match=r"c\.npz: not a readable conversion analysis"):
        read_analysis(tmp_path / "c.npz")
    with pytest.raises(ConvertError, match=r"not found; rerun rule convert"):
        read_analysis(tmp_path / "missing.npz")


# ---------------------------------------------------------------------------
# (4) errors
# ---------------------------------------------------------------------------


@pytest.fixture()
def shot_files(tmp_path):
    opt = small_optics()
    calib = calib_for_optics(opt)
    grid = MicrolensGrid(calib, 400, 300)
    img = lenslet_from_patch_size(grid, 5.0, random_texture(256, 1.5, 5))
    write_image(tmp_path / "x00_y00.png", img)
    write_calib(calib, tmp_path / "calib.xml")
    (tmp_path / "camera.yaml").write_text("sensor_width_px: 400\nsensor_height_px: 300\n")
    return tmp_path


def test_files_convert(shot_files):
    shot = convert_files(shot_files / "x00_y00.png", shot_files / "calib.xml",
                         shot_files / "camera.yaml", 3, ConvertSettings.from_config(
                             {"tile_size": 5, "patch_size": {"step_px": 0.25}}))
    assert shot.layout.tile == 5
    assert abs(np.median(shot.used_patch) - 5.0) < 0.05


def test_error_size_differs_from_datasheet(shot_files):
    (shot_files / "camera.yaml").write_text("sensor_width_px: 640\nsensor_height_px: 300\n")
    with pytest.raises(ConvertError, match=r"400x300.*640x300"):
        convert_files(shot_files / "x00_y00.png", shot_files / "calib.xml",
                      shot_files / "camera.yaml", 3)


def test_crop_with_its_offset_moved(shot_files, tmp_path):
    """A crop whose calib.xml offset moved with it converts on the full image's lattice,
    though the lens that the offset names (the grid's origin) lies outside the crop."""
    calib = read_calib(shot_files / "calib.xml")
    img = cv2.imread(str(shot_files / "x00_y00.png"))
    H, W = img.shape[:2]
    x0, y0, w, h = 230, 170, 160, 120
    cv2.imwrite(str(tmp_path / "crop.png"), img[y0:y0 + h, x0:x0 + w])
    ox = (W - 1) / 2 + calib.offset[0] - x0 - (w - 1) / 2
    oy = (h - 1) / 2 - ((H - 1) / 2 - calib.offset[1] - y0)
    assert (w - 1) / 2 + ox < 0 or (h - 1) / 2 - oy < 0  # the origin outside the crop
    write_calib(replace(calib, offset=(ox, oy)), tmp_path / "crop.xml")
    shot = convert_files(tmp_path / "crop.png", tmp_path / "crop.xml", None, 3,
                         ConvertSettings.from_config({"tile_size": 5}))
    full = MicrolensGrid(calib, W, H)
    inside = ((full.centres[:, 0] >= x0) & (full.centres[:, 0] <= x0 + w - 1)
              & (full.centres[:, 1] >= y0) & (full.centres[:, 1] <= y0 + h - 1))
    np.testing.assert_allclose(shot.grid.centres, full.centres[inside] - [x0, y0], atol=1e-9)
    np.testing.assert_array_equal(shot.grid.types, full.types[inside])
    assert abs(np.median(shot.used_patch) - 5.0) < 0.1


def test_error_cropped_image(shot_files, tmp_path):
    img = cv2.imread(str(shot_files / "x00_y00.png"))
    cv2.imwrite(str(tmp_path / "crop.png"), img[:60, :80])
    with pytest.raises(ConvertError, match="calib.xml"):
        convert_files(tmp_path / "crop.png", shot_files / "calib.xml", None, 3)


def test_error_unreadable_image(shot_files):
    (shot_files / "x00_y00.png").write_bytes(b"not a png at all")
    with pytest.raises(ConvertError, match=r"x00_y00.png: cannot read the lenslet image"):
        convert_files(shot_files / "x00_y00.png", shot_files / "calib.xml", None, 3)
    with pytest.raises(ConvertError, match="cannot read the lenslet image"):
        convert_files(shot_files / "missing.png", shot_files / "calib.xml", None, 3)


def test_error_truncated_png_names_the_cut_before_libpng_speaks(shot_files, capfd):
    """A lenslet PNG cut short (a copy that stopped) is named as truncated, with where it
    stops, and libpng's own "Read Error" does not come first; a PNG with bytes after its
    IEND chunk still reads."""
    whole = (shot_files / "x00_y00.png").read_bytes()
    (shot_files / "cut.png").write_bytes(whole[: len(whole) * 2 // 3])
    capfd.readouterr()
    with pytest.raises(ConvertError, match=r"cut.png: a truncated PNG, cut short in its "
                                            r"'IDAT' chunk.*copy or make it again"):
        convert_files(shot_files / "cut.png", shot_files / "calib.xml", None, 3)
    assert "libpng" not in capfd.readouterr().err
    (shot_files / "cut.png").write_bytes(whole[:33])  # the signature and the header chunk
    with pytest.raises(ConvertError, match=r"cut short after 33 bytes \(no IEND chunk\)"):
        convert_files(shot_files / "cut.png", shot_files / "calib.xml", None, 3)
    (shot_files / "tail.png").write_bytes(whole + b"appended by a tool")
    assert png_truncation(shot_files / "tail.png") is None
    assert np.array_equal(read_image(shot_files / "tail.png"),
                          read_image(shot_files / "x00_y00.png"))


def test_error_lens_type_without_depth_range(shot_files):
    text = (shot_files / "calib.xml").read_text()
    start = text.index("<depth_range")
    end = text.index("</depth_range>") + len("</depth_range>")
    (shot_files / "calib.xml").write_text(text[:start] + text[end:])
    with pytest.raises(ConvertError, match=r"lens_type\[0\].depth_range"):
        convert_files(shot_files / "x00_y00.png", shot_files / "calib.xml", None, 3)
    # a calibration built in memory with an unusable range
    bad = RayCalib(**{**calib_for_optics(small_optics()).__dict__,
                      "lens_types": (LensType(0, (0.0, 0.0), 4.0, float("nan")),)})
    with pytest.raises(ConvertError, match="virtual-depth range"):
        ShotConversion(np.zeros((300, 400, 3), np.uint8), bad, 3)


# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------


def test_weighted_median_by_hand():
    v = np.array([[1.0, 2.0, 3.0], [5.0, 1.0, 9.0]])
    w = np.array([[1.0, 1.0, 5.0], [0.0, 0.0, 0.0]])
    out = weighted_median(v, w)
    assert out[0] == 3.0 and np.isnan(out[1])


def test_quality_summary():
    a = np.zeros((20, 20, 3), np.uint8)
    b = a.copy()
    b[5, 5] = 255
    q = view_quality(a, b, border=2)
    # one pixel of 16 x 16 x 3 channels off by 255 in each channel: MSE = 255^2 / 256
    assert q["psnr_db"] == pytest.approx(10 * np.log10(256), abs=1e-6)
    s = summarise({"x00_y00": {"1_1": {"psnr_db": 31.0, "ssim": 0.9},
                               "0_0": {"psnr_db": 28.0, "ssim": 0.8}},
                   "x01_y00": {"1_1": {"psnr_db": 33.0, "ssim": 0.95}}}, "1_1")
    assert s["mean_psnr_central_db"] == pytest.approx(32.0)
    assert s["min_psnr_db"] == 28.0 and s["worst_view"] == "x00_y00/0_0"
    assert s["meets_targets"]
    with pytest.raises(ConvertError, match="same convert settings"):
        view_quality(a, np.zeros((10, 20, 3), np.uint8), 1)


def test_views_reaching_the_rim_take_the_wide_blend():
    """rim_reach: 1 where |q_rc| + P / sqrt(2) passes D'/2, 2 where |q_rc| + P / 2 does too
    (hand-computed), and the shot renders each view with the blend of its reach (more
    lenses, wider fade, stronger centre weight the farther it reaches)."""
    from plenocal.convert.render import RenderSettings, reaches_rim, rim_reach

    assert rim_reach(6.0, 7.1, 20.0) == 1  # corner 6 + 5.02 > 10, side 6 + 3.55 < 10
    assert rim_reach(6.0, 5.6, 20.0) == 0  # 6 + 3.96 < 10
    assert rim_reach(8.0, 5.0, 20.0) == 2  # side 8 + 2.5 > 10
    assert reaches_rim(6.0, 7.1, 20.0) is True and reaches_rim(6.0, 5.6, 20.0) is False
    wide, wider = RenderSettings().wide(), RenderSettings().wider()
    # every lens within one tile: at most 4 (issue 33: a wider fade is cut at tile borders)
    assert (wide.slots, wide.fade_radius, wide.centre_power) == (4, 1.0, 3.0)
    assert (wider.slots, wider.fade_radius, wider.centre_power) == (7, 1.6, 1.0)
    assert RenderSettings().for_reach(0) == RenderSettings()
    calib, grid, shot = patch6_shot()
    P = float(np.median(shot.used_patch))
    slots = (3, 4, 7)
    reaches = set()
    for r in range(5):
        for c in range(5):
            off = float(np.hypot(*shot.layout.offset_image(r, c)))
            reach = rim_reach(off, P, calib.safe_diameter)
            reaches.add(reach)
            assert (shot.plan_for(r, c) is not shot.plan) == (reach > 0), (r, c)
            assert shot.plan_for(r, c).tile_weight.shape[0] == slots[reach], (r, c)
    assert shot.plan_for(2, 2) is shot.plan and {0, 1} <= reaches


def test_sparse_sharp_lenses_take_the_wider_blend_everywhere():
    """focus_reach (hand-computed): a shot whose lenses' mean focus weight is under 2/3
    (fewer than two of the three nearest lenses sharp) renders every view at the wider
    blend; one lens type (every weight 1), or two of three types sharp, leaves each view
    at its own reach."""
    from plenocal.convert.render import FOCUS_SPARSE, focus_reach

    assert FOCUS_SPARSE == pytest.approx(2 / 3)
    assert focus_reach(np.ones(90)) == 0
    assert focus_reach(np.tile([1.0, 1.0, 0.05], 30)) == 0  # mean 0.683
    assert focus_reach(np.tile([1.0, 0.05, 0.05], 30)) == 2  # mean 0.367: one type sharp
    assert focus_reach(np.tile([1.0, 0.5, 0.4], 30)) == 2  # mean 0.633
    assert focus_reach(np.zeros(0)) == 0
    calib, grid, shot = patch6_shot()  # one lens type: as it was
    assert shot.least_reach == 0 and shot.plan_for(2, 2) is shot.plan


def test_the_blend_weighs_the_lenses_by_their_trust_averaged_over_the_lattice():
    """Every blend weighs each lens by its focus times its trust (reliability) averaged
    over the lattice (convert.blend.trust_passes, 2), the wide ones too; 0 passes give
    each lens its own trust."""
    from plenocal.convert.patchsize import lattice_mean, reliability
    from plenocal.convert.render import RenderSettings

    s = RenderSettings()
    assert s.trust_passes == s.wide().trust_passes == s.wider().trust_passes == 2
    opt = small_optics(480, 300)
    calib = calib_for_optics(opt)
    grid = MicrolensGrid(calib, 480, 300)
    img = lenslet_from_patch_size(grid, 6.0, random_texture(512, 1.5, 4))
    shot = ShotConversion(img, calib, 5, FIXED_TILE)
    p = shot.patch
    trust = reliability(p.raw, p.patch, p.confident, shot.settings.patch.step_px)
    assert 0 < (trust < 1).sum() < len(trust)  # a mix: the averaging changes something
    used = shot.layout.lens_index
    expect = (p.focus * lattice_mean(trust, grid.neighbours, 2))[used]
    assert np.array_equal(shot._lens_weight, expect)
    own = ShotConversion(img, calib, 5, replace(FIXED_TILE, render=replace(
        FIXED_TILE.render, trust_passes=0)))
    assert np.array_equal(own._lens_weight, (p.focus * trust)[used])
    assert not np.array_equal(own._lens_weight, shot._lens_weight)


def test_each_slot_is_devignetted_with_its_lens_types_profile():
    """A profile per lens type: every slot of the plan looks its gain up in its own lens's
    row, so a flat grey frame whose two halves of lenses vignette differently (type 0
    falls to 0.5 at the rim, type 1 stays flat) renders flat once each type has its
    profile, and not with one profile for both."""
    from plenocal.convert.render import make_plans, render_view
    from plenocal.convert.vignetting import BIN_PX

    calib, grid, shot = patch6_shot()
    layout = shot.layout
    lens_type = (np.arange(len(grid.centres)) % 2).astype(np.int64)
    half = calib.safe_diameter / 2
    radii = np.arange(0.0, half + 1.5, BIN_PX)
    fall = np.clip(1.0 - 0.5 * (radii / half) ** 2, 0.5, 1.0)
    profiles = np.stack([fall, np.ones_like(fall)]).astype(np.float32)
    # the frame: grey 0.6 times each pixel's own lens type's profile at its radius
    yy, xx = np.mgrid[0:300, 0:480].astype(np.float64)
    d2 = ((xx[None] - grid.centres[:, 0, None, None]) ** 2
          + (yy[None] - grid.centres[:, 1, None, None]) ** 2)
    owner = np.argmin(d2, axis=0)
    rho = np.sqrt(np.take_along_axis(d2, owner[None], 0)[0])
    prof = np.where(lens_type[owner] == 0, np.interp(rho, radii, fall), 1.0)
    frame = np.repeat((0.6 * prof).astype(np.float32)[..., None], 3, axis=2)
    used = layout.lens_index
    plan, = make_plans(layout, shot.used_patch, calib.safe_diameter, [shot.settings.render],
                       profile=profiles, profile_row=lens_type[used])
    assert plan.gain_table.shape[0] == 2 and plan.gain_base is not None
    one, = make_plans(layout, shot.used_patch, calib.safe_diameter, [shot.settings.render],
                      profile=profiles[:1])
    b = layout.tile
    for r, c in [(0, 0), (4, 4)]:
        typed = render_view(plan, frame, r, c)[b:-b, b:-b, 0]
        common = render_view(one, frame, r, c)[b:-b, b:-b, 0]
        assert np.abs(typed - 0.6).max() < 0.01, (r, c, np.abs(typed - 0.6).max())
        assert np.abs(common - 0.6).max() > 0.05, (r, c)


def test_soften_unreliable_is_one_blend_for_every_depth_and_channel_count():
    """soften_unreliable mixes the view with its blur where the reliability map is under 1:
    a 16-bit view (OpenCV's products) gives the 8-bit one's result (cv2.blendLinear) to
    one and a half levels (sigma 6 px: the blur runs on the view shrunk by 3, and 8 bits
    round after the shrink, the blur and the growth), one channel gives each of three equal
    channels' result, and rows whose map is 1 are left as they were."""
    from plenocal.convert.render import soften_unreliable

    rng = np.random.default_rng(3)
    H, W = 96, 120
    grey8 = cv2.GaussianBlur(rng.integers(0, 256, (H, W), dtype=np.uint8), (0, 0), 1.0)
    view8 = np.repeat(grey8[..., None], 3, axis=2)
    rmap = np.ones((H, W), np.float32)
    rmap[40:80, 30:90] = np.linspace(0.0, 1.0, 60, dtype=np.float32)[None, :]
    out8 = soften_unreliable(view8.copy(), rmap, 6.0)
    out16 = soften_unreliable(view8.astype(np.uint16) * 257, rmap.copy(), 6.0)
    mono = soften_unreliable(view8[..., :1].astype(np.uint16) * 257, rmap.copy(), 6.0)
    assert out16.dtype == np.uint16 and mono.shape == (H, W, 1)
    assert np.abs(out16 / 257.0 - out8).max() <= 1.5
    assert not np.array_equal(out8[40:80], view8[40:80])  # softened where the map is < 1
    np.testing.assert_array_equal(mono[..., 0], out16[..., 0])
    np.testing.assert_array_equal(out8[:40], view8[:40])
    np.testing.assert_array_equal(out16[80:], view8[80:].astype(np.uint16) * 257)


def test_soften_unreliable_blurs_only_the_box_it_softens():
    """Only the box around the pixels to soften is blurred (with the kernel's reach): an
    8-bit view comes out as when the whole view is blurred and blended, to the bit (sigmas
    under 4 px, blurred at full scale as the simulator's views are)."""
    from plenocal.convert.render import _lowpass, soften_unreliable

    rng = np.random.default_rng(5)
    H, W = 300, 420
    view = cv2.GaussianBlur(rng.integers(0, 256, (H, W, 3), dtype=np.uint8), (0, 0), 1.0)
    bad = np.ones((H, W), np.float32)
    bad[120:150, 200:260] = 0.0
    rmap = cv2.GaussianBlur(bad, (0, 0), 6.0)
    for sigma in (2.0, 3.0):
        whole = cv2.blendLinear(view, _lowpass(view, sigma), rmap, 1.0 - rmap)
        np.testing.assert_array_equal(soften_unreliable(view.copy(), rmap, sigma), whole)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_soften_unreliable_in_strips_is_the_whole_blend(dtype):
    """soften_unreliable blends SOFTEN_ROWS rows at a time (the weights and the result of
    a whole 31-MP frame's filled view are 44 MB): a view softened nearly everywhere, taller
    than three strips and of an odd width, comes out as one blend of the whole box, to the
    bit (8 bits: cv2.blendLinear; 16 bits: in float32, rounded)."""
    from plenocal.convert.render import SOFTEN_ROWS, _lowpass, soften_unreliable

    rng = np.random.default_rng(11)
    H, W = 3 * SOFTEN_ROWS + 77, 131
    top = np.iinfo(dtype).max
    view = cv2.GaussianBlur(rng.integers(0, top, (H, W, 3), dtype=dtype), (0, 0), 1.0)
    rmap = rng.random((H, W), dtype=np.float32)
    rmap[:5] = 1.0  # the box starts below the first rows
    sigma = 2.5
    ys = slice(5, H)
    blurred = _lowpass(view, sigma)[ys]
    r = rmap[ys]
    if dtype == np.uint8:
        whole = cv2.blendLinear(view[ys], blurred, r, 1.0 - r)
    else:
        mixed = cv2.blendLinear(view[ys].astype(np.float32), blurred.astype(np.float32), r, 1.0 - r)
        whole = np.rint(mixed).astype(np.uint16)
    out = soften_unreliable(view.copy(), rmap, sigma)
    np.testing.assert_array_equal(out[ys], whole)
    np.testing.assert_array_equal(out[:5], view[:5])


@pytest.mark.parametrize("safe_diameter", [16.0, 50.0])
def test_radial_tables_follow_the_weight_formula_in_the_squared_radius(safe_diameter):
    """The blend weight read from the 256-entry tables over the squared radius
    (radial_entries, cv2.LUT) is the formula rim x (1 - (rho / (D'/2))^2)^power + floor at
    the entry's radius, sqrt(round(scale rho^2) / scale); within 0.06 px of radius of the
    sample's own at the rim ramp, and the floor beyond the table."""
    from plenocal.convert.render import (  # noqa: PLC0415
        _FLOOR,
        RADIAL_LEVELS,
        RenderSettings,
        radial_entries,
        radial_tables,
    )

    st = RenderSettings()
    half = safe_diameter / 2.0
    rim = half - st.rim_px

    def formula(rho):
        w = np.clip((rim - rho) / st.rim_ramp_px, 0.0, 1.0)
        return w * np.clip(1.0 - (rho / half) ** 2, 0.0, 1.0) ** st.centre_power + _FLOOR

    wt, gt, scale = radial_tables(safe_diameter, st, None)
    assert wt.shape == (RADIAL_LEVELS,) and gt.shape == (1, RADIAL_LEVELS)
    rng = np.random.default_rng(1)
    x = rng.uniform(-half - 4, half + 4, (64, 64)).astype(np.float32)
    y = rng.uniform(-half - 4, half + 4, (64, 64)).astype(np.float32)
    o = np.array([0.7, -1.3])
    entry = radial_entries(x, y, o, scale)
    rho = np.hypot(x.astype(np.float64) + 0.7, y.astype(np.float64) - 1.3)
    j = np.minimum(np.rint(scale * rho ** 2), RADIAL_LEVELS - 1)
    assert np.abs(entry.astype(int) - j).max() <= 1  # float32 rounding at .5 only
    got = cv2.LUT(entry, wt)
    np.testing.assert_allclose(got, formula(np.sqrt(entry / scale)), atol=1e-6)
    beyond = rho > rim + 2.5
    assert beyond.any() and np.allclose(got[beyond], _FLOOR)
    ramp = (rho > rim - st.rim_ramp_px) & (rho < rim)
    step = np.abs(np.sqrt(entry / scale) - rho)[ramp]
    assert step.max() < 0.06, step.max()


def test_remembered_slots_give_the_same_tables_once_made(monkeypatch):
    """Inside remembered_slots, nearest_slots makes each band's tables once per layout
    geometry and hands the same read-only arrays out again (a recording's frames share one
    layout), equal to those made without the block; another layout, band or count makes
    its own; past the byte budget nothing is kept; outside the block nothing is."""
    from plenocal import viewgeom
    from plenocal.viewgeom import nearest_slots, remembered_slots

    calib, grid, shot = patch6_shot()
    layout = shot.layout
    rows = slice(8, 40)
    made = []
    compute = viewgeom._nearest_slots
    monkeypatch.setattr(viewgeom, "_nearest_slots",
                        lambda *a: made.append(a[1:]) or compute(*a))
    plain = nearest_slots(layout, keep=4, k=13, rows=rows)
    with remembered_slots():
        first = nearest_slots(layout, keep=4, k=13, rows=rows)
        again = nearest_slots(replace(layout), keep=4, k=13, rows=slice(8, 40))
        other = nearest_slots(layout, keep=3, k=13, rows=rows)
        moved = replace(layout, tile_centres=layout.tile_centres + 0.5)
        nearest_slots(moved, keep=4, k=13, rows=rows)
        with pytest.raises(RuntimeError, match="already open"), remembered_slots():
            pass
    assert len(made) == 4  # plain, first, other, moved: again was remembered
    assert again[0] is first[0] and again[1] is first[1]
    assert not first[0].flags.writeable and not first[1].flags.writeable
    for a, b in zip(plain, first, strict=True):
        assert np.array_equal(a, b)
    assert other[0].shape[0] == 3
    with remembered_slots(max_bytes=1):  # nothing fits: made every time
        nearest_slots(layout, keep=4, k=13, rows=rows)
        nearest_slots(layout, keep=4, k=13, rows=rows)
    assert len(made) == 6
    nearest_slots(layout, keep=4, k=13, rows=rows)
    assert len(made) == 7 and viewgeom._slot_memo is None


@pytest.mark.parametrize("turn", [0.0, 0.37])
def test_slots_are_the_true_nearest_lenses_and_every_lens_within_the_blend(turn):
    """nearest_slots against brute force over every used lens's tile centre: with the
    candidates that :func:`candidates_within` gives a blend's radius, the k nearest come out
    nearest first (a tile's radius with 13 candidates, the wider blend's 1.6 tiles with 19:
    the cell's lens and its six neighbours do not hold every lens within either, and a
    blend that misses one changes at the candidates' borders, the corner views' sawtooth of
    seams). And the counts: 7 candidates to 0.87 tiles, 13 to 1.13, 19 to 1.78, beyond
    refused."""
    from plenocal.viewgeom import candidates_within, nearest_slots

    assert [candidates_within(r) for r in (0.8, 1.0, 1.6)] == [7, 13, 19]
    with pytest.raises(ValueError, match="candidates"):
        candidates_within(1.8)
    calib = RayCalib(**{**calib_for_optics(small_optics(480, 300)).__dict__,
                        "rotation": math.pi / 2 + turn})
    calib, grid, shot = patch6_shot(calib)
    layout = shot.layout
    rows = slice(layout.height // 3, layout.height // 3 + 24)
    ys = np.arange(layout.height, dtype=np.float64)[rows][:, None, None]
    xs = np.arange(layout.width, dtype=np.float64)[None, :, None]
    tc = layout.tile_centres
    d2 = ((xs - tc[:, 0]) ** 2 + (ys - tc[:, 1]) ** 2) / layout.tile ** 2
    d2.sort(axis=2)
    inner = (slice(None), slice(2 * layout.tile, -2 * layout.tile))  # whole lattice around
    for radius, keep in ((1.0, 4), (1.6, 7)):
        _, got = nearest_slots(layout, keep=keep, k=candidates_within(radius), rows=rows)
        np.testing.assert_allclose(np.sqrt(got[(slice(None),) + inner]),
                                   np.sqrt(np.moveaxis(d2[..., :keep], 2, 0)[(slice(None),)
                                                                             + inner]),
                                   atol=1e-3)
    _, seven = nearest_slots(layout, keep=7, k=7, rows=rows)
    for slot, share in ((3, 0.01), (6, 0.1)):  # the old candidates missed these often
        missed = np.abs(np.sqrt(seven[slot]) - np.sqrt(d2[..., slot])) > 1e-3
        assert missed[inner].mean() > share, slot
