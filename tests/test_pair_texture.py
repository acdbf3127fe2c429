"""The matching pairs weighted by their texture (Eq. M1, plenocal.convert.patchsize)."""

from __future__ import annotations

import numpy as np
from synth.lenslets import _owner, calib_for_optics, lenslet_from_patch_size, random_texture
from test_convert import small_optics

import plenocal.convert.patchsize as ps
from plenocal.grid import MicrolensGrid


def test_pair_texture_by_hand():
    s0 = 0.02
    w = ps.pair_texture(np.array([0.0, 0.005, 0.01, 0.02, 0.5], np.float32), s0)
    eps = ps.FLAT_PAIR_WEIGHT
    assert np.allclose(w, [eps, 0.25 + eps, 0.5 + eps, 1 + eps, 1 + eps])
    assert np.array_equal(ps.pair_texture(np.array([0.0, 0.3]), None), [1.0, 1.0])


def test_pair_weights_by_hand():
    """A pair weighs its texture where it is flattest over the candidates, relative to its
    lens's most textured pair; a pair never scored weighs 0; a lens whose pairs are all
    flat weighs them alike."""
    nan = np.nan
    tex = np.array([
        [[1.0, 1.0, 1.0], [1.0, 0.2, 1.0], [nan, nan, nan]],  # one pair flat at one size
        [[0.4, 0.5, 0.6], [0.2, 0.2, nan], [0.1, 0.3, 0.2]],  # every pair weak
        [[1e-3, 1e-3, 1e-3], [1e-3, 1e-3, 1e-3], [1e-3, 1e-3, 1e-3]],  # nothing at all
    ], np.float32)
    w = ps.pair_weights(tex)
    assert w.dtype == np.float32
    assert np.allclose(w, [[1.0, 0.2, 0.0], [1.0, 0.5, 0.25], [1.0, 1.0, 1.0]])


def edge_over_faint_black(p_true: float, p_wrong: float, amplitude: float):
    """A plane at patch size ``p_true`` whose texture ends at a horizontal edge below
    which the scene is black but for a faint pattern that matches at ``p_wrong`` (a
    dark background's remnants of structure). Returns (grid, image, the lenses whose
    centre block the edge crosses)."""
    opt = small_optics(480, 360)
    calib = calib_for_optics(opt)
    grid = MicrolensGrid(calib, 480, 360)
    tex = random_texture(512, 1.5, 1)
    row = int(256 + 180 / (calib.diameter / p_true))  # the edge across the sensor's middle
    top = tex.copy()
    top[row:] = 0.0
    below = np.zeros_like(tex)
    below[row:] = 1.0
    faint = 0.03 + amplitude * (random_texture(512, 1.5, 2) - 0.5)
    black = lenslet_from_patch_size(grid, p_true, below)[..., 0] > 127
    img = np.where(black[..., None], lenslet_from_patch_size(grid, p_wrong, faint),
                   lenslet_from_patch_size(grid, p_true, top))
    _, centre, dist = _owner(grid)
    # each pixel's lens: its owner's lattice index looked up among the grid's lenses
    ij = np.rint((centre - grid.origin) @ np.linalg.inv(grid.A).T).astype(np.int64)
    lo = grid.ij.min(axis=0)
    table = np.full(tuple(grid.ij.max(axis=0) - lo + 1), -1, np.int64)
    table[tuple((grid.ij - lo).T)] = np.arange(len(grid))
    local = ij - lo
    known = np.all((local >= 0) & (local < table.shape), axis=-1)
    lens = np.full(known.shape, -1, np.int64)
    lens[known] = table[tuple(local[known].T)]
    block = (dist < calib.safe_diameter / 7) & (lens >= 0)  # the centre block's reach
    count = np.bincount(lens[block], minlength=len(grid))
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.bincount(lens[block], weights=black[block], minlength=len(grid)) / count
    return grid, img, grid.inside() & (share > 0.25) & (share < 0.75)


def test_flat_pairs_do_not_outvote_the_edge():
    """Lenses on the edge: their pairs below it see only the faint black, whose chance
    match at another size outvoted the pairs that see the edge (Boxer's board). With the
    pairs weighted by their texture the edge decides; every pair weighing the same, the
    faint pattern pulls the matches off (the bias the weights remove)."""
    p_true = 8.0
    grid, img, edge = edge_over_faint_black(p_true, 5.0, 0.03)
    assert edge.sum() >= 10
    res = ps.estimate_patch_size(img, grid, ps.PatchSizeSettings(pair_weights=True))
    err = np.abs(res.raw[edge] - p_true)
    assert np.median(err) < 0.3, np.median(err)
    assert not np.any((err > 1.0) & res.confident[edge])
    plain = ps.estimate_patch_size(img, grid, ps.PatchSizeSettings(pair_weights=False))
    assert np.median(np.abs(plain.raw[edge] - p_true)) > 0.4


def textured_plane():
    """A textured plane at patch size 6 px on a small grid: (grid, grey image, candidate
    sizes, block radius)."""
    calib = calib_for_optics(small_optics(320, 240))
    grid = MicrolensGrid(calib, 320, 240)
    img = lenslet_from_patch_size(grid, 6.0, random_texture(512, 1.5, 3))
    return grid, ps.to_gray(img), np.arange(3.0, 9.01, 0.5), calib.safe_diameter / 7


def test_textured_pairs_score_as_their_plain_mean():
    """Where every block carries texture (weights saturated), the weighted score is the
    plain mean ZNCC of the lens's pairs: the weights change nothing on a textured plane."""
    grid, gray, cand, r = textured_plane()
    weighted, _, _ = ps.match_scores(gray, grid, cand, r, 9, texture_scale=1e-6)
    plain, _, _ = ps.match_scores(gray, grid, cand, r, 9, texture_scale=None)
    inner = grid.inside()
    assert np.allclose(weighted[inner], plain[inner], atol=1e-5)


def test_match_scores_are_the_same_bits_lens_chunk_by_chunk(monkeypatch):
    """match_scores makes its block maps and squared blocks a chunk of lenses at a time
    (memory on 40-MP sensors): chunks of 7 lenses give the bits of one chunk of all, with
    the second ring, vignetting gains and pair weights."""
    from plenocal.convert.vignetting import lens_type_profiles

    grid, gray, cand, r = textured_plane()
    vig = lens_type_profiles(gray, grid)
    runs = []
    for chunk in (7, 10**6):
        monkeypatch.setattr(ps, "LENS_CHUNK", chunk)
        runs.append(ps.match_scores(gray, grid, cand, r, 9, ring2=True, vignetting=vig,
                                    texture_scale=0.02))
    assert len(grid) > 7 * 3
    for a, b in zip(*runs, strict=True):
        assert np.array_equal(a, b, equal_nan=True)
