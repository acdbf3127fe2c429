"""Surface pixels of a synthesis target: where the dB lost to calibration is the
calibration's (synthetic data, issue 32 item 4).

A synthesised view's PSNR is dominated by the pixels at occlusion edges, where a renderer
decides per pixel which surface it shows. With two camera sets that differ by a fraction
of a pixel that decision, not the calibration, moves a target's PSNR by up to 1 dB, in our
DIBR and in RVS alike, and favours cameras that are exactly aligned (the ground truth's):
on the default data the ground-truth cameras moved by 1e-4 px lost 0.6 dB of Exp. 2's
whole-view PSNR. The surface pixels leave those decisions out: pixels of the target that
some input sees on a smooth surface, by the TRUE cameras and depth, away from the target's
own depth edges and from the PSNR's border. The mask is a property of the scene, the same
for every camera set, and the PSNR over it does not move when the cameras move by 1e-4 px.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import cv2
import numpy as np

from plenocal.camera import PinholeCamera

SMOOTH_WINDOW = 5  # px: the window of the depth-edge test
SMOOTH_RATIO = 1.01  # max / min depth in the window below this: a smooth surface
VISIBLE_TOLERANCE = 0.003  # relative: the input's own depth agrees with the warped one


def smooth_depth(z: np.ndarray) -> np.ndarray:
    """Pixels of valid depth whose ``SMOOTH_WINDOW``-square neighbourhood spans less than
    ``SMOOTH_RATIO`` (max / min)."""
    z = np.asarray(z, np.float32)
    k = np.ones((SMOOTH_WINDOW, SMOOTH_WINDOW), np.uint8)
    return (z > 0) & (cv2.dilate(z, k) < SMOOTH_RATIO * cv2.erode(z, k))


def surface_mask(target: str, inputs: Sequence[str], cameras: Mapping[str, PinholeCamera],
                 depth: Callable[[str], np.ndarray], border: int = 0) -> np.ndarray:
    """(H, W) bool: the target's pixels, ``border`` px inside its edge, on a smooth surface
    of its true depth that at least one input sees, on a smooth surface of its own true
    depth, by the true ``cameras`` (``depth(key)``: a view's true z-depth)."""
    ct = cameras[target]
    zt = np.asarray(depth(target), np.float64)
    H, W = zt.shape
    ys, xs = np.mgrid[0:H, 0:W].astype(np.float64)
    rays = np.stack([xs, ys, np.ones_like(xs)], axis=-1) @ np.linalg.inv(ct.K).T
    world = ct.centre + (rays * zt[..., None]) @ ct.R.T
    seen = np.zeros((H, W), bool)
    for key in inputs:
        cs = cameras[key]
        zs = np.asarray(depth(key), np.float32)
        local = (world - cs.centre) @ cs.R  # world to the input's camera axes
        p = local @ cs.K.T
        with np.errstate(divide="ignore", invalid="ignore"):
            u = (p[..., 0] / p[..., 2]).astype(np.float32)
            v = (p[..., 1] / p[..., 2]).astype(np.float32)
        zi = cv2.remap(zs, u, v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                       borderValue=0)
        flat = cv2.remap(smooth_depth(zs).astype(np.uint8), u, v, cv2.INTER_NEAREST,
                         borderMode=cv2.BORDER_CONSTANT, borderValue=0) > 0
        seen |= flat & (zi > 0) & (np.abs(zi - local[..., 2])
                                   < VISIBLE_TOLERANCE * local[..., 2])
    mask = seen & smooth_depth(zt) & (zt > 0)
    if border > 0:
        mask[:border], mask[-border:] = False, False
        mask[:, :border], mask[:, -border:] = False, False
    return mask


def masked_error(out: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> tuple[float, int]:
    """(sum of squared differences over the mask's pixels and channels, float64; the
    number of values summed)."""
    d = np.subtract(np.asarray(out), np.asarray(truth), dtype=np.float64)
    if d.ndim == 2:
        d = d[..., None]
    sel = d[np.asarray(mask, bool)]
    return float(np.square(sel).sum()), int(sel.size)


def psnr_of_error(sse: float, count: int, peak: float = 1.0) -> float | None:
    """PSNR (dB) of a summed squared error over ``count`` values (None: no value)."""
    if count <= 0:
        return None
    mse = sse / count
    return float("inf") if mse == 0 else float(10.0 * np.log10(peak * peak / mse))
