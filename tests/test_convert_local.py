"""Issue 33: the measures that see local failure (worst textured tile, lattice trace), the
safe diameter measured on the frame and the patch-size fill, on synthetic images built to
have (or not have) each defect. The same measures on the real frames:
tests/test_convert_real.py."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from synth.lenslets import calib_for_optics, random_texture

from plenocal.convert.localcheck import lattice_frequencies, lattice_trace, ssim_map, tile_ssim
from plenocal.convert.patchsize import (
    FILL_PERCENTILES,
    UNRELIABLE_WEIGHT,
    _smooth,
    fill_and_smooth,
    fill_unreliable,
    lattice_mean,
    reliability,
)
from plenocal.convert.safediameter import WEBER, measure_safe_diameter
from plenocal.grid import MicrolensGrid
from plenocal.optics import PlenopticOptics

HEX = np.array([[12.0, 0.0], [6.0, 12.0 * math.sqrt(3) / 2]])  # tile lattice steps, pixels


def smooth_scene(h: int = 360, w: int = 480, seed: int = 0) -> np.ndarray:
    """A grey scene with texture at every scale below ~20 px (float32, 0..1)."""
    tex = random_texture(max(h, w), 3.0, seed)[:h, :w].mean(axis=2)
    return cv2.GaussianBlur(tex, (0, 0), 1.0).astype(np.float32)


def lattice_coords(h: int, w: int, basis: np.ndarray) -> np.ndarray:
    """(h, w, 2) each pixel's coordinates in the lattice ``basis`` (rows: steps)."""
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    return np.stack([xs, ys], axis=-1) @ np.linalg.inv(basis)


def hex_cells(h: int, w: int) -> np.ndarray:
    """(h, w, 2) int: each pixel's cell of a hexagonal lattice 1.5 times HEX."""
    return np.floor(lattice_coords(h, w, HEX * 1.5)).astype(np.int64)


def flatten_cells(img: np.ndarray, cell: np.ndarray, box: tuple[slice, slice]) -> np.ndarray:
    """``img`` with each cell of ``cell`` (:func:`hex_cells`) inside ``box`` set to its
    mean: a honeycomb of flat hexagons (the doll's face); in place, and returned."""
    keys = cell[box][..., 0] * 100003 + cell[box][..., 1]
    part = img[box]
    _, inv = np.unique(keys.ravel(), return_inverse=True)
    img[box] = (np.bincount(inv, part.ravel()) / np.bincount(inv))[inv].reshape(part.shape)
    return img


def test_lattice_frequencies_are_the_reciprocal_lattice():
    f = lattice_frequencies(HEX, 6)
    assert f.shape == (6, 2)
    # every first-shell frequency is dual to the lattice: k . b is an integer, |k| the same
    dots = f @ HEX.T
    assert np.allclose(dots, np.rint(dots), atol=1e-9)
    assert np.allclose(np.linalg.norm(f, axis=1), 2 / (12 * math.sqrt(3)), rtol=1e-9)


def test_lattice_trace_sees_a_sawtooth_of_tiles_and_not_a_clean_scene():
    """A ramp across every tile (the TSPC corner views' sawtooth) raises the trace over
    the clean scene's few dB (a smooth spectrum; the peak is the largest of a few bins),
    the more the stronger the ramp: 3 % of the range by more than 2 dB."""
    scene = smooth_scene()
    frac = lattice_coords(*scene.shape, HEX)
    ramp = frac[..., 0] - np.floor(frac[..., 0])
    clean = lattice_trace(scene, HEX)["db"]
    weak = lattice_trace(scene + 0.03 * ramp, HEX)["db"]
    strong = lattice_trace(scene + 0.06 * ramp, HEX)["db"]
    assert clean < 6.0
    assert weak > clean + 2.0
    assert strong > weak + 2.0


def test_lattice_trace_floor_is_its_level_where_no_lattice_is():
    """The measure's floor (the trace at the lattice's frequencies turned by 10-50 deg):
    on six clean scenes each trace lies within 2.5 floor deviations of its floor (a
    clean scene's trace scatters by about 1 dB from scene to scene, as the floor does
    from turn to turn), and the six sit about on it; a sawtooth of 10 % of the range
    across every tile stands more than 2 deviations above it on each."""
    clean, saw = [], []
    for seed in range(6):
        scene = smooth_scene(seed=seed)
        frac = lattice_coords(*scene.shape, HEX)
        ramp = frac[..., 0] - np.floor(frac[..., 0])
        clean.append(lattice_trace(scene, HEX))
        saw.append(lattice_trace(scene + 0.1 * ramp, HEX))
    assert all(abs(t["z"]) < 2.5 for t in clean), [t["z"] for t in clean]
    assert abs(np.mean([t["db"] - t["null_db"] for t in clean])) < 1.0
    assert all(0.4 < t["null_sd_db"] < 2.0 for t in clean)
    assert all(t["z"] > 2.0 for t in saw), [t["z"] for t in saw]
    # the floor is the scene's, not the lattice's: the sawtooth hardly moves it
    assert all(abs(a["null_db"] - b["null_db"]) < 0.5 for a, b in zip(clean, saw, strict=True))


def test_worst_tile_sees_a_local_honeycomb_that_the_whole_view_hides():
    """One tile of flat hexagons (each cell its mean: the doll's face) drags the worst
    textured tile far down while the SSIM of the whole view stays high; a flat black
    region with its own defect is not a textured tile and is not counted."""
    ref = smooth_scene(seed=1)
    h, w = ref.shape
    cell = hex_cells(h, w)
    box = (slice(0, h // 6), slice(w // 6, 2 * w // 6))
    ours = flatten_cells(ref.copy(), cell, box)
    mask = np.ones(ref.shape, bool)
    whole = float(ssim_map(ref, ours).mean())
    found = tile_ssim(ref, ours, mask)
    assert whole > 0.9
    assert found["worst"] < 0.75
    assert found["worst_tile"] == (0, 1)
    # a black, texture-less region: not a textured tile, whatever is drawn there
    ref2, ours2 = ref.copy(), ref.copy()
    ref2[box] = 0.01
    ours2[box] = 0.01 + 0.005 * (cell[box][..., 0] % 2)
    found2 = tile_ssim(ref2, ours2, mask)
    assert not found2["textured"][0, 1]
    assert found2["worst"] > 0.95
    # a dark subject's texture (grey std 2.5 % of full range: hair on black) is texture,
    # and a honeycomb over it is seen
    ref3 = ref.copy()
    ref3[box] = 0.08 + (ref[box] - ref[box].mean()) * (0.025 / ref[box].std())
    ours3 = flatten_cells(ref3.copy(), cell, box)
    found3 = tile_ssim(ref3, ours3, mask)
    assert found3["textured"][0, 1] and found3["worst_tile"] == (0, 1)
    assert found3["worst"] < 0.9  # the clean tiles read 0.97 or more
    assert not tile_ssim(ref3, ours3, mask, texture_std=0.03)["textured"][0, 1]


def test_worst_tile_takes_each_tiles_own_subpixel_shift():
    """A view whose content sits 2.6-3.4 px off the reference's, varying over the view
    (one affine map cannot align a TLCT view everywhere): each tile at its own sub-pixel
    shift reads near 1, where whole-pixel shifts within SHIFT_PX leave the tiles
    0.5-1.4 px off; a honeycomb in such a view still reads low."""
    from plenocal.convert.localcheck import SHIFT_PX, SUBPIXEL_REACH_PX

    ref = smooth_scene(seed=2)
    h, w = ref.shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    off = (2.6 + 0.8 * xs / w).astype(np.float32)  # 2.6 px at the left, 3.4 px at the right
    ours = cv2.remap(ref, xs - off, ys + 0.5 * off, cv2.INTER_CUBIC,
                     borderMode=cv2.BORDER_REFLECT)
    assert SHIFT_PX < 2.6 and SUBPIXEL_REACH_PX > 3.4
    mask = np.zeros(ref.shape, bool)
    mask[4:-4, 4:-4] = True  # what the moved view covers
    found = tile_ssim(ref, ours, mask)
    assert found["worst"] > 0.95, found["tiles"]
    whole_pixel = min(float(ssim_map(ref, np.roll(ours, (dy, dx), axis=(0, 1)))[
        h // 3:2 * h // 3, w // 3:2 * w // 3].mean()) for dy in range(-2, 3)
        for dx in range(-2, 3))
    assert whole_pixel < found["worst"] - 0.05, (whole_pixel, found["worst"])
    box = (slice(0, h // 6), slice(w // 6, 2 * w // 6))
    ours = flatten_cells(ours, hex_cells(h, w), box)
    assert tile_ssim(ref, ours, mask)["worst"] < 0.75


def _overlapping_frame(grid: MicrolensGrid, light_radius: float, seed: int = 0
                       ) -> np.ndarray:
    """A frame whose micro images are discs of ``light_radius`` around the lens centres,
    each with its own texture, summed where they overlap (light from the neighbours)."""
    rng = np.random.default_rng(seed)
    H, W = grid.height, grid.width
    ys, xs = np.mgrid[0:H, 0:W].astype(np.float32)
    img = np.zeros((H, W), np.float32)
    tex = random_texture(64, 1.5, seed).mean(axis=2)
    for cx, cy in grid.centres:
        r2 = (xs - cx) ** 2 + (ys - cy) ** 2
        inside = r2 <= light_radius ** 2
        if not inside.any():
            continue
        ox, oy = rng.integers(0, 32, 2)
        tx = np.clip((xs[inside] - cx + 32 + ox) % 64, 0, 63).astype(int)
        ty = np.clip((ys[inside] - cy + 32 + oy) % 64, 0, 63).astype(int)
        img[inside] += 0.3 + 0.2 * tex[ty, tx]
    return img


@pytest.fixture(scope="module")
def small_grid() -> MicrolensGrid:
    opt = PlenopticOptics(focal_length=0.035, focus_distance=0.6, mla_pitch=130e-6,
                          mla_f_number=2.8, k=5.0, pixel_size=5.5e-6, width=400, height=300)
    return MicrolensGrid(calib_for_optics(opt), opt.width, opt.height)


def test_safe_diameter_ends_where_the_neighbours_light_arrives(small_grid):
    """Micro images of radius 0.65 D overlap their neighbours from 0.35 D out along the
    lattice directions: the measured D' lies near 0.7 D (less than the file's D - 2);
    micro images inside their cells (radius 0.45 D, dark gaps) keep the file's."""
    D = small_grid.diameter
    wide = measure_safe_diameter(_overlapping_frame(small_grid, 0.65 * D), small_grid)
    assert wide.source == "measured"
    assert 0.55 * D < wide.diameter_px < 0.8 * D
    assert wide.diameter_px < wide.file_px
    tight = measure_safe_diameter(_overlapping_frame(small_grid, 0.45 * D), small_grid)
    assert tight.source == "file"
    assert tight.diameter_px == pytest.approx(small_grid.calib.safe_diameter)
    assert WEBER == 0.02


def test_fill_takes_the_nearest_confident_lenses_and_stays_in_their_range():
    """A texture-less region (no confident lens) between two surfaces is filled from the
    confident lenses around each lens, within their range: never the smallest candidate
    that the micro images' own vignetting matched there, never a streak."""
    n = 40
    xs, ys = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float))
    centres = np.stack([xs.ravel(), ys.ravel()], axis=1)
    raw = np.where(centres[:, 0] < n / 2, 10.0, 14.0)
    conf = np.ones(len(raw))
    hole = (np.abs(centres[:, 0] - n / 2) < 8) & (np.abs(centres[:, 1] - n / 2) < 8)
    raw[hole] = 2.0  # what the vignetting matched: the smallest candidate
    conf[hole] = 0.0
    P, w, notes = fill_unreliable(raw, conf, centres, 0.25, 6.0)
    assert not notes
    assert P[hole].min() >= 10.0 and P[hole].max() <= 14.0
    left = hole & (centres[:, 0] < n / 2 - 2)
    right = hole & (centres[:, 0] > n / 2 + 1)
    assert np.all(P[left] == 10.0) and np.all(P[right] == 14.0)
    assert np.all(w[hole] < 0.2)
    trust = reliability(raw, P, conf >= 0.25, 0.5)
    assert np.all(trust[hole] == UNRELIABLE_WEIGHT) and np.all(trust[~hole] == 1.0)


def test_smoothing_leaves_no_filled_lens_outside_the_confident_range():
    """One confident lens at the search range's top among filled ones (a darkened
    HandTools: one 34.2-px match where the confident lenses span 16.4-19.3 px) outweighed
    each filled neighbour in the smoothing's weighted median and gave it 34.2 px; the
    filled lenses now stay within the confident range, and the confident lens keeps its
    own size."""
    nb_of: dict[int, list[int]] = {}
    n = 30
    xs, ys = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float))
    centres = np.stack([xs.ravel(), ys.ravel()], axis=1)
    for i in range(n * n):
        nb_of[i] = [j for j in (i - 1, i + 1, i - n, i + n, i - n + 1, i + n - 1)
                    if 0 <= j < n * n and abs(centres[j] - centres[i]).max() <= 1]
    neighbours = np.array([(v + [-1] * 6)[:6] for v in nb_of.values()])
    rng = np.random.default_rng(3)
    raw = rng.uniform(16.4, 19.3, n * n)
    conf = np.full(n * n, 0.6)  # the real frame's matched lenses: about 0.6
    dark = centres[:, 1] < 3  # the top rows: nothing to match
    conf[dark] = 0.01
    lone = 1 * n + 12  # one confident match at the range's top among them
    raw[lone], conf[lone] = 34.2, 0.43
    out, _ = fill_and_smooth(raw, conf, neighbours, centres, 0.25, 1, 17.0)
    lo, hi = np.percentile(raw[conf >= 0.25], FILL_PERCENTILES)
    filled = conf < 0.25
    assert out[filled].min() >= lo and out[filled].max() <= hi
    assert out[lone] == np.float32(34.2)
    # without the bound the smoothing carried the lone match into its filled neighbours
    unbounded = _smooth(*fill_unreliable(raw, conf, centres, 0.25, 17.0)[:2], neighbours, 1)
    assert unbounded[filled].max() == np.float32(34.2)


def test_lattice_mean_by_hand():
    """lattice_mean: the mean of a lens and the neighbours it has (-1: none), pass after
    pass; 0 passes leave the values as they are."""
    nb = np.full((3, 6), -1)
    nb[0, 0], nb[1, 0], nb[1, 1], nb[2, 0] = 1, 0, 2, 1  # a row of three lenses
    v = np.array([1.0, 0.1, 0.1], np.float32)
    assert np.array_equal(lattice_mean(v, nb, 0), v)
    one = lattice_mean(v, nb, 1)
    np.testing.assert_allclose(one, [0.55, 0.4, 0.1], rtol=1e-6)
    two = lattice_mean(v, nb, 2)
    np.testing.assert_allclose(two, [(0.55 + 0.4) / 2, (0.55 + 0.4 + 0.1) / 3, 0.25],
                               rtol=1e-6)


def test_lattice_mean_bounds_the_trust_between_adjacent_lenses():
    """One measured lens among filled ones weighs ten times each neighbour; two passes of
    the lattice mean (the blend's default) bring every adjacent pair within 2.6x, so
    that no lens takes a corner view's blend over its whole disc (issue 33's arcs),
    while a measured region still outweighs a filled one away from their border."""
    calib = calib_for_optics(PlenopticOptics(focal_length=0.035, focus_distance=0.6,
                                             mla_pitch=130e-6, mla_f_number=2.8, k=5.0,
                                             pixel_size=5.5e-6, width=480, height=300))
    grid = MicrolensGrid(calib, 480, 300)
    nb = grid.neighbours
    rng = np.random.default_rng(3)
    trust = np.where(rng.random(len(nb)) < 0.5, 1.0, UNRELIABLE_WEIGHT).astype(np.float32)

    def adjacent_ratio(t: np.ndarray) -> float:
        have = nb >= 0
        a = np.broadcast_to(t[:, None], nb.shape)[have]
        return float((a / t[nb[have]]).max())

    assert adjacent_ratio(trust) == pytest.approx(1 / UNRELIABLE_WEIGHT)
    assert adjacent_ratio(lattice_mean(trust, nb, 2)) <= 2.6
    x = grid.centres[:, 0]
    halves = np.where(x < np.median(x), 1.0, UNRELIABLE_WEIGHT).astype(np.float32)
    smooth = lattice_mean(halves, nb, 2)
    far = np.abs(x - np.median(x)) > 4 * np.linalg.norm(grid.neighbour_vectors[0])
    np.testing.assert_allclose(smooth[far], halves[far], rtol=1e-6)
