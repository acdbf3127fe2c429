"""Our view against another converter's view of the same lenslet frame (issue 12).

Real frames have no ground truth; what the reference converter (TLCT / RLC) makes of
them is the bar. Two numbers:

* **SSIM after alignment**: our view is registered to the reference by an affine map
  (SIFT matches, RANSAC, :func:`cv2.estimateAffine2D`; a similarity does not do: TLCT's
  views do not have square pixels, its x scale is ~7 % larger than its y scale against
  ours on Fujita2, 4 % on Boys2, and the best similarity then turns by 1-2 degrees),
  resampled onto the
  reference's pixel grid (area-averaged first where it is larger), and the SSIM of the
  grey levels is taken over the overlap (:func:`skimage.metrics.structural_similarity`,
  its full map, averaged where both images have data).
* **Sharpness ratio**: fine detail, the image minus its Gaussian blur (sigma
  ``DETAIL_SIGMA`` reference pixels), as its RMS over the overlap; ours (resampled onto
  the reference's grid as above, so a small view upsampled gains nothing) over the
  reference's. 1 = as sharp as the reference.

Targets (issue 12): SSIM >= 0.85, sharpness ratio >= 0.8, our view at least the
reference's size.

Which of the two has square pixels the frame itself says (:func:`sensor_aspect`): a view
against the lenslet frame it was made from, both blurred until the micro images are gone
(what is left is the scene as the lattice of lenses sees it), aligned by an affine map.
On the real frames of ``shared/real`` our central views read the sensor's aspect to
0.1 % on the Raytrix frames (the corner views to 0.7 %) and within the measure's 1.5 % on
the TSPC ones (whose large inverted micro images leave the blurred frame least like the
scene); TLCT's are 4-8 % off it (BENCHMARKS.md, "Whose views have square pixels").
"""

from __future__ import annotations

import cv2
import numpy as np
from skimage.metrics import structural_similarity

from plenocal.convert.errors import ConvertError

DETAIL_SIGMA = 1.5
SSIM_TARGET = 0.85
SHARPNESS_TARGET = 0.8


def grey(img: np.ndarray) -> np.ndarray:
    """float32 grey in [0, 1] of a uint8 / uint16 grey or RGB image."""
    scale = 1.0 / 65535.0 if img.dtype == np.uint16 else 1.0 / 255.0
    f = img.astype(np.float32) * np.float32(scale)
    if f.ndim == 3:
        f = cv2.cvtColor(f, cv2.COLOR_RGB2GRAY)
    return f


def alignment(ours: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray, int]:
    """2x3 affine map taking pixels of ``ours`` to ``ref`` (grey float images) and the
    number of RANSAC inliers."""
    sift = cv2.SIFT_create(nfeatures=4000)
    a8 = np.clip(ours * 255, 0, 255).astype(np.uint8)
    b8 = np.clip(ref * 255, 0, 255).astype(np.uint8)
    ka, da = sift.detectAndCompute(a8, None)
    kb, db = sift.detectAndCompute(b8, None)
    if da is None or db is None or len(ka) < 8 or len(kb) < 8:
        raise ConvertError("too few SIFT features to align the views (texture-less?)")
    matches = cv2.BFMatcher(cv2.NORM_L2).knnMatch(da, db, k=2)
    good = [m for m, n in (p for p in matches if len(p) == 2) if m.distance < 0.75 * n.distance]
    if len(good) < 8:
        raise ConvertError(f"only {len(good)} SIFT matches between the views: not the same scene?")
    pa = np.float32([ka[m.queryIdx].pt for m in good])
    pb = np.float32([kb[m.trainIdx].pt for m in good])
    M, inl = cv2.estimateAffine2D(pa, pb, method=cv2.RANSAC, ransacReprojThreshold=2.0,
                                  maxIters=5000, confidence=0.999, refineIters=20)
    if M is None:
        raise ConvertError("no affine map aligns the views")
    return M, int(inl.sum())


def onto_reference(ours: np.ndarray, ref_shape: tuple[int, int], M: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """``ours`` resampled onto the reference's grid by the affine map ``M`` (area-averaged
    first where it shrinks) and the mask of reference pixels it covers."""
    s = float(np.sqrt(abs(np.linalg.det(M[:, :2]))))
    src = ours
    M = M.astype(np.float64).copy()
    if s < 0.95:  # shrink with area averaging first, then the remaining near-unit warp
        h, w = ours.shape[:2]
        nw, nh = max(1, int(round(w * s))), max(1, int(round(h * s)))
        src = cv2.resize(ours, (nw, nh), interpolation=cv2.INTER_AREA)
        S = np.array([[nw / w, 0, 0.5 * nw / w - 0.5], [0, nh / h, 0.5 * nh / h - 0.5],
                      [0, 0, 1]])
        M = (np.vstack([M, [0, 0, 1]]) @ np.linalg.inv(S))[:2]
    H, W = ref_shape
    warped = cv2.warpAffine(src, M, (W, H), flags=cv2.INTER_LANCZOS4,
                            borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    mask = cv2.warpAffine(np.ones(src.shape[:2], np.uint8), M, (W, H), flags=cv2.INTER_NEAREST,
                          borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    mask = cv2.erode(mask, np.ones((7, 7), np.uint8)) > 0
    return warped, mask


def fine_detail(img: np.ndarray, mask: np.ndarray, sigma: float = DETAIL_SIGMA) -> float:
    """RMS of the image minus its Gaussian blur, over ``mask``."""
    hp = img - cv2.GaussianBlur(img, (0, 0), sigma)
    return float(np.sqrt(np.mean(hp[mask] ** 2)))


def compare_to_reference(ours_img: np.ndarray, ref_img: np.ndarray) -> dict:
    """SSIM on the overlap after the affine alignment and the sharpness ratio (see the
    module docstring), with the sizes, the alignment and the verdicts."""
    ours, ref = grey(ours_img), grey(ref_img)
    M, inliers = alignment(ours, ref)
    warped, mask = onto_reference(ours, ref.shape, M)
    if mask.mean() < 0.25:
        raise ConvertError(f"the aligned views overlap on {100 * mask.mean():.0f}% only")
    _, smap = structural_similarity(ref, warped, data_range=1.0, full=True,
                                    gaussian_weights=True, sigma=1.5,
                                    use_sample_covariance=False)
    ssim = float(smap[mask].mean())
    sharp = fine_detail(warped, mask) / max(fine_detail(ref, mask), 1e-9)
    scale = float(np.sqrt(abs(np.linalg.det(M[:, :2]))))
    sx, sy = (float(np.hypot(*M[:, k])) for k in (0, 1))
    angle = float(np.degrees(np.arctan2(M[1, 0], M[0, 0])))
    big_enough = ours.shape[0] >= ref.shape[0] and ours.shape[1] >= ref.shape[1]
    return {
        "ours_size": [int(ours.shape[1]), int(ours.shape[0])],
        "reference_size": [int(ref.shape[1]), int(ref.shape[0])],
        "scale_to_reference": scale, "scale_xy": [sx, sy], "rotation_deg": angle,
        "inliers": inliers,
        "overlap": float(mask.mean()), "ssim": ssim, "sharpness_ratio": float(sharp),
        "meets_targets": bool(ssim >= SSIM_TARGET and sharp >= SHARPNESS_TARGET
                              and big_enough),
    }


#: :func:`sensor_aspect`: the width both images are brought to, and the blur (px at that
#: width) that leaves no micro image: a 68-px micro image of a 4,000-px TSPC frame is 7 px
#: wide at 400
ASPECT_WIDTH = 400
ASPECT_SIGMA = 2.5


def sensor_aspect(view: np.ndarray, frame: np.ndarray) -> tuple[float, float]:
    """The aspect of ``view`` against the lenslet ``frame`` it was made from (grey or RGB,
    any depth): both area-averaged to :data:`ASPECT_WIDTH` px and blurred by
    :data:`ASPECT_SIGMA` px, then the affine map from the view onto the frame by ECC
    (:func:`cv2.findTransformECC`, started with the view spanning 100, 90, 80 or 70 % of
    the frame's width about its centre, the best correlation kept). Returns (its x scale
    over its y scale, the correlation): 1 where the view has the sensor's square pixels."""
    def prep(img: np.ndarray) -> np.ndarray:
        g = grey(img)
        h = max(8, int(round(g.shape[0] * ASPECT_WIDTH / g.shape[1])))
        small = cv2.resize(g, (ASPECT_WIDTH, h), interpolation=cv2.INTER_AREA)
        return cv2.GaussianBlur(small, (0, 0), ASPECT_SIGMA)

    a, b = prep(view), prep(frame)
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 300, 1e-7)
    best: tuple[float, np.ndarray] | None = None
    for cover in (1.0, 0.9, 0.8, 0.7):
        k = cover * b.shape[1] / a.shape[1]
        warp = np.array([[k, 0, (b.shape[1] - k * a.shape[1]) / 2],
                         [0, k, (b.shape[0] - k * a.shape[0]) / 2]], np.float32)
        try:
            cc, W = cv2.findTransformECC(b, a, warp, cv2.MOTION_AFFINE, criteria, None, 5)
        except cv2.error:  # ECC did not converge from this start
            continue
        if best is None or cc > best[0]:
            best = (float(cc), W)
    if best is None:
        raise ConvertError("the view could not be aligned with its lenslet frame")
    cc, W = best
    return float(np.hypot(*W[:, 0]) / np.hypot(*W[:, 1])), cc
