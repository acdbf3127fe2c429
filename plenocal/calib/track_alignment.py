"""Every observation of a track aligned to one reference observation by its patch (beyond
the paper; the joint refinement's observations, :mod:`plenocal.calib.refine`).

Why: SIFT places a keypoint at an extremum of its scale space, and on views as soft as
the converter's (about a Gaussian of 1 px over an ideal render) where that extremum falls
moves with the local appearance, which differs between the hand-held shots' turned views
and the array's. On the simulator this leaned the refined focal length by +0.1 to +0.2 %
(BENCHMARKS.md, "SIFT on soft views"). Aligned by their pixels to one observation of the
same point, every observation sits where the same image content is, and the adjustment
sees the geometry rather than SIFT's placement (BENCHMARKS.md, "The observations aligned
by their patches").

For each track (3-D point ``X`` of the Eq. 6 triangulation):

* the **reference** observation is the one whose camera centre is nearest the mean of the
  track's camera centres (:func:`reference_index`); its keypoint stays SIFT's (an error
  there moves the whole track, i.e. the point, not the cameras);
* each other observation's **affine map** from the reference image to its own is the
  Jacobian of the homography that the plane through ``X`` facing the reference camera
  induces (:func:`local_affine`): within a set nearly the identity, across the shots the
  turn and the change of scale;
* its **translation** is found by Lucas-Kanade, inverse compositional (the template's
  gradients fixed), a patch of ``(2 radius + 1)^2`` pixels under a Gaussian weight, each
  patch's mean and contrast normalised (:func:`align_translations`); kept where it moved
  at most ``max_shift_px`` from SIFT's keypoint and the aligned patches' normalised
  correlation is at least ``min_zncc``, SIFT's keypoint otherwise.

Conventions: keypoints in COLMAP's convention (pixel centres at +0.5) in and out; image
arrays indexed by pixel centres (``keypoint - 0.5``) inside. The result is a function of
the inputs alone: each observation is computed on its own, whatever the threads.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from plenocal.config import stage_defaults
from plenocal.convert.exact import remap

_ALIGN = stage_defaults("refine")["align"]


@dataclass(frozen=True)
class AlignSettings:
    """The ``refine.align`` block of the config (config.schema.yaml documents each key)."""

    enabled: bool = _ALIGN["enabled"]
    radius_px: int = _ALIGN["radius_px"]
    iterations: int = _ALIGN["iterations"]
    max_shift_px: float = _ALIGN["max_shift_px"]
    min_zncc: float = _ALIGN["min_zncc"]

    def __post_init__(self) -> None:
        if not 1 <= int(self.radius_px) <= 32:
            raise ValueError(f"config refine.align.radius_px = {self.radius_px}: 1 to 32")
        if int(self.iterations) < 1:
            raise ValueError(f"config refine.align.iterations = {self.iterations}: at least 1")
        if not self.max_shift_px > 0:
            raise ValueError(f"config refine.align.max_shift_px = {self.max_shift_px}: "
                             "a positive number of pixels")
        if not -1.0 <= self.min_zncc <= 1.0:
            raise ValueError(f"config refine.align.min_zncc = {self.min_zncc}: -1 to 1")


@dataclass(frozen=True)
class Observations:
    """The observations to align, one row each (n rows): ``image`` (n,) the index of its
    image, ``keypoint`` (n, 2) COLMAP's convention; ``ref_image`` (n,) and ``ref_keypoint``
    (n, 2) its track's reference observation; ``affine`` (n, 2, 2) the map of
    :func:`local_affine`."""

    image: np.ndarray
    keypoint: np.ndarray
    ref_image: np.ndarray
    ref_keypoint: np.ndarray
    affine: np.ndarray


def reference_index(centres: np.ndarray) -> int:
    """The observation of a track (``centres``: (m, 3) its cameras' centres) whose camera is
    nearest the mean of them all (the first such, for ties)."""
    centres = np.asarray(centres, float)
    return int(np.argmin(np.linalg.norm(centres - centres.mean(axis=0), axis=1)))


def _back_project(K_inv: np.ndarray, R: np.ndarray, t: np.ndarray, uv: np.ndarray,
                  depth: np.ndarray) -> np.ndarray:
    """World points (n, 3) at camera depth ``depth`` (n,) along the pixels ``uv`` (n, 2) of
    cameras ``x_cam = R x + t`` (R (n, 3, 3), t (n, 3), ``K_inv`` (n, 3, 3))."""
    ray = np.einsum("nij,nj->ni", K_inv, np.concatenate([uv, np.ones((len(uv), 1))], 1))
    p_cam = ray / ray[:, 2:3] * depth[:, None]
    return np.einsum("nji,nj->ni", R, p_cam - t)


def _project(K: np.ndarray, R: np.ndarray, t: np.ndarray, X: np.ndarray) -> np.ndarray:
    c = np.einsum("nij,nj->ni", K, np.einsum("nij,nj->ni", R, X) + t)
    return c[:, :2] / c[:, 2:3]


def local_affine(K_ref: np.ndarray, R_ref: np.ndarray, t_ref: np.ndarray,
                 K: np.ndarray, R: np.ndarray, t: np.ndarray, X: np.ndarray,
                 uv_ref: np.ndarray, K_ref_inv: np.ndarray | None = None) -> np.ndarray:
    """(n, 2, 2): the derivative of the target pixel by the reference pixel at ``uv_ref``
    (n, 2) for the plane through the point ``X`` (n, 3) that faces the reference camera
    (fronto-parallel to it), i.e. the Jacobian of the homography ``K (R - t n^T / d)
    K_ref^-1`` that plane induces. Cameras as ``x_cam = R x + t`` (each (n, 3, 3) / (n, 3)),
    intrinsics ``K`` (n, 3, 3); any pixel convention, the same for both. ``K_ref_inv``:
    the inverses of ``K_ref`` where the caller has them (one per camera, not one per
    observation: the same bits)."""
    depth = np.einsum("nij,nj->ni", R_ref, X)[:, 2] + t_ref[:, 2]
    K_inv = np.linalg.inv(K_ref) if K_ref_inv is None else K_ref_inv
    p0 = _project(K, R, t, _back_project(K_inv, R_ref, t_ref, uv_ref, depth))
    cols = [_project(K, R, t, _back_project(K_inv, R_ref, t_ref, uv_ref + d, depth)) - p0
            for d in ((1.0, 0.0), (0.0, 1.0))]
    return np.stack(cols, axis=2)


def _remap(image: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``image`` sampled bilinearly at the array coordinates ``x``, ``y`` (each (n, k)
    float32) -> (n, k), for any n (:func:`plenocal.convert.exact.remap` slices the rows
    OpenCV cannot take at once)."""
    import cv2  # noqa: PLC0415

    return remap(image, x, y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def patch_grid(radius: int) -> tuple[np.ndarray, np.ndarray]:
    """The patch's offsets (k, 2) and their Gaussian weights (k,) (sigma radius / 1.5)."""
    r = np.arange(-radius, radius + 1, dtype=np.float64)
    gx, gy = np.meshgrid(r, r)
    grid = np.stack([gx.ravel(), gy.ravel()], axis=1)
    return grid, np.exp(-(grid ** 2).sum(1) / (2.0 * (radius / 1.5) ** 2))


def _grid_radius(grid: np.ndarray) -> int:
    radius = int(round(float(np.abs(grid).max())))
    if len(grid) != (2 * radius + 1) ** 2:
        raise ValueError("the patch's offsets are not patch_grid's")
    return radius


def templates(image: np.ndarray, uv: np.ndarray, grid: np.ndarray, w: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The reference patches at the array coordinates ``uv`` (n, 2) of ``image``: values,
    x and y gradients (central differences), each (n, k) float32 and mean-free under the
    weights ``w``; ``grid`` :func:`patch_grid`'s. One bilinear sampling of the patch grown
    by a pixel on each side gives all three."""
    radius = _grid_radius(grid)
    side = 2 * radius + 3
    r = np.arange(-radius - 1, radius + 2, dtype=np.float64)
    gx, gy = np.meshgrid(r, r)
    big = _remap(image, (uv[:, 0:1] + gx.ravel()).astype(np.float32),
                 (uv[:, 1:2] + gy.ravel()).astype(np.float32)).reshape(len(uv), side, side)
    values = big[:, 1:-1, 1:-1]
    dx = 0.5 * (big[:, 1:-1, 2:] - big[:, 1:-1, :-2])
    dy = 0.5 * (big[:, 2:, 1:-1] - big[:, :-2, 1:-1])
    mean_weights = (w / w.sum()).astype(np.float32)
    out = []
    for a in (values, dx, dy):
        a = a.reshape(len(uv), -1)
        out.append(np.ascontiguousarray(a - (a @ mean_weights)[:, None]))
    return out[0], out[1], out[2]


def patch_offsets(affine: np.ndarray, grid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The patch's offsets seen through each observation's affine map, ``A_n g_k``: x and
    y, each (n, k) float32, for ``affine`` (n, 2, 2) and ``grid`` (k, 2) (:func:`patch_grid`).

    Each entry is ``A_i0 g_0 + A_i1 g_1`` in float64, rounded once to float32: the bits
    ``np.einsum("nij,kj->nki", affine, grid)`` gives, whose generic loop took 0.8 s per
    65,536 observations of 121 pixels (9 s of a default capture's 20 s alignment) against
    0.1 s for the two products here."""
    a = np.asarray(affine, dtype=np.float64)
    g = np.asarray(grid, dtype=np.float64)
    out = []
    for i in (0, 1):
        v = np.multiply.outer(np.ascontiguousarray(a[:, i, 0]), g[:, 0])
        v += np.multiply.outer(np.ascontiguousarray(a[:, i, 1]), g[:, 1])
        out.append(v.astype(np.float32))
    return out[0], out[1]


def align_translations(image: np.ndarray, uv: np.ndarray, affine: np.ndarray,
                       template: tuple[np.ndarray, np.ndarray, np.ndarray],
                       grid: np.ndarray, w: np.ndarray, iterations: int
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Lucas-Kanade, inverse compositional, for the translation only: the positions (n, 2,
    array coordinates of ``image``) where the template (:func:`templates`) seen through
    ``affine`` (n, 2, 2) matches, started at ``uv``; and the aligned patches' weighted
    normalised correlation (n,). A step is at most 1 px; a patch without contrast stays
    where it started.

    Each step needs of the sampled patch ``v`` only its weighted sums: ``sum w v`` and
    ``sum w v^2`` (its mean and contrast) and ``sum w g v`` for the template's gradients
    ``g``, since those are mean-free (``sum w g (v - mean) = sum w g v``): the error
    ``gain (v - mean) - t`` is never formed."""
    t, tx, ty = (np.asarray(a, np.float32) for a in template)
    wk = np.asarray(w, np.float32)
    total = float(np.asarray(w, np.float64).sum())
    txw, tyw = tx * wk, ty * wk
    a = np.einsum("nk,nk->n", txw, tx).astype(np.float64)
    b = np.einsum("nk,nk->n", txw, ty).astype(np.float64)
    c = np.einsum("nk,nk->n", tyw, ty).astype(np.float64)
    det = a * c - b * b
    solvable = det > 1e-9 * np.maximum(a + c, 1e-12) ** 2
    det = np.where(solvable, det, 1.0)
    t_norm = np.sqrt(np.einsum("nk,nk->n", t * wk, t).astype(np.float64))
    gx_t = np.einsum("nk,nk->n", txw, t).astype(np.float64)
    gy_t = np.einsum("nk,nk->n", tyw, t).astype(np.float64)
    off_x, off_y = patch_offsets(affine, grid)
    u = np.array(uv, dtype=np.float64)
    h, wd = image.shape

    def sample(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The patch at ``u`` and its contrast (weighted, mean removed)."""
        v = _remap(image, off_x + u[:, 0:1].astype(np.float32),
                   off_y + u[:, 1:2].astype(np.float32))
        mean = (v @ wk).astype(np.float64) / total
        square = ((v * v) @ wk).astype(np.float64)
        return v, np.sqrt(np.maximum(square - total * mean * mean, 0.0))

    for _ in range(iterations):
        v, v_norm = sample(u)
        gain = np.where(v_norm > 1e-9, t_norm / np.maximum(v_norm, 1e-9), 0.0)
        ex = gain * np.einsum("nk,nk->n", txw, v) - gx_t
        ey = gain * np.einsum("nk,nk->n", tyw, v) - gy_t
        d = np.stack([(c * ex - b * ey) / det, (a * ey - b * ex) / det], axis=1)
        d = np.where(solvable[:, None], np.clip(d, -1.0, 1.0), 0.0)
        # the warp composed with the step's inverse: u - A d
        u = u - np.einsum("nij,nj->ni", affine, d)
        u[:, 0] = np.clip(u[:, 0], 0.0, wd - 1.0)
        u[:, 1] = np.clip(u[:, 1], 0.0, h - 1.0)
    v, v_norm = sample(u)
    denom = v_norm * t_norm
    vt = np.einsum("nk,nk->n", v, t * wk).astype(np.float64)  # t mean-free
    zncc = np.where(denom > 1e-9, vt / np.maximum(denom, 1e-9), 0.0)
    return u, zncc


def inside(uv: np.ndarray, affine: np.ndarray, radius: int, width: int, height: int
           ) -> np.ndarray:
    """(n,) whether the patch at ``uv`` (array coordinates) seen through ``affine`` lies in
    the image, one pixel to spare for the gradients."""
    reach = radius * np.abs(affine).sum(axis=2) + 1.5
    return ((uv - reach >= 0) & (uv + reach <= (width - 1, height - 1))).all(axis=1)


def rows_of(image: np.ndarray) -> dict[int, np.ndarray]:
    """Image index -> the rows (ascending) of ``image`` (n,) that hold it."""
    order = np.argsort(image, kind="stable")
    values, starts = np.unique(image[order], return_index=True)
    return {int(v): rows for v, rows in zip(values, np.split(order, starts[1:]), strict=True)}


#: observations whose templates are held at once (three float32 patches each): those of a
#: batch of target images, not of every observation (a 10,000-point capture's 740,000
#: observations took 1.1 GB at once)
BATCH_OBSERVATIONS = 1 << 16


def _batches(by_image: Mapping[int, np.ndarray], size: int) -> list[list[int]]:
    """The images of ``by_image`` (image -> its rows) in ascending order, cut into runs of
    at least ``size`` rows each (the last one fewer)."""
    batches: list[list[int]] = [[]]
    count = 0
    for i in sorted(by_image):
        if count >= size:
            batches.append([])
            count = 0
        batches[-1].append(i)
        count += len(by_image[i])
    return [b for b in batches if b]


def align_observations(obs: Observations, load: Callable[[int], np.ndarray],
                       settings: AlignSettings, num_threads: int
                       ) -> tuple[np.ndarray, np.ndarray, dict]:
    """The aligned keypoints (n, 2, COLMAP's convention) of ``obs``, whether each was
    aligned (n,) (SIFT's keypoint kept where not), and statistics. ``load``: image index ->
    the view's grey levels (2-D; kept as loaded, in float32 only while in use; each image
    loaded once per call, on ``num_threads`` threads; the result does not depend on
    them). The statistics hold no timing: refine.json, which holds them, must be the same
    bytes in every run."""
    n = len(obs.image)
    radius = int(settings.radius_px)
    grid, w = patch_grid(radius)
    ref_uv = obs.ref_keypoint - 0.5
    uv = obs.keypoint - 0.5
    by_ref, by_image = rows_of(obs.ref_image), rows_of(obs.image)
    images = sorted(set(by_ref) | set(by_image))
    k = len(grid)
    ok = np.zeros(n, bool)
    out = uv.copy()
    zncc = np.full(n, np.nan)
    with ThreadPoolExecutor(max(1, num_threads)) as pool:
        loaded = dict(zip(images, pool.map(load, images), strict=True))
        for i, sel in by_ref.items():
            h, wd = loaded[i].shape
            ok[sel] = inside(ref_uv[sel], np.broadcast_to(np.eye(2), (len(sel), 2, 2)),
                             radius, wd, h)
        for i, sel in by_image.items():
            h, wd = loaded[i].shape
            ok[sel] &= inside(uv[sel], obs.affine[sel], radius, wd, h)
        at = np.full(n, -1)  # a row's place among its batch's templates
        for batch in _batches(by_image, BATCH_OBSERVATIONS):
            rows = np.concatenate([by_image[i] for i in batch])
            rows = np.sort(rows[ok[rows]])
            at[rows] = np.arange(len(rows))
            tmpl = [np.empty((len(rows), k), np.float32) for _ in range(3)]
            by_batch_ref = rows_of(obs.ref_image[rows])

            def template(i: int, rows=rows, tmpl=tmpl, by_batch_ref=by_batch_ref) -> None:
                sub = by_batch_ref[i]
                parts = templates(loaded[i].astype(np.float32), ref_uv[rows[sub]], grid, w)
                for arr, part in zip(tmpl, parts, strict=True):
                    arr[sub] = part

            list(pool.map(template, sorted(by_batch_ref)))

            def one(i: int, tmpl=tmpl) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
                sel = by_image[i][ok[by_image[i]]]
                if not sel.size:
                    return sel, np.zeros((0, 2)), np.zeros(0)
                u, z = align_translations(loaded[i].astype(np.float32), uv[sel],
                                          obs.affine[sel], tuple(t[at[sel]] for t in tmpl),
                                          grid, w, int(settings.iterations))
                return sel, u, z

            for sel, u, z in pool.map(one, batch):
                out[sel] = u
                zncc[sel] = z
    shift = np.linalg.norm(out - uv, axis=1)
    aligned = ok & (shift <= settings.max_shift_px) & (zncc >= settings.min_zncc)
    out = np.where(aligned[:, None], out, uv) + 0.5
    stats = {"observations": int(n), "aligned": int(aligned.sum()),
             "aligned_share": float(aligned.mean()) if n else 0.0,
             "shift_median_px": float(np.median(shift[aligned])) if aligned.any() else None,
             "zncc_median": float(np.nanmedian(zncc)) if np.isfinite(zncc).any() else None,
             "images": int(len(loaded))}
    return out, aligned, stats


def track_observations(points: Mapping[int, tuple[np.ndarray, list[tuple[int, int]]]],
                       cameras: Mapping[int, tuple[np.ndarray, np.ndarray, np.ndarray]],
                       keypoints: Mapping[int, np.ndarray],
                       may_reference: Callable[[np.ndarray, np.ndarray], np.ndarray]
                       | None = None) -> tuple[Observations, np.ndarray]:
    """The observations to align of ``points`` (point id -> (X (3,), its track's (image
    id, keypoint index) pairs)), each track's reference observation left out
    (:func:`reference_index`). ``cameras``: image id -> (K, R, t) in COLMAP's pixel
    convention, ``x_cam = R x + t``; ``keypoints``: image id -> (m, 2). ``may_reference``
    (image ids (e,), keypoint indices (e,)) -> whether each observation may be its track's
    reference (bool (e,); the one of those nearest the mean of all the track's camera
    centres; any where None, or where the track has none that may). Returns them and each
    row's (image id, keypoint index), (n, 2): the points in id order, each track's
    observations in its order.

    Every track at once (numpy: the default data's two track sets in 0.8 and 1.5 s
    against 1.5-3.8 s a loop over the points took; the same bits): each track's mean
    centre summed in its order (``add.reduceat``), as ``mean(axis=0)`` sums a track's
    rows."""
    ids = sorted(cameras)
    KK, RR, TT = (np.stack([cameras[i][m] for i in ids]) for m in range(3))
    centres = np.stack([-cameras[i][1].T @ cameras[i][2] for i in ids])
    pids = sorted(points)
    lengths = np.array([len(points[p][1]) for p in pids], dtype=np.intp)
    none = (Observations(np.zeros(0, int), np.zeros((0, 2)), np.zeros(0, int),
                         np.zeros((0, 2)), np.zeros((0, 2, 2))), np.zeros((0, 2), int))
    if not lengths.sum():
        return none
    els = np.array([el for p in pids for el in points[p][1]], dtype=np.int64).reshape(-1, 2)
    cam_of = np.searchsorted(np.asarray(ids, dtype=np.int64), els[:, 0])
    start = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    track = np.repeat(np.arange(len(pids)), lengths)
    c = centres[cam_of]
    mean = np.add.reduceat(c, start, axis=0) / lengths[:, None]
    d = np.linalg.norm(c - mean[track], axis=1)
    if may_reference is not None:
        cand = np.asarray(may_reference(els[:, 0], els[:, 1]), dtype=bool)
        d = np.where(cand | ~np.logical_or.reduceat(cand, start)[track], d, np.inf)
    # each track's reference: its first observation of least distance
    ref = np.lexsort((np.arange(len(els)), d, track))[start]
    keep = np.ones(len(els), bool)
    keep[ref] = False
    if not keep.any():
        return none
    rows, owner = els[keep], track[keep]
    refs = els[ref][owner]  # each row's reference (image id, keypoint index)
    cam, ref_cam = cam_of[keep], cam_of[ref][owner]
    flat = [np.asarray(keypoints[i], float).reshape(-1, 2) for i in ids]
    first = np.concatenate([[0], np.cumsum([len(f) for f in flat])[:-1]])
    flat = np.concatenate(flat)
    kp = flat[first[cam] + rows[:, 1]]
    ref_kp = flat[first[ref_cam] + refs[:, 1]]
    xyz = np.stack([np.asarray(points[p][0], float) for p in pids])[owner]
    A = local_affine(KK[ref_cam], RR[ref_cam], TT[ref_cam], KK[cam], RR[cam], TT[cam], xyz,
                     ref_kp, np.linalg.inv(KK)[ref_cam])
    return Observations(rows[:, 0], kp, refs[:, 0], ref_kp, A), rows
