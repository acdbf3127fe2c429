"""Fronto-parallel plane sweep stereo on the CPU (OpenCV warps and box filters, the
per-pixel passes compiled in :mod:`plenocal.depth.costkernels`).

For every depth label ``d`` (uniform in inverse depth between ``near`` and ``far``)
each source image is warped onto the reference by the homography induced by the
plane ``n^T X_r = d`` (``n = (0, 0, 1)``, reference camera frame). With
``[R | t] = world_to_cam_s @ cam_to_world_r`` a reference point on the plane maps to
the source as ``X_s = (R + t n^T / d) X_r``, so the reference-to-source pixel
homography is::

    H(d) = K_s (R + t n^T / d) K_r^-1

(used with ``cv2.WARP_INVERSE_MAP``: reference pixel -> source sampling position).

Matching cost per source: ``zncc`` (1 - zero-mean normalised cross-correlation over a
window, insensitive to the gain/offset differences of subaperture views) or ``tad``
(truncated absolute difference of colour and gradient, box-aggregated). Occlusions:
per pixel and label the mean of the best ``ceil(S * best_fraction)`` source costs.
Winner-take-all with parabolic sub-label refinement (in inverse depth), then pixels
are marked invalid (0) when: the best label is at the end of the range, the
aggregated cost exceeds ``max_cost``, the best/second-best cost ratio exceeds
``uniqueness`` (second best taken outside +-1 label), the reference texture is too
weak, the optional left-right check against a source depth map fails, or the pixel
lies in a small connected region (``cv2.filterSpeckles``).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import cv2
import numpy as np

from plenocal.camera import PinholeCamera
from plenocal.config import stage_defaults
from plenocal.depth.costkernels import (
    mask_box_uncovered,
    mask_uncovered,
    mean_of_best,
    tad_pixels,
    tad_pixels_cover,
    wta_labels,
)
from plenocal.io.files import to_float

_DEPTH = stage_defaults("depth")


@dataclass(frozen=True)
class PlaneSweepOptions:
    """The plane sweep's settings; defaults: the ``depth`` block of config.schema.yaml."""
    num_depths: int | None = _DEPTH["num_depths"]  # None: from the sources' disparity range
    labels_per_px: float = _DEPTH["labels_per_px"]  # auto label count per px of disparity
    min_depths: int = _DEPTH["min_depths"]
    max_depths: int = _DEPTH["max_depths"]
    cost: str = _DEPTH["cost"]  # tad | zncc
    window: int = _DEPTH["window"]  # matching / aggregation window (odd)
    best_fraction: float = _DEPTH["best_fraction"]  # share of sources averaged (occlusions)
    max_cost: float = _DEPTH["max_cost"]  # tad: normalised truncated difference; zncc: 1 - ncc
    uniqueness: float = _DEPTH["uniqueness"]  # best / second-best cost above this: ambiguous
    min_texture: float = _DEPTH["min_texture"]  # std of the reference grey in the window (0..1)
    lr_check: bool = _DEPTH["lr_check"]  # left-right check against the nearest source
    lr_tolerance: float = _DEPTH["lr_tolerance"]  # relative depth agreement of that check
    speckle_size: int = _DEPTH["speckle_size"]  # connected regions below this many px removed
    speckle_labels: float = _DEPTH["speckle_labels"]  # label jump that separates regions


def _grey(img: np.ndarray) -> np.ndarray:
    img = to_float(np.asarray(img))
    if img.ndim == 3:
        img = img.mean(axis=2)
    return np.ascontiguousarray(img)


def _features(img: np.ndarray) -> np.ndarray:
    """Channels warped per plane: grey, x/y gradients (for tad) and a fourth of ones that
    nothing reads: OpenCV warps four float channels as fast as one (three take 2.5x as
    long)."""
    g = _grey(img)
    gx = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    gy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3) / 8.0
    ones = np.ones_like(g)
    return np.ascontiguousarray(np.stack([g, gx, gy, ones], axis=-1))


def relative_pose(ref: PinholeCamera, src: PinholeCamera) -> tuple[np.ndarray, np.ndarray]:
    """(R, t) with X_src = R X_ref + t."""
    M = src.world_to_cam @ ref.cam_to_world
    return M[:3, :3], M[:3, 3]


def plane_homography(ref: PinholeCamera, src: PinholeCamera, depth: float) -> np.ndarray:
    """Reference-to-source pixel homography of the plane z_ref = depth."""
    R, t = relative_pose(ref, src)
    n = np.array([0.0, 0.0, 1.0])
    H = src.K @ (R + np.outer(t, n) / depth) @ np.linalg.inv(ref.K)
    return H / H[2, 2]


def disparity_range_px(ref: PinholeCamera, src: PinholeCamera, near: float, far: float) -> float:
    """Largest pixel displacement, over the image corners and centre, between the
    near and far planes (sets the label count)."""
    W, Hh = ref.width, ref.height
    pts = np.array([[0, 0], [W - 1, 0], [0, Hh - 1], [W - 1, Hh - 1],
                    [(W - 1) / 2, (Hh - 1) / 2]], dtype=np.float64)
    ph = np.concatenate([pts, np.ones((len(pts), 1))], axis=1)
    out = []
    for d in (near, far):
        q = ph @ plane_homography(ref, src, d).T
        out.append(q[:, :2] / q[:, 2:3])
    return float(np.max(np.linalg.norm(out[0] - out[1], axis=1)))


def depth_labels(near: float, far: float, n: int) -> np.ndarray:
    """Depths of ``n`` labels uniform in inverse depth, near first."""
    return (1.0 / np.linspace(1.0 / near, 1.0 / far, n)).astype(np.float64)


def choose_num_depths(ref: PinholeCamera, srcs: list[PinholeCamera], near: float, far: float,
                      opt: PlaneSweepOptions) -> int:
    if opt.num_depths is not None:
        return int(opt.num_depths)
    rng = max(disparity_range_px(ref, s, near, far) for s in srcs)
    n = int(math.ceil(rng * opt.labels_per_px)) + 1
    return int(np.clip(n, opt.min_depths, opt.max_depths))


def _box(x: np.ndarray, w: int, out: np.ndarray | None = None) -> np.ndarray:
    return cv2.boxFilter(x, cv2.CV_32F, (w, w), dst=out, normalize=True,
                         borderType=cv2.BORDER_REFLECT)


def plane_homographies(ref: PinholeCamera, src: PinholeCamera,
                       depths: np.ndarray) -> np.ndarray:
    """(D, 3, 3) reference-to-source homographies of the planes z_ref = depths, as
    ``H(d) = K_s R K_r^-1 + K_s t n^T K_r^-1 / d`` (the two terms computed once)."""
    R, t = relative_pose(ref, src)
    k_inv = np.linalg.inv(ref.K)
    a = src.K @ R @ k_inv
    b = src.K @ np.outer(t, [0.0, 0.0, 1.0]) @ k_inv
    hs = a[None] + b[None] / np.asarray(depths, np.float64)[:, None, None]
    return hs / hs[:, 2:3, 2:3]


def _source_cost(ref_feat: np.ndarray, ref_stats: tuple, warped: np.ndarray,
                 hom: np.ndarray, src_size: tuple[int, int], opt: PlaneSweepOptions,
                 out: np.ndarray | None = None, scratch: np.ndarray | None = None,
                 cover: str = "homography", cover_plane: np.ndarray | None = None,
                 ) -> np.ndarray:
    """Cost of one source, warped onto the reference by the homography ``hom`` (reference
    -> source pixels), +inf where the window leaves the source image (``src_size``:
    width, height). ``cover``: ``homography`` tests the window's pixels' sampling
    positions (:func:`plenocal.depth.costkernels.mask_uncovered`), ``warped`` the
    box-filtered warped coverage channel (:func:`plenocal.depth.costkernels.
    mask_box_uncovered`: a fifth of the cost more; SGM's choice, see :func:`source_costs`).
    Written into ``out`` when given; ``scratch`` and ``cover_plane``: (H, W) float32 planes
    the tad cost and the ``warped`` test may reuse."""
    w = opt.window
    coverage = None  # the warped coverage channel as a plane, where a step copied it out
    if opt.cost == "tad":
        # 0.3 min(|dI|, 0.08) / 0.08 + 0.7 min(|dIx| + |dIy|, 0.04) / 0.04, box-aggregated
        dc = scratch if scratch is not None else np.empty(warped.shape[:2], np.float32)
        if cover == "warped":  # the coverage channel copied out in the same pass
            coverage = cover_plane if cover_plane is not None else np.empty_like(dc)
            tad_pixels_cover(ref_feat, warped, dc, coverage)
        else:
            tad_pixels(ref_feat, warped, dc)
        out = _box(dc, w, out)
    elif opt.cost == "zncc":
        mr, sr = ref_stats
        s = np.ascontiguousarray(warped[..., 0])
        ms = _box(s, w)
        vs = np.maximum(_box(s * s, w) - ms * ms, 0.0)
        cov = _box(ref_feat[..., 0] * s, w) - mr * ms
        ncc = cov / np.sqrt(np.maximum(sr * sr * vs, 1e-12))
        cost = (1.0 - np.clip(ncc, -1.0, 1.0)).astype(np.float32)
        if out is None:
            out = cost
        else:
            out[...] = cost
    else:
        raise ValueError(f"depth: unknown matching cost {opt.cost!r} (use zncc or tad)")
    if cover == "homography":
        mask_uncovered(np.ascontiguousarray(hom, dtype=np.float64), float(src_size[0]),
                       float(src_size[1]), w // 2, out)
    elif cover == "warped":
        # the box of the coverage channel into the scratch plane (free again after the cost)
        if coverage is None:
            coverage = np.ascontiguousarray(warped[..., 3])
        mask_box_uncovered(_box(coverage, w, scratch), out)
    else:
        raise ValueError(f"depth: unknown coverage test {cover!r} (homography or warped)")
    return out


def source_costs(ref: PinholeCamera, ref_img: np.ndarray, srcs: list[PinholeCamera],
                 src_imgs: list[np.ndarray], depths: np.ndarray,
                 opt: PlaneSweepOptions, cover: str = "homography") -> Iterator[np.ndarray]:
    """Per depth label, in order: the (S, H, W) float32 costs of the S sources warped onto
    the reference by the plane homography (+inf where the window leaves a source; ``cover``
    as :func:`_source_cost`'s).

    The plane sweep's and SGM's shared inner loop; one buffer is yielded again and again
    (overwritten at the next label: reduce it before asking for the next). SGM keeps the
    warped coverage channel's test: the two tests differ only within a fiftieth of a pixel
    of a source's border, but SGM carries a changed cost along its paths - on the default
    run the SGM maps of Exp. 1 kept 55 % of their values, their share within 1 % of the
    truth moved by -0.5 to +0.4 points, and Exp. 1's PSNR by -0.23 dB (issue 15); the
    registrations' plane sweep has no paths (A's maps 99.6 % the same values, B's the same
    bits)."""
    ref_feat = _features(ref_img)
    w = opt.window
    mr = _box(ref_feat[..., 0], w)
    sr = np.sqrt(np.maximum(_box(ref_feat[..., 0] ** 2, w) - mr * mr, 0.0))
    src_feat = [_features(im) for im in src_imgs]
    homs = [plane_homographies(ref, sc, depths) for sc in srcs]
    size = (ref.width, ref.height)
    per = np.empty((len(srcs), ref.height, ref.width), dtype=np.float32)
    warped = np.empty((ref.height, ref.width, 4), dtype=np.float32)
    scratch = np.empty(per.shape[1:], np.float32)
    cover_plane = np.empty(per.shape[1:], np.float32) if cover == "warped" else None
    flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
    for i in range(len(depths)):
        for j, sf in enumerate(src_feat):
            cv2.warpPerspective(sf, homs[j][i], size, dst=warped, flags=flags,
                                borderMode=cv2.BORDER_CONSTANT, borderValue=0)
            _source_cost(ref_feat, (mr, sr), warped, homs[j][i], (srcs[j].width,
                         srcs[j].height), opt, out=per[j], scratch=scratch, cover=cover,
                         cover_plane=cover_plane)
        yield per


def cost_volume(ref: PinholeCamera, ref_img: np.ndarray, srcs: list[PinholeCamera],
                src_imgs: list[np.ndarray], depths: np.ndarray,
                opt: PlaneSweepOptions) -> np.ndarray:
    """Aggregated cost (D, H, W), best-k over the sources, +inf where no source sees."""
    S = len(srcs)
    k = max(1, int(math.ceil(S * opt.best_fraction)))
    vol = np.empty((len(depths), ref.height, ref.width), dtype=np.float32)
    for i, per in enumerate(source_costs(ref, ref_img, srcs, src_imgs, depths, opt)):
        mean_of_best(per, k, vol[i])
    return vol


def winner_take_all(vol: np.ndarray, depths: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                                   np.ndarray, np.ndarray]:
    """Best label (the first minimum), sub-label inverse depth -> depth, best cost and
    second-best cost (outside +-1 label) per pixel of the cost volume ``vol`` (D, H, W),
    whose non-finite costs count as 1e6 (:func:`plenocal.depth.costkernels.wta_labels`)."""
    D, H, W = vol.shape
    inv = 1.0 / np.asarray(depths, np.float64)
    step = (inv[-1] - inv[0]) / (D - 1)
    best = np.empty((H, W), np.int64)
    depth = np.empty((H, W), np.float32)
    c0 = np.empty((H, W), np.float32)
    second = np.empty((H, W), np.float32)
    wta_labels(np.ascontiguousarray(vol, dtype=np.float32), float(inv[0]), float(step), best,
               depth, c0, second)
    return best, depth, c0, second


def _remove_speckles(labels: np.ndarray, valid: np.ndarray, size: int,
                     jump: float) -> np.ndarray:
    if size <= 0:
        return valid
    lab = np.where(valid, np.rint(labels * 16.0), -16).astype(np.int16)
    cv2.filterSpeckles(lab, -16, int(size), int(round(jump * 16)))
    return valid & (lab != -16)


def _sweep(ref: PinholeCamera, ref_img: np.ndarray, srcs: list[PinholeCamera],
           src_imgs: list[np.ndarray], near: float, far: float,
           opt: PlaneSweepOptions) -> tuple[np.ndarray, np.ndarray]:
    """Depth (0 invalid) and the continuous label map, without the left-right check."""
    n = choose_num_depths(ref, srcs, near, far, opt)
    depths = depth_labels(near, far, n)
    vol = cost_volume(ref, ref_img, srcs, src_imgs, depths, opt)
    best, depth, c0, second = winner_take_all(vol, depths)
    g = _grey(ref_img)
    m = _box(g, opt.window)
    std = np.sqrt(np.maximum(_box(g * g, opt.window) - m * m, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = c0 / np.maximum(second, 1e-9)
    valid = ((best > 0) & (best < n - 1) & (c0 <= opt.max_cost) & (ratio <= opt.uniqueness)
             & (std >= opt.min_texture) & np.isfinite(depth) & (depth > 0))
    inv = 1.0 / np.maximum(depth, 1e-12)
    cont = (inv - 1.0 / near) / ((1.0 / far - 1.0 / near) / (n - 1))
    valid = _remove_speckles(cont, valid, opt.speckle_size, opt.speckle_labels)
    return np.where(valid, depth, 0.0).astype(np.float32), cont


def left_right_check(ref: PinholeCamera, depth: np.ndarray, src: PinholeCamera,
                     src_depth: np.ndarray, tol: float) -> np.ndarray:
    """Valid where the reference point, projected into the source, meets the source's
    own depth map within ``tol`` (relative), i.e. both maps see the same surface."""
    Hh, W = depth.shape
    ys, xs = np.mgrid[0:Hh, 0:W].astype(np.float64)
    uv = np.stack([xs, ys], axis=-1)
    X = ref.unproject(uv, depth.astype(np.float64))
    uvs, zs = src.project(X)
    mx = uvs[..., 0].astype(np.float32)
    my = uvs[..., 1].astype(np.float32)
    sd = cv2.remap(src_depth.astype(np.float32), mx, my, cv2.INTER_NEAREST,
                   borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    inside = ((mx >= 0) & (mx <= src.width - 1) & (my >= 0) & (my <= src.height - 1)
              & (zs > 0))
    agree = (sd > 0) & (np.abs(sd - zs) <= tol * zs)
    # outside the source's image the check cannot be made: keep those pixels
    return (depth > 0) & (agree | ~inside)


def check_sweep_inputs(ref: PinholeCamera, ref_img: np.ndarray, srcs: list[PinholeCamera],
                       near: float, far: float, what: str) -> np.ndarray:
    """The checks every depth estimator makes of its inputs; the reference as an array."""
    if not srcs:
        raise ValueError(f"{what} needs at least one source view")
    if not 0 < near < far:
        raise ValueError(f"{what} needs 0 < near < far (got {near}, {far})")
    ref_img = np.asarray(ref_img)
    if ref_img.shape[:2] != (ref.height, ref.width):
        raise ValueError(f"reference image is {ref_img.shape[1]}x{ref_img.shape[0]}, its camera "
                         f"says {ref.width}x{ref.height}")
    return ref_img


def consistency_partner(ref: PinholeCamera, ref_img: np.ndarray, srcs: list[PinholeCamera],
                        src_imgs: list[np.ndarray]) -> tuple[int, list, list]:
    """For the left-right check: the source nearest the reference (by camera centre), and
    its own sources - the reference and the other sources - with their images."""
    dist = [np.linalg.norm(s.centre - ref.centre) for s in srcs]
    j = int(np.argmin(dist))
    others = [ref] + [s for i, s in enumerate(srcs) if i != j]
    other_imgs = [ref_img] + [im for i, im in enumerate(src_imgs) if i != j]
    return j, others, other_imgs


def plane_sweep_unchecked(ref: PinholeCamera, ref_img: np.ndarray, srcs: list[PinholeCamera],
                          src_imgs: list[np.ndarray], near: float, far: float,
                          opt: PlaneSweepOptions | None = None) -> np.ndarray:
    """:func:`plane_sweep_depth` without the left-right check, whatever ``opt.lr_check``
    says: for maps that are checked against each other (:func:`plenocal.depth.shot.
    depths_a`)."""
    opt = opt or PlaneSweepOptions()
    ref_img = check_sweep_inputs(ref, ref_img, srcs, near, far, "plane sweep")
    return _sweep(ref, ref_img, srcs, src_imgs, near, far, opt)[0]


def plane_sweep_depth(ref: PinholeCamera, ref_img: np.ndarray, srcs: list[PinholeCamera],
                      src_imgs: list[np.ndarray], near: float, far: float,
                      opt: PlaneSweepOptions | None = None) -> np.ndarray:
    """Float32 z-depth map of the reference (cameras' units), 0 where unreliable."""
    opt = opt or PlaneSweepOptions()
    ref_img = check_sweep_inputs(ref, ref_img, srcs, near, far, "plane sweep")
    depth, _ = _sweep(ref, ref_img, srcs, src_imgs, near, far, opt)
    if opt.lr_check:
        j, others, other_imgs = consistency_partner(ref, ref_img, srcs, src_imgs)
        src_depth, _ = _sweep(srcs[j], src_imgs[j], others, other_imgs, near, far, opt)
        ok = left_right_check(ref, depth, srcs[j], src_depth, opt.lr_tolerance)
        depth = np.where(ok, depth, 0.0).astype(np.float32)
    return depth
