"""The DIBR as it was before the ninth session's speed-up (plenocal/verify/dibr.py at
398734f): per input and target a full forward splat from the depth, a backward pass
over every target pixel, a nearest remap of the input's aux and a cubic remap of its
whole image, a weights pass, the blend over full-size colour stacks (float64) and a
push-pull with the full pull; its splat's footprint is the current one (the pixels
within ``SPLAT_REACH`` of a point, not ``floor(u)`` and ``floor(u) + 1``). The reference
the faster kernels must reproduce bit for bit (tests/test_dibr_kernels.py); the input
preparation (dense depth, aux) and the unchanged push and pull levels are shared."""

from __future__ import annotations

import math

import cv2
import numba
import numpy as np

from plenocal.verify.dibr import (
    SPLAT_REACH,
    DibrOptions,
    _geometry,
    _pull_up,
    _push,
    fill_holes_rows,
    prepare_view,
)


def push_pull(values: np.ndarray, weight: np.ndarray) -> np.ndarray:
    v = np.asarray(values, np.float32)
    squeeze = v.ndim == 2
    if squeeze:
        v = v[..., None]
    w = (np.asarray(weight, np.float32) > 0).astype(np.float32)
    levels = [(np.ascontiguousarray(v * w[..., None]), np.ascontiguousarray(w))]
    while min(levels[-1][1].shape) > 1:
        levels.append(_push(*levels[-1], False))
    cv_, cw = levels[-1]
    mean = cv_ / np.maximum(cw, 1e-12)[..., None]
    for sv, sw in reversed(levels[:-1]):
        mean = _pull_up(np.ascontiguousarray(mean), sv, sw)
    out = np.where((w > 0)[..., None], v, mean)
    return out[..., 0] if squeeze else out


@numba.njit(cache=True, nogil=True, inline="always")
def _pixel_into(Kinv, R, C, R2, t2, x, y, z):  # pragma: no cover - numba
    cx = Kinv[0, 0] * x + Kinv[0, 1] * y + Kinv[0, 2]
    cy = Kinv[1, 0] * x + Kinv[1, 1] * y + Kinv[1, 2]
    cz = Kinv[2, 0] * x + Kinv[2, 1] * y + Kinv[2, 2]
    X0 = C[0] + (R[0, 0] * cx + R[0, 1] * cy + R[0, 2] * cz) * z
    X1 = C[1] + (R[1, 0] * cx + R[1, 1] * cy + R[1, 2] * cz) * z
    X2 = C[2] + (R[2, 0] * cx + R[2, 1] * cy + R[2, 2] * cz) * z
    a = R2[0, 0] * X0 + R2[0, 1] * X1 + R2[0, 2] * X2 + t2[0]
    b = R2[1, 0] * X0 + R2[1, 1] * X1 + R2[1, 2] * X2 + t2[1]
    c = R2[2, 0] * X0 + R2[2, 1] * X1 + R2[2, 2] * X2 + t2[2]
    return a, b, c


@numba.njit(cache=True, nogil=True)
def _splat(depth, Kinv_s, R_s, C_s, K_t, R_t, t_t, zbuf):  # pragma: no cover - numba
    H, W = depth.shape
    Ht, Wt = zbuf.shape
    for y in range(H):
        for x in range(W):
            z = depth[y, x]
            if not z > 0:
                continue
            a, b, zt = _pixel_into(Kinv_s, R_s, C_s, R_t, t_t, x, y, z)
            if not zt > 0:
                continue
            w = K_t[2, 0] * a + K_t[2, 1] * b + K_t[2, 2] * zt
            u = (K_t[0, 0] * a + K_t[0, 1] * b + K_t[0, 2] * zt) / w
            v = (K_t[1, 0] * a + K_t[1, 1] * b + K_t[1, 2] * zt) / w
            # the pixels within SPLAT_REACH along each axis (floor(u) and floor(u) + 1
            # before issue 32: see plenocal.verify.dibr.SPLAT_REACH)
            if not (u > -SPLAT_REACH and u < Wt - 1 + SPLAT_REACH and v > -SPLAT_REACH
                    and v < Ht - 1 + SPLAT_REACH):
                continue
            x0 = int(math.ceil(u - SPLAT_REACH))
            x1 = int(math.floor(u + SPLAT_REACH))
            y0 = int(math.ceil(v - SPLAT_REACH))
            y1 = int(math.floor(v + SPLAT_REACH))
            for yy in range(max(y0, 0), min(y1 + 1, Ht)):
                for xx in range(max(x0, 0), min(x1 + 1, Wt)):
                    if zt < zbuf[yy, xx]:
                        zbuf[yy, xx] = zt


def forward_depth(src, depth, tgt) -> np.ndarray:
    _, Kinv_s, R_s, C_s, _, _ = _geometry(src)
    K_t, _, _, _, R_t, t_t = _geometry(tgt)
    zbuf = np.full((tgt.height, tgt.width), np.inf)
    _splat(np.ascontiguousarray(depth, dtype=np.float64), Kinv_s, R_s, C_s, K_t, R_t, t_t, zbuf)
    return np.where(np.isfinite(zbuf), zbuf, 0.0).astype(np.float32)


@numba.njit(cache=True, nogil=True)
def _backward(zt, Kinv_t, R_t, C_t, K_s, R_s, t_s, mx, my, zs):  # pragma: no cover - numba
    H, W = zt.shape
    for y in range(H):
        for x in range(W):
            z = zt[y, x]
            a, b, c = _pixel_into(Kinv_t, R_t, C_t, R_s, t_s, x, y, z)
            zs[y, x] = c
            if z > 0:
                w = K_s[2, 0] * a + K_s[2, 1] * b + K_s[2, 2] * c
                mx[y, x] = (K_s[0, 0] * a + K_s[0, 1] * b + K_s[0, 2] * c) / w
                my[y, x] = (K_s[1, 0] * a + K_s[1, 1] * b + K_s[1, 2] * c) / w
            else:
                mx[y, x] = -10.0
                my[y, x] = -10.0


@numba.njit(cache=True, nogil=True)
def _sample_weights(zt, mx, my, zs, aux, W, H, occlusion_tolerance, edge_weight,
                    filled_weight, w, z):  # pragma: no cover - numba
    for y in range(zt.shape[0]):
        for x in range(zt.shape[1]):
            u = mx[y, x]
            v = my[y, x]
            ok = (zt[y, x] > 0 and u >= -0.5 and u <= W - 0.5 and v >= -0.5
                  and v <= H - 0.5
                  and abs(np.float64(aux[y, x, 0]) - zs[y, x])
                  <= occlusion_tolerance * abs(zs[y, x]))
            wt = np.float32(1.0) if ok else np.float32(0.0)
            if aux[y, x, 1] > 0:
                wt = wt * edge_weight
            if aux[y, x, 2] > 0:
                wt = wt * filled_weight
            w[y, x] = wt
            z[y, x] = zt[y, x] if ok else np.float32(0.0)


def warp_view(pv, tgt, opt: DibrOptions) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(colour (H, W, C), depth, weight) of one input in the target, the whole image."""
    channels = 1 if pv.image.ndim == 2 else pv.image.shape[2]
    colour = np.empty((tgt.height, tgt.width, channels), np.float32)
    z = np.empty((tgt.height, tgt.width), np.float32)
    w = np.empty((tgt.height, tgt.width), np.float32)
    zt = forward_depth(pv.camera, pv.dense, tgt)
    _, Kinv_t, R_t, C_t, _, _ = _geometry(tgt)
    K_s, _, _, _, R_s, t_s = _geometry(pv.camera)
    mx = np.empty(zt.shape, np.float32)
    my = np.empty(zt.shape, np.float32)
    zs = np.empty(zt.shape, np.float64)
    _backward(zt.astype(np.float64), Kinv_t, R_t, C_t, K_s, R_s, t_s, mx, my, zs)
    image = pv.image.astype(np.float32, copy=False)
    interp = {"linear": cv2.INTER_LINEAR, "cubic": cv2.INTER_CUBIC}[opt.interpolation]
    cv2.remap(image, mx, my, interp, dst=colour[..., 0] if image.ndim == 2 else colour,
              borderMode=cv2.BORDER_REPLICATE)
    aux = cv2.remap(pv.aux, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT,
                    borderValue=0)
    _sample_weights(zt, mx, my, zs, np.ascontiguousarray(aux), pv.camera.width,
                    pv.camera.height, float(opt.occlusion_tolerance),
                    np.float32(opt.edge_weight), np.float32(opt.filled_weight), w, z)
    return colour, z, w


@numba.njit(cache=True, nogil=True)
def _blend(colour, z, w, q, z_tolerance, depth_exponent):  # pragma: no cover - numba
    n, H, W, C = colour.shape
    out = np.zeros((H, W, C))
    tot = np.zeros((H, W))
    band = np.float32(1.0 + z_tolerance)
    exponent = np.float32(depth_exponent)
    acc = np.zeros(C)
    for y in range(H):
        for x in range(W):
            zmin = np.float32(np.inf)
            for i in range(n):
                if w[i, y, x] > 0 and z[i, y, x] < zmin:
                    zmin = z[i, y, x]
            t = 0.0
            acc[:] = 0.0
            for i in range(n):
                wi = w[i, y, x]
                if not wi > 0:
                    continue
                zi = z[i, y, x]
                if z_tolerance >= 0 and not zi <= np.float32(zmin * band):
                    continue
                wt = np.float64(wi) * q[i]
                if depth_exponent > 0:
                    r = np.float32(zmin / zi)
                    # an integer exponent: the float64 power rounded to float32 (as the
                    # DIBR since the seventeenth session; powf is not correctly rounded)
                    e = int(depth_exponent)
                    p = (np.float32(np.float64(r) ** e) if e == depth_exponent and 1 <= e <= 64
                         else r ** exponent)
                    wt = wt * np.float64(p)
                t += wt
                for c in range(C):
                    acc[c] += wt * np.float64(colour[i, y, x, c])
            tot[y, x] = t
            d = max(t, 1e-30)
            for c in range(C):
                out[y, x, c] = acc[c] / d
    return out, tot


def synthesize(views, target, opt: DibrOptions | None = None) -> tuple[np.ndarray, np.ndarray]:
    opt = opt or DibrOptions()
    prepared = [prepare_view(v, opt) for v in views]
    warped = [warp_view(pv, target, opt) for pv in prepared]
    colour = np.stack([c for c, _, _ in warped])
    z = np.stack([d for _, d, _ in warped])
    w = np.stack([s for _, _, s in warped])
    dist = np.array([np.linalg.norm(v.camera.centre - target.centre) for v in views])
    q = 1.0 / (dist ** 2 + opt.distance_eps ** 2)
    out, tot = _blend(colour, z, w, q,
                      -1.0 if opt.z_tolerance is None else float(opt.z_tolerance),
                      float(opt.depth_exponent))
    seen = tot > 0
    if opt.inpaint and not seen.all():
        have = seen
        if opt.hole_fill == "rows":
            out, have = fill_holes_rows(out, seen)
        out = push_pull(out, have.astype(np.float32))
    if np.asarray(views[0].image).ndim == 2:
        out = out[..., 0]
    return np.clip(out, 0.0, 1.0).astype(np.float32), seen


def psnr(a: np.ndarray, b: np.ndarray, border: int = 0, peak: float = 1.0) -> float:
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    if border > 0:
        a = a[border:-border, border:-border]
        b = b[border:-border, border:-border]
    mse = float(np.mean((a - b) ** 2))
    return float("inf") if mse == 0 else float(10.0 * np.log10(peak * peak / mse))
