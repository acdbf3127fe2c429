"""The observations aligned by their patches (plenocal.calib.track_alignment): the patch's
affine map against hand-computed cases, Lucas-Kanade against known shifts and warps."""

import cv2
import numpy as np
import pytest

from plenocal.calib import track_alignment as ta

F = 500.0
K = np.array([[F, 0.0, 320.0], [0.0, F, 240.0], [0.0, 0.0, 1.0]])


def _one(*arrays):
    return [np.asarray(a, float)[None] for a in arrays]


def _rz(deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def test_the_affine_map_of_a_camera_moved_sideways_is_the_identity():
    X = np.array([0.1, -0.05, 2.0])
    uv = K @ X
    A = ta.local_affine(*_one(K, np.eye(3), np.zeros(3), K, np.eye(3), [-0.2, 0.0, 0.0]),
                        X[None], (uv[:2] / uv[2])[None])
    assert np.allclose(A[0], np.eye(2), atol=1e-9)


def test_the_affine_map_of_a_camera_twice_as_far_halves_the_patch():
    # the target camera 2 m behind the reference: the point at 4 m instead of 2 m
    X = np.array([0.0, 0.0, 2.0])
    A = ta.local_affine(*_one(K, np.eye(3), np.zeros(3), K, np.eye(3), [0.0, 0.0, 2.0]),
                        X[None], np.array([[320.0, 240.0]]))
    assert np.allclose(A[0], 0.5 * np.eye(2), atol=1e-9)


def test_the_affine_map_of_a_camera_turned_about_its_axis_is_the_turn():
    X = np.array([0.0, 0.0, 2.0])
    A = ta.local_affine(*_one(K, np.eye(3), np.zeros(3), K, _rz(30.0), np.zeros(3)),
                        X[None], np.array([[320.0, 240.0]]))
    assert np.allclose(A[0], _rz(30.0)[:2, :2], atol=1e-9)


def test_the_patch_offsets_are_the_affine_map_applied_to_the_grid():
    # by hand: a turn by 90 deg and a halving, on the offsets (1, 0) and (0, 2)
    A = np.array([[[0.0, -1.0], [1.0, 0.0]], [[0.5, 0.0], [0.0, 0.5]]])
    grid = np.array([[1.0, 0.0], [0.0, 2.0]])
    x, y = ta.patch_offsets(A, grid)
    assert x.dtype == y.dtype == np.float32
    assert np.array_equal(x, [[0.0, -2.0], [0.5, 0.0]])
    assert np.array_equal(y, [[1.0, 0.0], [0.0, 1.0]])
    # every entry A_i0 g_0 + A_i1 g_1 in float64, rounded once; the einsum it replaced
    # agrees (on this machine to the bit: BENCHMARKS.md, "The alignment's patch offsets")
    rng = np.random.default_rng(3)
    A = rng.standard_normal((500, 2, 2)) * rng.choice([1e-3, 1.0, 1e3], size=(500, 2, 2))
    grid, _ = ta.patch_grid(5)
    x, y = ta.patch_offsets(A, grid)
    for i, got in enumerate((x, y)):
        exact = A[:, i, 0, None] * grid[None, :, 0] + A[:, i, 1, None] * grid[None, :, 1]
        assert np.array_equal(got, exact.astype(np.float32))
        assert np.allclose(got, np.einsum("nij,kj->nki", A, grid)[..., i], rtol=1e-6, atol=0)


def test_the_reference_is_the_observation_nearest_the_tracks_middle():
    centres = np.array([[0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0], [3.0, 0, 0], [4.1, 0, 0]])
    assert ta.reference_index(centres) == 2
    assert ta.reference_index(centres[:2]) == 0  # a tie: the first


def texture(seed: int = 3, size: tuple[int, int] = (200, 240)) -> np.ndarray:
    """Blurred noise (soft, as the converter's views): float32 grey levels."""
    rng = np.random.default_rng(seed)
    img = cv2.GaussianBlur(rng.uniform(0, 255, size).astype(np.float32), (0, 0), 1.5)
    return cv2.normalize(img, None, 0, 255, cv2.NORM_MINMAX)


def warped(img: np.ndarray, M: np.ndarray) -> np.ndarray:
    """``img`` seen through the 2 x 3 map ``M`` (a target pixel x shows ``img`` at
    ``M^-1 x``)."""
    return cv2.warpAffine(img, M, img.shape[::-1], flags=cv2.INTER_CUBIC,
                          borderMode=cv2.BORDER_REFLECT)


def _points(n: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(40, 160, (n, 2))


@pytest.mark.parametrize("deg, scale, shift", [(0.0, 1.0, (0.37, -0.21)),
                                               (20.0, 1.1, (0.6, 0.3))])
def test_lucas_kanade_finds_the_translation_through_the_affine_map(deg, scale, shift):
    ref = texture()
    L = scale * _rz(deg)[:2, :2]
    c = np.array([120.0, 100.0])
    M = np.hstack([L, (c + shift - L @ c)[:, None]])  # ref pixel p -> target L (p - c) + c + s
    tgt = warped(ref, M)
    p = _points(50)
    truth = p @ L.T + (c + shift - L @ c)
    start = truth + np.random.default_rng(1).uniform(-0.4, 0.4, truth.shape)
    grid, w = ta.patch_grid(5)
    tmpl = ta.templates(ref, p, grid, w)
    u, zncc = ta.align_translations(tgt, start, np.broadcast_to(L, (len(p), 2, 2)), tmpl,
                                    grid, w, 8)
    err = np.linalg.norm(u - truth, axis=1)
    # bilinear sampling at the template's and the target's sub-pixel phases: a few
    # hundredths of a pixel, which a pure shift (one phase over the whole patch) shows most
    assert np.median(err) < 0.06, np.median(err)
    assert err.max() < 0.15, err.max()
    assert np.median(np.linalg.norm(start - truth, axis=1)) > 0.2  # it did move them
    assert np.all(zncc > 0.95)


def test_alignment_keeps_the_reference_and_sift_where_it_cannot_align_and_ignores_threads(
        monkeypatch):
    ref = texture(5)
    shift = np.array([0.3, -0.4])
    tgt = warped(ref, np.array([[1.0, 0, shift[0]], [0, 1.0, shift[1]]]))
    flat = np.full_like(ref, 100.0)  # no contrast: nothing to align on
    images = {0: ref, 1: tgt, 2: flat}
    p = _points(20, 2)
    n = len(p)
    obs = ta.Observations(
        image=np.array([1] * n + [2] * n + [1]),
        keypoint=np.vstack([p + 0.5, p + 0.5, [[2.0, 2.0]]]),  # COLMAP's convention
        ref_image=np.zeros(2 * n + 1, int),
        ref_keypoint=np.vstack([p + 0.5, p + 0.5, [[2.0, 2.0]]]),
        affine=np.broadcast_to(np.eye(2), (2 * n + 1, 2, 2)).copy())
    settings = ta.AlignSettings()
    out1, aligned1, stats = ta.align_observations(obs, images.__getitem__, settings, 1)
    out2, aligned2, stats2 = ta.align_observations(obs, images.__getitem__, settings, 2)
    assert np.array_equal(out1, out2) and np.array_equal(aligned1, aligned2)
    assert stats == stats2  # refine.json holds them: no timing, the same bytes every run
    # the templates held a batch of target images at a time: each image its own batch
    monkeypatch.setattr(ta, "BATCH_OBSERVATIONS", 1)
    assert ta._batches(ta.rows_of(obs.image), 1) == [[1], [2]]
    out3, aligned3, stats3 = ta.align_observations(obs, images.__getitem__, settings, 2)
    assert np.array_equal(out1, out3) and np.array_equal(aligned1, aligned3)
    assert stats == stats3
    assert aligned1[:n].all()
    assert np.abs(out1[:n] - (p + 0.5 + shift)).max() < 0.08  # the phases (test above)
    # the flat image, and the patch past the border, keep SIFT's keypoints
    assert not aligned1[n:].any()
    assert np.array_equal(out1[n:], obs.keypoint[n:])
    assert stats["observations"] == 2 * n + 1 and stats["aligned"] == n


def test_settings_are_checked():
    with pytest.raises(ValueError, match="radius_px"):
        ta.AlignSettings(radius_px=0)
    with pytest.raises(ValueError, match="max_shift_px"):
        ta.AlignSettings(max_shift_px=0)
    with pytest.raises(ValueError, match="min_zncc"):
        ta.AlignSettings(min_zncc=2.0)


def test_every_tracks_reference_is_reference_indexs_choice():
    """track_observations takes every track's reference at once: the observation that
    reference_index picks for the track alone (the first of a tie), and with
    may_reference, the nearest of those that may (any where none may)."""
    K = np.array([[100.0, 0, 50], [0, 100.0, 40], [0, 0, 1]])
    centres = {1: (0.0, 0, 0), 2: (1.0, 0, 0), 3: (2.0, 0, 0), 4: (-1.0, 0, 0)}
    cameras = {i: (K, np.eye(3), -np.asarray(c)) for i, c in centres.items()}
    keypoints = {i: np.array([[10.0 + i, 20.0], [30.0, 5.0 * i]]) for i in centres}
    points = {7: (np.array([0.0, 0, 5]), [(2, 0), (1, 1), (3, 0)]),  # mean at camera 2
              3: (np.array([0.5, 0, 5]), [(4, 1), (2, 1)]),  # a tie: the first
              9: (np.array([1.0, 0, 5]), [(1, 0), (2, 0), (3, 1)])}
    obs, rows = ta.track_observations(points, cameras, keypoints)
    at = 0  # the rows: the points in id order, each track but its reference in its order
    for pid in sorted(points):
        track = points[pid][1]
        ref = track[ta.reference_index(np.array([centres[i] for i, _ in track]))]
        mine = slice(at, at + len(track) - 1)
        at = mine.stop
        assert [tuple(r) for r in rows[mine].tolist()] == [el for el in track if el != ref]
        assert set(obs.ref_image[mine].tolist()) == {ref[0]}, pid
    assert at == len(rows)
    # only keypoint 0 of an image may be a reference: point 7's nearest is then camera 2
    # again, point 9's camera 2 too (keypoint 0 there), point 3's (no keypoint 0) any:
    # camera 4, the first of its tie
    obs, _ = ta.track_observations(points, cameras, keypoints,
                                   may_reference=lambda i, j: j == 0)
    assert obs.ref_image.tolist() == [4, 2, 2, 2, 2]
