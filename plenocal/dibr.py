"""Depth-image-based rendering in the manner of MPEG's Reference View Synthesizer
(RVS): every input view (camera, image, z-depth) is unprojected with its depth,
warped to the target camera, z-tested, blended by quality, and the remaining holes
are inpainted.

Warping is "depth forward, colour backward": the input's 3-D points are splatted
into the target as 2x2 pixel quads with a z-buffer (the equivalent of rasterising
RVS's triangle mesh for magnifications below two, without its stretched triangles
across depth discontinuities, which are simply not drawn), then each covered target
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
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numba
import numpy as np

from plenocal.camera import PinholeCamera
from plenocal.io import to_float


@dataclass(frozen=True)
class DibrOptions:
    z_tolerance: float | None = None  # hard z-test: relative depth band of the nearest surface
    occlusion_tolerance: float = 0.02  # backward check against the input's depth
    edge_ratio: float = 1.03  # depth jump (max/min in 3x3) marking a discontinuity
    edge_weight: float = 0.05  # weight of samples at discontinuities
    filled_weight: float = 0.3  # weight of samples whose input depth was filled
    distance_eps: float = 1e-3  # metres (or model units): weight regulariser
    inpaint: bool = True
    interpolation: str = "cubic"  # colour sampling in the input: cubic or linear (as RVS)
    hole_fill: str = "rows"  # rows (interpolate along rows, as RVS) or pushpull
    depth_exponent: float = 8.0  # soft z-test: weight times (z_nearest / z) ** depth_exponent


_INTERPOLATION = {"linear": cv2.INTER_LINEAR, "cubic": cv2.INTER_CUBIC}


@dataclass
class View:
    camera: PinholeCamera
    image: np.ndarray  # float32 (H, W, C) or (H, W)
    depth: np.ndarray  # float32 z-depth, 0 = invalid


def push_pull(values: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Fill pixels of zero weight by push-pull (pyramid) interpolation of the weighted
    ones; pixels of positive weight are returned unchanged."""
    v = np.asarray(values, np.float32)
    squeeze = v.ndim == 2
    if squeeze:
        v = v[..., None]
    w = (np.asarray(weight, np.float32) > 0).astype(np.float32)
    levels = [(v * w[..., None], w)]
    while min(levels[-1][1].shape) > 1:
        sv, sw = levels[-1]
        H, W = sw.shape
        H2, W2 = (H + 1) // 2, (W + 1) // 2
        pv = np.zeros((H2 * 2, W2 * 2, sv.shape[2]), np.float32)
        pw = np.zeros((H2 * 2, W2 * 2), np.float32)
        pv[:H, :W] = sv
        pw[:H, :W] = sw
        dv = pv.reshape(H2, 2, W2, 2, -1).sum(axis=(1, 3))
        dw = pw.reshape(H2, 2, W2, 2).sum(axis=(1, 3))
        levels.append((dv, dw))
    # pull: from coarse to fine, replace empty pixels by the coarser average
    cv_, cw = levels[-1]
    mean = cv_ / np.maximum(cw, 1e-12)[..., None]
    for sv, sw in reversed(levels[:-1]):
        H, W = sw.shape
        up = np.repeat(np.repeat(mean, 2, axis=0), 2, axis=1)[:H, :W]
        own = sv / np.maximum(sw, 1e-12)[..., None]
        mean = np.where((sw > 0)[..., None], own, up)
    out = np.where((w > 0)[..., None], v, mean)
    return out[..., 0] if squeeze else out


@numba.njit(cache=True)
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


def _pixel_grid(H: int, W: int) -> np.ndarray:
    ys, xs = np.mgrid[0:H, 0:W].astype(np.float64)
    return np.stack([xs, ys], axis=-1)


def forward_depth(src: PinholeCamera, depth: np.ndarray, tgt: PinholeCamera) -> np.ndarray:
    """Target z-depth of the input's surface: 2x2 splats with a z-buffer (0 = none)."""
    H, W = depth.shape
    ok = depth > 0
    uv = _pixel_grid(H, W)[ok]
    X = src.unproject(uv, depth[ok].astype(np.float64))
    uvt, zt = tgt.project(X)
    front = (zt > 0) & np.isfinite(uvt).all(axis=1)
    uvt, zt = uvt[front], zt[front]
    x0 = np.floor(uvt[:, 0]).astype(np.int64)
    y0 = np.floor(uvt[:, 1]).astype(np.int64)
    zbuf = np.full(tgt.height * tgt.width, np.inf)
    for dx in (0, 1):
        for dy in (0, 1):
            x, y = x0 + dx, y0 + dy
            m = (x >= 0) & (x < tgt.width) & (y >= 0) & (y < tgt.height)
            np.minimum.at(zbuf, y[m] * tgt.width + x[m], zt[m])
    zbuf = zbuf.reshape(tgt.height, tgt.width)
    return np.where(np.isfinite(zbuf), zbuf, 0.0).astype(np.float32)


def depth_edges(depth: np.ndarray, ratio: float) -> np.ndarray:
    """Pixels next to a depth discontinuity (3x3 max/min above ``ratio``)."""
    k = np.ones((3, 3), np.uint8)
    mx = cv2.dilate(depth, k)
    mn = cv2.erode(depth, k)
    return mx > ratio * np.maximum(mn, 1e-12)


def warp_view(view: View, tgt: PinholeCamera, opt: DibrOptions) -> tuple[np.ndarray, np.ndarray,
                                                                          np.ndarray]:
    """(colour (H, W, C), target depth (H, W), sample weight (H, W), 0 = no sample)."""
    dense, measured = densify_depth(view.depth)
    zt = forward_depth(view.camera, dense, tgt)
    have = zt > 0
    uv = _pixel_grid(tgt.height, tgt.width)
    X = tgt.unproject(uv, zt.astype(np.float64))
    uvs, zs = view.camera.project(X)
    mx = np.where(have, uvs[..., 0], -10).astype(np.float32)
    my = np.where(have, uvs[..., 1], -10).astype(np.float32)
    img = to_float(view.image)
    if opt.interpolation not in _INTERPOLATION:
        raise ValueError(f"config: verify.dibr.interpolation = {opt.interpolation!r}: must be "
                         f"one of {', '.join(_INTERPOLATION)}")
    colour = cv2.remap(img, mx, my, _INTERPOLATION[opt.interpolation],
                       borderMode=cv2.BORDER_REPLICATE)
    if colour.ndim == 2:
        colour = colour[..., None]
    own = cv2.remap(dense, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT,
                    borderValue=0)
    inside = (mx >= -0.5) & (mx <= view.camera.width - 0.5) & (my >= -0.5) & \
        (my <= view.camera.height - 0.5)
    agree = np.abs(own - zs) <= opt.occlusion_tolerance * np.abs(zs)
    ok = have & inside & agree
    w = ok.astype(np.float32)
    edge = depth_edges(dense, opt.edge_ratio).astype(np.float32)
    at_edge = cv2.remap(edge, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT,
                        borderValue=0) > 0
    was_filled = cv2.remap((~measured).astype(np.float32), mx, my, cv2.INTER_NEAREST,
                           borderMode=cv2.BORDER_CONSTANT, borderValue=0) > 0
    w = np.where(at_edge, w * opt.edge_weight, w)
    w = np.where(was_filled, w * opt.filled_weight, w)
    return colour.astype(np.float32), np.where(ok, zt, 0.0).astype(np.float32), w


def synthesize(views: list[View], target: PinholeCamera,
               opt: DibrOptions | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Synthesized target image (float32 in [0, 1], the inputs' channels) and the mask of
    pixels seen by at least one input (the rest is inpainted)."""
    opt = opt or DibrOptions()
    if not views:
        raise ValueError("DIBR needs at least one input view")
    warped = [warp_view(v, target, opt) for v in views]
    zs = np.stack([w[1] for w in warped])
    ws = np.stack([w[2] for w in warped])
    zs_valid = np.where(ws > 0, zs, np.inf)
    zmin = zs_valid.min(axis=0)
    keep = ws > 0
    if opt.z_tolerance is not None:
        keep &= zs_valid <= zmin * (1.0 + opt.z_tolerance)
    dist = np.array([np.linalg.norm(v.camera.centre - target.centre) for v in views])
    q = 1.0 / (dist ** 2 + opt.distance_eps ** 2)
    wt = np.where(keep, ws, 0.0) * q[:, None, None]
    if opt.depth_exponent > 0:
        zr = np.where(keep, zmin[None] / np.where(keep, zs_valid, 1.0), 0.0)
        wt = wt * zr ** opt.depth_exponent
    tot = wt.sum(axis=0)
    acc = sum(wt[i][..., None] * warped[i][0] for i in range(len(views)))
    seen = tot > 0
    out = acc / np.maximum(tot, 1e-30)[..., None]
    if opt.inpaint and not seen.all():
        have = seen
        if opt.hole_fill == "rows":
            out, have = fill_holes_rows(out, seen)
        elif opt.hole_fill != "pushpull":
            raise ValueError(f"config: verify.dibr.hole_fill = {opt.hole_fill!r}: must be rows "
                             "or pushpull")
        out = push_pull(out, have.astype(np.float32))
    if np.asarray(views[0].image).ndim == 2:
        out = out[..., 0]
    return np.clip(out, 0.0, 1.0).astype(np.float32), seen


def psnr(a: np.ndarray, b: np.ndarray, border: int = 0, peak: float = 1.0) -> float:
    """PSNR (dB) of two float images in [0, peak], excluding ``border`` pixels."""
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    if a.shape != b.shape:
        raise ValueError(f"PSNR of images of different shapes {a.shape} and {b.shape}")
    if border > 0:
        a = a[border:-border, border:-border]
        b = b[border:-border, border:-border]
    mse = float(np.mean((a - b) ** 2))
    return float("inf") if mse == 0 else float(10.0 * np.log10(peak * peak / mse))
