"""Depth-image-based rendering in the manner of MPEG's Reference View Synthesizer
(RVS): every input view (camera, image, z-depth) is unprojected with its depth,
warped to the target camera, z-tested, blended by quality, and the remaining holes
are inpainted.

Warping is "depth forward, colour backward": the input's 3-D points are splatted
into the target as 2x2 pixel quads with a z-buffer (the pixels within a pixel of the
point, :data:`SPLAT_REACH`: the equivalent of rasterising RVS's triangle mesh for
magnifications below two, without its stretched triangles across depth discontinuities,
which are simply not drawn), then each covered target
pixel is unprojected with its splatted depth and projected back into the input,
where the colour is sampled bilinearly (``cv2.remap``). A target pixel is kept from
an input only if the input's own depth there agrees (occlusion check).

Blending (RVS's soft z-test and quality weights): per target pixel every input that
sees it is averaged with weights ``(z_near / z_i)^depth_exponent / (|C_i - C_t|^2 +
eps^2)``, z_near being the nearest of the inputs' depths there: nearer surfaces win
smoothly, as RVS's ``(quality / z)^BlendingFactor``, and closer cameras (which see the
target rays at smaller angles) count more; the weights are reduced at the input's
depth discontinuities (stretched mesh triangles in RVS) and where the input depth was
filled rather than measured. A hard z-test (only inputs within ``z_tolerance``,
relative, of the nearest surface) is optional: with estimated depth it lets a distant
input whose depth is a few per cent too near replace the nearest input's correct
sample (-1.4 dB on Exp. 1 of the default data, README 'DIBR and RVS').
Holes (pixels no input sees: disocclusions) are filled along the image rows by linear
interpolation between the seen pixels on either side - what RVS's triangles stretched
across a depth discontinuity draw - and what remains (holes open to the image border)
by push-pull interpolation.

What does not depend on the target is computed once per input (:class:`PreparedView`:
dense depth, its discontinuities); the colour is sampled only where a sample is blended.
Each step keeps the arithmetic and order of the straightforward version
(tests/synth/dibr_previous.py), so the renders are the same bits (since the seventeenth
session both take an integer depth exponent's power as the float64 one rounded to
float32, not powf's: see :func:`_blend`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numba
import numpy as np

from plenocal.camera import PinholeCamera
from plenocal.config import stage_defaults
from plenocal.io.files import to_float

_DIBR = stage_defaults("verify.dibr")


@dataclass(frozen=True)
class DibrOptions:
    """The DIBR's settings; defaults: ``verify.dibr`` of config.schema.yaml (but
    ``distance_eps``, which the config does not set)."""
    z_tolerance: float | None = _DIBR["z_tolerance"]  # hard z-test: relative depth band
    occlusion_tolerance: float = _DIBR["occlusion_tolerance"]  # backward check, input depth
    edge_ratio: float = _DIBR["edge_ratio"]  # depth jump (max/min in 3x3): a discontinuity
    edge_weight: float = _DIBR["edge_weight"]  # weight of samples at discontinuities
    filled_weight: float = _DIBR["filled_weight"]  # weight of samples of filled input depth
    distance_eps: float = 1e-3  # metres (or model units): weight regulariser
    inpaint: bool = _DIBR["inpaint"]
    interpolation: str = _DIBR["interpolation"]  # colour sampling: cubic or linear (as RVS)
    hole_fill: str = _DIBR["hole_fill"]  # rows (along rows, as RVS) or pushpull
    depth_exponent: float = _DIBR["depth_exponent"]  # soft z-test: (z_nearest / z) ** this


_INTERPOLATION = {"linear": cv2.INTER_LINEAR, "cubic": cv2.INTER_CUBIC}


@dataclass
class View:
    camera: PinholeCamera
    image: np.ndarray  # float32 (H, W, C) or (H, W)
    depth: np.ndarray  # float32 z-depth, 0 = invalid


@numba.njit(cache=True, nogil=True)
def _push(v, w, weigh):  # pragma: no cover - numba
    """One push level: 2x2 block sums of the values (``weigh``: of the products ``v * w``,
    each the float32 one numpy's ``v * w[..., None]`` gives, without forming their
    image; ``w`` 1 or 0) and of the weights, odd sizes padded with zeros, in float32 as
    the levels, summed in the order numpy's ``reshape(H2, 2, W2, 2, C).sum(axis=(1, 3))``
    takes (one channel: the two row pairs, then their sum; more: the four values in row
    order)."""
    H, W, C = v.shape
    H2, W2 = (H + 1) // 2, (W + 1) // 2
    dv = np.zeros((H2, W2, C), np.float32)
    dw = np.zeros((H2, W2), np.float32)
    zero = np.float32(0.0)
    one = np.float32(1.0)
    for y in range(H2):
        y1 = 2 * y + 1
        for x in range(W2):
            x1 = 2 * x + 1
            w00 = w[2 * y, 2 * x]
            w01 = w[2 * y, x1] if x1 < W else zero
            w10 = w[y1, 2 * x] if y1 < H else zero
            w11 = w[y1, x1] if (y1 < H and x1 < W) else zero
            dw[y, x] = (w00 + w01) + (w10 + w11)
            m00, m01, m10, m11 = (w00, w01, w10, w11) if weigh else (one, one, one, one)
            for c in range(C):
                a00 = v[2 * y, 2 * x, c] * m00
                a01 = v[2 * y, x1, c] * m01 if x1 < W else zero
                a10 = v[y1, 2 * x, c] * m10 if y1 < H else zero
                a11 = v[y1, x1, c] * m11 if (y1 < H and x1 < W) else zero
                if C == 1:
                    dv[y, x, c] = (a00 + a01) + (a10 + a11)
                else:
                    dv[y, x, c] = ((a00 + a01) + a10) + a11
    return dv, dw


@numba.njit(cache=True, nogil=True)
def _pull_up(mean, sv, sw):  # pragma: no cover - numba
    """One pull level: the level's own mean where it has weight, else the coarser mean."""
    H, W, C = sv.shape
    out = np.empty((H, W, C), np.float32)
    eps = np.float32(1e-12)
    for y in range(H):
        for x in range(W):
            w = sw[y, x]
            for c in range(C):
                if w > 0:
                    out[y, x, c] = sv[y, x, c] / max(w, eps)
                else:
                    out[y, x, c] = mean[y // 2, x // 2, c]
    return out


@numba.njit(cache=True, nogil=True)
def _pull_holes(out, w, mean):  # pragma: no cover - numba
    """The last pull level at the pixels of zero weight only (the others keep their
    values): the coarser level's mean."""
    H, W, C = out.shape
    for y in range(H):
        for x in range(W):
            if not w[y, x] > 0:
                for c in range(C):
                    out[y, x, c] = mean[y // 2, x // 2, c]


def push_pull(values: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Fill pixels of zero weight by push-pull (pyramid) interpolation of the weighted
    ones; pixels of positive weight are returned unchanged. The pyramid's levels are the
    2x2 sums of the weighted values and of the weights (float32); pulling from the
    coarsest, a pixel of zero weight takes the coarser level's mean. The first level is
    summed without forming the weighted image (:func:`_push` with ``weigh``) and the finest pull
    only sets the holes (:func:`_pull_holes`)."""
    v = np.asarray(values, np.float32)
    squeeze = v.ndim == 2
    if squeeze:
        v = v[..., None]
    v = np.ascontiguousarray(v)
    w = np.ascontiguousarray((np.asarray(weight, np.float32) > 0).astype(np.float32))
    out = v.copy()
    if w.all():
        return out[..., 0] if squeeze else out
    if min(w.shape) > 1:
        levels = [_push(v, w, True)]
        while min(levels[-1][1].shape) > 1:
            levels.append(_push(*levels[-1], False))
        cv_, cw = levels[-1]
        mean = cv_ / np.maximum(cw, 1e-12)[..., None]
        for sv, sw in reversed(levels[:-1]):
            mean = _pull_up(np.ascontiguousarray(mean), sv, sw)
        _pull_holes(out, w, np.ascontiguousarray(mean))
    else:  # a single row or column: the pyramid's top is the image itself
        mean = (v * w[..., None]) / np.maximum(w, 1e-12)[..., None]
        out = np.where((w > 0)[..., None], v, mean)
    return out[..., 0] if squeeze else out


@numba.njit(cache=True, nogil=True)
def _fill_rows(img, seen):  # pragma: no cover - numba
    H, W, C = img.shape
    out = img.copy()
    filled = seen.copy()
    for y in range(H):
        x = 0
        while x < W:
            if seen[y, x]:
                x += 1
                continue
            x0 = x - 1
            while x < W and not seen[y, x]:
                x += 1
            if x0 < 0 or x >= W:
                continue
            n = x - x0
            for k in range(x0 + 1, x):
                t = (k - x0) / n
                for c in range(C):
                    out[y, k, c] = (1.0 - t) * img[y, x0, c] + t * img[y, x, c]
                filled[y, k] = True
    return out, filled


def fill_holes_rows(image: np.ndarray, seen: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unseen pixels between two seen ones on their row, linearly interpolated between
    them; returns (image, mask of the pixels now set)."""
    img = np.ascontiguousarray(image, dtype=np.float32)
    squeeze = img.ndim == 2
    out, filled = _fill_rows(img[..., None] if squeeze else img,
                             np.ascontiguousarray(seen, dtype=np.bool_))
    return (out[..., 0] if squeeze else out), filled


def densify_depth(depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fill invalid depth (0) by push-pull of inverse depth; returns (dense depth,
    measured mask)."""
    valid = depth > 0
    if not valid.any():
        raise ValueError("DIBR: an input depth map has no valid pixel")
    inv = np.where(valid, 1.0 / np.where(valid, depth, 1.0), 0.0).astype(np.float32)
    filled = push_pull(inv, valid.astype(np.float32))
    return (1.0 / np.maximum(filled, 1e-12)).astype(np.float32), valid


def _geometry(cam: PinholeCamera) -> tuple[np.ndarray, ...]:
    """(K, K^-1, camera-to-world R, centre C, world-to-camera R, t) as C-contiguous
    float64 arrays, the arguments of the compiled warps."""
    w2c = cam.world_to_cam

    def c(a: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(a, dtype=np.float64)

    return (c(cam.K), c(np.linalg.inv(cam.K)), c(cam.R), c(cam.centre), c(w2c[:3, :3]),
            c(w2c[:3, 3]))


@numba.njit(cache=True, nogil=True, inline="always")
def _unproject(Kinv, R, C, x, y, z):  # pragma: no cover - numba
    """World point of pixel (x, y) of a camera (``Kinv``, camera-to-world rotation
    ``R``, centre ``C``) at z-depth ``z``: the ray through the pixel (z_cam = 1) scaled
    by z. Term by term as numpy's matrix products order them."""
    cx = Kinv[0, 0] * x + Kinv[0, 1] * y + Kinv[0, 2]
    cy = Kinv[1, 0] * x + Kinv[1, 1] * y + Kinv[1, 2]
    cz = Kinv[2, 0] * x + Kinv[2, 1] * y + Kinv[2, 2]
    X0 = C[0] + (R[0, 0] * cx + R[0, 1] * cy + R[0, 2] * cz) * z
    X1 = C[1] + (R[1, 0] * cx + R[1, 1] * cy + R[1, 2] * cz) * z
    X2 = C[2] + (R[2, 0] * cx + R[2, 1] * cy + R[2, 2] * cz) * z
    return X0, X1, X2


@numba.njit(cache=True, nogil=True, inline="always")
def _entries(M):  # pragma: no cover - numba
    """The nine entries of a 3 x 3 matrix in row order, read once into the kernels'
    locals."""
    return (M[0, 0], M[0, 1], M[0, 2], M[1, 0], M[1, 1], M[1, 2], M[2, 0], M[2, 1],
            M[2, 2])


#: A point covers the target pixels whose centres lie less than ``SPLAT_REACH`` pixels from
#: it along each axis: the two pixels on either side of it, or, where it falls on a pixel
#: centre (to 1e-6 px), that pixel alone. The footprint used to be ``floor(u)`` and
#: ``floor(u) + 1``: a point exactly on pixel ``k`` then covered ``k + 1`` too, a whole
#: pixel away, or ``k - 1`` when round-off left it at ``k - 1e-13``. The ground-truth
#: cameras of a set or an array are exactly aligned (one image axis of every warp between
#: views of a row or column maps pixel centres onto pixel centres), so the last bit of the
#: projection grew every foreground edge along that axis by a whole pixel, on one side or
#: the other, and that pixel's background, which the input sees, was lost behind it:
#: -0.3 dB on Exp. 2 of the default data with the true depth, -0.7 dB on its ideal
#: renders (README, "Ground truth in the synthesis experiments").
SPLAT_REACH = 1.0 - 1e-6


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _splat(depth, Kinv, R, C, K_t, R_t, t_t, zbuf):  # pragma: no cover - numba
    """Forward warp of every pixel of an input z-depth map (float32; the input's
    ``Kinv``, camera-to-world ``R``, centre ``C``), unprojected to its world point
    (:func:`_unproject`, float64; none where the depth is not > 0), into the target
    (world-to-camera ``R_t``, ``t_t``, intrinsics ``K_t``) as a splat into the
    target z-buffer ``zbuf`` (float64, min; +inf = none) over the pixels within
    :data:`SPLAT_REACH` of it along each axis (2 x 2 pixels; one row or column where it
    falls on a pixel centre: exactly aligned cameras). The order of the points does
    not matter (min), so the result is deterministic. Row by row: the projections first
    (a loop without branches, which the compiler vectorises: numpy's error model, no
    check for a division by zero), then the splats. The world points are computed here
    rather than read from an (H, W, 3) float64 array made once per input: the array's
    reads took longer than the arithmetic. The products are summed term by term in this
    order, not by BLAS. A point within 1e-6 px of a pixel centre covers that row or
    column alone, so the round-off of exactly aligned cameras no longer decides which
    pixels a splat covers."""
    H, W = depth.shape
    Ht, Wt = zbuf.shape
    us = np.empty(W)
    vs = np.empty(W)
    zs = np.empty(W)
    q00, q01, q02, q10, q11, q12, q20, q21, q22 = _entries(R_t)
    p0, p1, p2 = t_t[0], t_t[1], t_t[2]
    k00, k01, k02, k10, k11, k12, k20, k21, k22 = _entries(K_t)
    reach = SPLAT_REACH
    for y in range(H):
        for x in range(W):
            z = np.float64(depth[y, x])
            X0, X1, X2 = _unproject(Kinv, R, C, x, y, z)
            if not z > 0:
                X0 = X1 = X2 = np.nan
            a = q00 * X0 + q01 * X1 + q02 * X2 + p0
            b = q10 * X0 + q11 * X1 + q12 * X2 + p1
            zt = q20 * X0 + q21 * X1 + q22 * X2 + p2
            w = k20 * a + k21 * b + k22 * zt
            us[x] = (k00 * a + k01 * b + k02 * zt) / w
            vs[x] = (k10 * a + k11 * b + k12 * zt) / w
            zs[x] = zt
        for x in range(W):
            zt = zs[x]
            u = us[x]
            v = vs[x]
            if not (zt > 0 and u > -reach and u < Wt - 1 + reach and v > -reach
                    and v < Ht - 1 + reach):
                continue  # behind, or no pixel within reach (also NaN / inf)
            x0 = int(math.ceil(u - reach))
            x1 = int(math.floor(u + reach))
            y0 = int(math.ceil(v - reach))
            y1 = int(math.floor(v + reach))
            if x0 >= 0 and y0 >= 0 and x1 < Wt and y1 < Ht:
                # the whole splat inside (nearly every point): minima without branches
                for yy in range(y0, y1 + 1):
                    for xx in range(x0, x1 + 1):
                        cur = zbuf[yy, xx]
                        zbuf[yy, xx] = zt if zt < cur else cur
                continue
            for yy in range(max(y0, 0), min(y1 + 1, Ht)):
                for xx in range(max(x0, 0), min(x1 + 1, Wt)):
                    if zt < zbuf[yy, xx]:
                        zbuf[yy, xx] = zt


def _zbuffer(depth: np.ndarray, src_geometry: tuple[np.ndarray, ...], tgt: PinholeCamera,
             tgt_geometry: tuple[np.ndarray, ...]) -> np.ndarray:
    """The target's z-buffer of the input's splatted depth (float64, +inf = none);
    the geometries: the cameras' (:func:`_geometry`)."""
    _, Kinv, R, C, _, _ = src_geometry
    K_t, _, _, _, R_t, t_t = tgt_geometry
    zbuf = np.full((tgt.height, tgt.width), np.inf)
    _splat(depth, Kinv, R, C, K_t, R_t, t_t, zbuf)
    return zbuf


def forward_depth(src: PinholeCamera, depth: np.ndarray, tgt: PinholeCamera) -> np.ndarray:
    """Target z-depth of the input's surface: splats over the pixels within a pixel
    (:data:`SPLAT_REACH`) with a z-buffer (0 = none)."""
    zbuf = _zbuffer(np.ascontiguousarray(depth, dtype=np.float64), _geometry(src), tgt,
                    _geometry(tgt))
    return np.where(np.isfinite(zbuf), zbuf, 0.0).astype(np.float32)


@numba.njit(cache=True, nogil=True, inline="always")
def _nearest_index(u, n):  # pragma: no cover - numba
    """cv2.remap's INTER_NEAREST index of float32 coordinate ``u`` on an axis of ``n``
    pixels: rounded half to even and saturated to int16 (as OpenCV converts the maps);
    -1 when off the image (BORDER_CONSTANT: the sample is 0)."""
    if not (u > -32768.5 and u < 32767.5):  # saturated (NaN too): off any image
        return -1
    i = int(np.rint(u))
    return i if 0 <= i < n else -1


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _backward(zbuf, Kinv_t, R_t, C_t, K_s, R_s, t_s, aux, Ws, Hs, occlusion_tolerance,
              edge_weight, filled_weight, mx, my, pos, w, z):  # pragma: no cover - numba
    """Per target pixel of depth ``zt`` (the z-buffer of :func:`_splat` as float32, 0
    where none): the pixel unprojected (its ray through the target's ``Kinv_t`` rotated
    by its camera-to-world ``R_t``, times zt from its centre ``C_t``: the arithmetic of
    :func:`_unproject`; computed here rather than read from an (H, W, 3) float64 array of
    the target's rays, which took twice as long as the arithmetic) and
    projected into the input, which gives the input's pixel (u, v) and the pixel's
    z-depth there (zs); the input's own aux (dense depth, discontinuity, filled) at that
    pixel, nearest (as ``cv2.remap(aux, u, v, INTER_NEAREST, BORDER_CONSTANT)``); and
    the sample's weight ``w`` and depth ``z``. The sample is kept (``ok``) where the
    target has depth, the input pixel lies on the input (``Ws`` x ``Hs``, its camera's
    size) and the input's own depth there agrees with the warped one (within
    ``occlusion_tolerance``, relative); its weight is 1, times ``edge_weight`` at a depth
    discontinuity and ``filled_weight`` where the input's depth was filled (float32
    products, as numpy's on float32 arrays); ``z``: the target depth where kept, else 0.
    The coordinates of the samples of positive weight (those blended) go to ``mx``,
    ``my`` (1-D, in pixel order), their index there to ``pos`` (-1: none); returns their
    number. One pass for what were a dozen array operations, a remap and two passes; the
    matrices' entries are read once, into locals."""
    H, W = zbuf.shape
    Ha, Wa = aux.shape[0], aux.shape[1]
    i00, i01, i02, i10, i11, i12, i20, i21, i22 = _entries(Kinv_t)
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = _entries(R_t)
    c0, c1, c2 = C_t[0], C_t[1], C_t[2]
    s00, s01, s02, s10, s11, s12, s20, s21, s22 = _entries(R_s)
    t0, t1, t2 = t_s[0], t_s[1], t_s[2]
    k00, k01, k02, k10, k11, k12, k20, k21, k22 = _entries(K_s)
    zts = np.empty(W, np.float32)
    us = np.empty(W, np.float32)
    vs = np.empty(W, np.float32)
    zss = np.empty(W)
    k = 0
    for y in range(H):
        # the row's arithmetic first, for every pixel: a loop without branches, which the
        # compiler vectorises (where the target has no depth its values are not read)
        for x in range(W):
            zb = zbuf[y, x]
            zt = np.float32(zb) if np.isfinite(zb) else np.float32(0.0)
            zts[x] = zt
            zz = np.float64(zt)
            cx = i00 * x + i01 * y + i02
            cy = i10 * x + i11 * y + i12
            cz = i20 * x + i21 * y + i22
            X0 = c0 + (r00 * cx + r01 * cy + r02 * cz) * zz
            X1 = c1 + (r10 * cx + r11 * cy + r12 * cz) * zz
            X2 = c2 + (r20 * cx + r21 * cy + r22 * cz) * zz
            a = s00 * X0 + s01 * X1 + s02 * X2 + t0
            b = s10 * X0 + s11 * X1 + s12 * X2 + t1
            zs = s20 * X0 + s21 * X1 + s22 * X2 + t2
            d = k20 * a + k21 * b + k22 * zs
            us[x] = np.float32((k00 * a + k01 * b + k02 * zs) / d)
            vs[x] = np.float32((k10 * a + k11 * b + k12 * zs) / d)
            zss[x] = zs
        for x in range(W):
            zt = zts[x]
            if not zt > 0:
                pos[y, x] = -1
                w[y, x] = 0.0
                z[y, x] = 0.0
                continue
            u = us[x]
            v = vs[x]
            zs = zss[x]
            ix = _nearest_index(u, Wa)
            iy = _nearest_index(v, Ha)
            if ix >= 0 and iy >= 0:
                depth_s = aux[iy, ix, 0]
                edge = aux[iy, ix, 1]
                filled = aux[iy, ix, 2]
            else:
                depth_s = edge = filled = np.float32(0.0)
            ok = (u >= -0.5 and u <= Ws - 0.5 and v >= -0.5 and v <= Hs - 0.5
                  and abs(np.float64(depth_s) - zs) <= occlusion_tolerance * abs(zs))
            wt = np.float32(1.0) if ok else np.float32(0.0)
            if edge > 0:
                wt = wt * edge_weight
            if filled > 0:
                wt = wt * filled_weight
            w[y, x] = wt
            z[y, x] = zt if ok else np.float32(0.0)
            if wt > 0:
                mx[k] = u
                my[k] = v
                pos[y, x] = k
                k += 1
            else:
                pos[y, x] = -1
    return k


def depth_edges(depth: np.ndarray, ratio: float) -> np.ndarray:
    """Pixels next to a depth discontinuity (3x3 max/min above ``ratio``)."""
    k = np.ones((3, 3), np.uint8)
    mx = cv2.dilate(depth, k)
    mn = cv2.erode(depth, k)
    return mx > ratio * np.maximum(mn, 1e-12)


@dataclass
class PreparedView:
    """What warping an input view needs that does not depend on the target, computed
    once per input and shared by every target it is warped to."""

    camera: PinholeCamera
    image: np.ndarray  # float32 (H, W) or (H, W, C), as to_float gives it
    dense: np.ndarray  # float32 z-depth, invalid pixels filled (densify_depth)
    aux: np.ndarray  # float32 (H, W, 3): dense depth, discontinuity (1/0), filled (1/0)
    geometry: tuple[np.ndarray, ...]  # the camera's (_geometry)


def prepare_view(view: View | PreparedView, opt: DibrOptions) -> PreparedView:
    """The input's target-independent part of its warp (:func:`_warp_into`): dense depth, its
    discontinuities (``opt.edge_ratio``) and the mask of filled depth."""
    if isinstance(view, PreparedView):
        return view
    dense, measured = densify_depth(view.depth)
    edge = depth_edges(dense, opt.edge_ratio)
    aux = np.ascontiguousarray(np.stack([dense, edge.astype(np.float32),
                                         (~measured).astype(np.float32)], axis=-1))
    image = np.ascontiguousarray(to_float(view.image), dtype=np.float32)
    return PreparedView(view.camera, image, np.ascontiguousarray(dense), aux,
                        _geometry(view.camera))


def _warp_into(pv: PreparedView, tgt: PinholeCamera, geometry: tuple[np.ndarray, ...],
               opt: DibrOptions, samples: np.ndarray, pos: np.ndarray,
               z: np.ndarray, w: np.ndarray) -> None:
    """One input warped onto the target ``tgt`` into the given arrays (colour samples,
    target depth, sample weight; C-contiguous: the colour samples
    float32 (H * W, C), the first as many as the target has samples, pixel by pixel
    in row order; ``pos`` int32 (H, W) their index there, -1 for none; z and w float32
    (H, W)), so that :func:`synthesize` stacks the inputs without copies and samples
    the colour only where it is blended; ``geometry``: the target's
    (:func:`_geometry`). Each colour sample is the one ``cv2.remap`` of the whole image
    gives at that pixel (a sample depends only on its coordinates)."""
    if opt.interpolation not in _INTERPOLATION:
        raise ValueError(f"config: verify.dibr.interpolation = {opt.interpolation!r}: must be "
                         f"one of {', '.join(_INTERPOLATION)}")
    zbuf = _zbuffer(pv.dense, pv.geometry, tgt, geometry)
    _, Kinv_t, R_t, C_t, _, _ = geometry
    K_s, _, _, _, R_s, t_s = pv.geometry
    H, W = zbuf.shape
    mx = np.empty(H * W, np.float32)
    my = np.empty(H * W, np.float32)
    k = _backward(zbuf, Kinv_t, R_t, C_t, K_s, R_s, t_s, pv.aux, pv.camera.width,
                  pv.camera.height, float(opt.occlusion_tolerance),
                  np.float32(opt.edge_weight), np.float32(opt.filled_weight), mx, my, pos,
                  w, z)
    if k == 0:
        return
    rows = -(-k // W)  # the samples' coordinates as rows of the target's width
    mx[k:rows * W] = -10.0
    my[k:rows * W] = -10.0
    dst = samples[:rows * W].reshape(rows, W, samples.shape[1])
    cv2.remap(pv.image, mx[:rows * W].reshape(rows, W), my[:rows * W].reshape(rows, W),
              _INTERPOLATION[opt.interpolation], dst=dst[..., 0] if pv.image.ndim == 2 else dst,
              borderMode=cv2.BORDER_REPLICATE)


@numba.njit(cache=True, nogil=True)
def _blend(colour, pos, z, w, q, z_tolerance, depth_exponent):  # pragma: no cover - numba
    """Per target pixel, the inputs' samples (colour (n, H * W, C) at ``pos`` (n, H, W),
    depth and weight (n, H, W), float32; see :func:`_warp_into`) averaged with weights
    ``w q (z_near / z)^depth_exponent``
    (the soft z-test; ``z_tolerance`` >= 0: only samples within that relative band of
    the nearest, the hard one). Returns the blend (float32, rounded from the float64
    average) and the total weight (float64; 0: no sample). The arithmetic is numpy's on
    the stacked arrays, input by input in order (float32 depth ratios and powers,
    float64 weights and sums), but for an integer exponent the power is the float64 one
    rounded to float32 rather than powf's; the power of a ratio of 1 (the nearest
    sample's) is 1 and not computed."""
    n, H, W = z.shape
    C = colour.shape[2]
    out = np.empty((H, W, C), np.float32)
    tot = np.empty((H, W))
    band = np.float32(1.0 + z_tolerance)
    exponent = np.float32(depth_exponent)
    # an integer exponent (the default 8): the float32 nearest the float64 power, by
    # repeated squaring (numba's float ** int). Each float64 step is exact or within
    # 2^-53, so this is the correctly rounded power but where the exact one lies within
    # ~1e-15 of a float32 rounding boundary; powf is 4x slower and not correctly rounded
    # (exponent 8: one unit in the last place off for 88,000 of the 1.07e9 float32
    # ratios in [2^-15, 1], checked exhaustively)
    int_exp = int(depth_exponent) if (depth_exponent == int(depth_exponent)
                                      and 1 <= depth_exponent <= 64) else 0
    one = np.float32(1.0)
    zmin = np.empty(W, np.float32)
    acc = np.empty((W, C))
    for y in range(H):  # a row at a time, input by input (contiguous reads)
        for x in range(W):
            zmin[x] = np.inf
        for i in range(n):
            for x in range(W):
                zi = z[i, y, x]
                if w[i, y, x] > 0 and zi < zmin[x]:
                    zmin[x] = zi
        t = tot[y]
        t[:] = 0.0
        acc[:] = 0.0
        for i in range(n):  # each pixel's sums in the inputs' order
            qi = q[i]
            for x in range(W):
                wi = w[i, y, x]
                if not wi > 0:
                    continue
                zi = z[i, y, x]
                if z_tolerance >= 0 and not zi <= np.float32(zmin[x] * band):
                    continue
                wt = np.float64(wi) * qi
                if depth_exponent > 0:
                    r = np.float32(zmin[x] / zi)
                    if r != one:  # pow(1, e) = 1 exactly
                        p = (np.float32(np.float64(r) ** int_exp) if int_exp > 0
                             else r ** exponent)
                        wt = wt * np.float64(p)
                t[x] += wt
                p = pos[i, y, x]
                for c in range(C):
                    acc[x, c] += wt * np.float64(colour[i, p, c])
        for x in range(W):
            d = max(t[x], 1e-30)
            for c in range(C):
                out[y, x, c] = acc[x, c] / d
    return out, tot


def synthesize(views: Sequence[View | PreparedView], target: PinholeCamera,
               opt: DibrOptions | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Synthesized target image (float32 in [0, 1], the inputs' channels) and the mask of
    pixels seen by at least one input (the rest is inpainted)."""
    opt = opt or DibrOptions()
    if not views:
        raise ValueError("DIBR needs at least one input view")
    prepared = [prepare_view(v, opt) for v in views]
    channels = {1 if p.image.ndim == 2 else p.image.shape[2] for p in prepared}
    if len(channels) != 1:
        raise ValueError(f"DIBR inputs differ in their channels ({sorted(channels)})")
    n, H, W = len(prepared), target.height, target.width
    colour = np.empty((n, H * W, channels.pop()), np.float32)
    pos = np.empty((n, H, W), np.int32)
    z = np.empty((n, H, W), np.float32)
    w = np.empty((n, H, W), np.float32)
    geometry = _geometry(target)
    for i, pv in enumerate(prepared):
        _warp_into(pv, target, geometry, opt, colour[i], pos[i], z[i], w[i])
    dist = np.array([np.linalg.norm(v.camera.centre - target.centre) for v in views])
    q = 1.0 / (dist ** 2 + opt.distance_eps ** 2)
    # float32 as the inpainting takes it; rounding first and clipping to [0, 1] after
    # gives the bits of clipping the float64 blend first (rounding keeps the order)
    out, tot = _blend(colour, pos, z, w, q,
                      -1.0 if opt.z_tolerance is None else float(opt.z_tolerance),
                      float(opt.depth_exponent))
    seen = tot > 0
    if opt.inpaint and not seen.all():
        have = seen
        if opt.hole_fill == "rows":
            out, have = fill_holes_rows(out, seen)
        elif opt.hole_fill != "pushpull":
            raise ValueError(f"config: verify.dibr.hole_fill = {opt.hole_fill!r}: must be rows "
                             "or pushpull")
        out = push_pull(out, have)
    np.clip(out, 0.0, 1.0, out=out)
    if np.asarray(views[0].image).ndim == 2:
        out = np.ascontiguousarray(out[..., 0])
    return out, seen


def psnr(a: np.ndarray, b: np.ndarray, border: int = 0, peak: float = 1.0) -> float:
    """PSNR (dB) of two float images in [0, peak], excluding ``border`` pixels; the
    squared differences in float64, averaged as numpy averages a C-contiguous array."""
    a = np.asarray(a)
    b = np.asarray(b)
    if a.shape != b.shape:
        raise ValueError(f"PSNR of images of different shapes {a.shape} and {b.shape}")
    if border > 0:
        a = a[border:-border, border:-border]
        b = b[border:-border, border:-border]
    d = np.subtract(a, b, dtype=np.float64)
    np.square(d, out=d)
    mse = float(np.mean(d))
    return float("inf") if mse == 0 else float(10.0 * np.log10(peak * peak / mse))
