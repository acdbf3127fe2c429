"""Raw Bayer lenslet frames: demosaicing, and telling a mosaic from a grey frame.

Many plenoptic cameras (Raytrix among them) can record the sensor's raw readout: one
sample per pixel behind a 2 x 2 colour filter array (CFA). ``convert.bayer`` names the
array by its top-left 2 x 2 block read row by row (``RGGB``: red at (0, 0), green at
(0, 1) and (1, 0), blue at (1, 1)), the usual naming of camera makers and of dcraw.

**Demosaicing** (:func:`demosaic`) is Malvar, He and Cutler's gradient-corrected linear
interpolation ("High-quality linear interpolation for demosaicing of Bayer-patterned
color images", ICASSP 2004): bilinear interpolation of the missing colour, corrected by
the Laplacian of the colour that the pixel holds. Four 5 x 5 kernels (Eqs. M1-M4 below,
each in eighths), applied to the mosaic and read at the sites where they belong. Their
coefficients sum to 1 and their Laplacian terms vanish on an affine image, so a frame
whose three channels are each affine in (x, y) comes back exactly
(``tests/test_demosaic.py``). It works at any bit depth, where OpenCV's better Bayer
codes (VNG) take 8-bit frames only. On the real frames of ``shared/real`` mosaicked
again (RGGB and GBRG), it comes nearer the frame than OpenCV's bilinear Bayer code on
every one: 3.8-7.6 dB on Boxer, Fujita2 and Origami (Fujita2 39.6 against 34.2 dB,
Origami 39.2 against 32.1), 0.2-3.9 dB on the TSPC frames, whose micro images are
smoother at the pixel scale, 0.9 and 17.2 dB on R42_klein_crop (GBRG, RGGB: its colours
were presumably made by a like interpolation); 0.1-0.3 s for a 12-MP frame.

**Telling a mosaic** (:func:`mosaic_likeness`): in a grey frame a pixel's diagonal
neighbours, 1.4 px away, differ from it more than its side neighbours, 1 px away; in a
Bayer mosaic the two greens of each 2 x 2 block are diagonal neighbours of the same
colour, and differ from each other far less than from the red and blue beside them (or,
under a raw sensor's gains, a dark red and a dark blue can be the more alike pair: the
measure does not tell which diagonal the greens are on, so the warning does not name a
pattern). The measure is the mean absolute difference along the more alike diagonal over that along
the sides: 1.20-1.43 on the grey versions of every frame in ``shared/real``, 0.15-0.64
on the same frames mosaicked (white-balanced) and 0.11-0.30 with a raw sensor's channel
gains. A frame under :data:`MOSAIC_LIKENESS` is reported as a likely mosaic.
"""

from __future__ import annotations

import numpy as np

BAYER_PATTERNS = ("RGGB", "GRBG", "GBRG", "BGGR")

# Below this, a one-channel frame's pixels are more alike along one diagonal than along
# the sides: a Bayer mosaic's greens. A grey frame gives 1.0 where it is pure noise (every
# neighbour alike) and more where it has content (about sqrt 2 for smooth content): 0.9
# leaves a tenth below noise alone, which only a scene dominated by 45-degree lines
# reaches; it is a warning, and the user decides.
MOSAIC_LIKENESS = 0.9

_BAND_ROWS = 256  # rows demosaiced at a time (even): 70 MB of float32 at 7716 px across

# Eq. M1: green at a red or blue site
_K_GREEN = np.array([[0, 0, -1, 0, 0],
                     [0, 0, 2, 0, 0],
                     [-1, 2, 4, 2, -1],
                     [0, 0, 2, 0, 0],
                     [0, 0, -1, 0, 0]], np.float32) / 8
# Eq. M2: at a green site, the colour of its row's other sites (its left and right
# neighbours); Eq. M3, its transpose: the colour of its column's other sites
_K_ROW = np.array([[0, 0, 0.5, 0, 0],
                   [0, -1, 0, -1, 0],
                   [-1, 4, 5, 4, -1],
                   [0, -1, 0, -1, 0],
                   [0, 0, 0.5, 0, 0]], np.float32) / 8
_K_COLUMN = np.ascontiguousarray(_K_ROW.T)
# Eq. M4: red at a blue site, blue at a red site (the diagonal neighbours)
_K_DIAGONAL = np.array([[0, 0, -1.5, 0, 0],
                        [0, 2, 0, 2, 0],
                        [-1.5, 0, 6, 0, -1.5],
                        [0, 2, 0, 2, 0],
                        [0, 0, -1.5, 0, 0]], np.float32) / 8


def colour_sites(pattern: str) -> dict[str, tuple[int, int]]:
    """The (row, column) parity of the red and blue sites of ``pattern``."""
    pattern = pattern.upper()
    if pattern not in BAYER_PATTERNS:
        raise ValueError(f"Bayer pattern {pattern!r}: one of {', '.join(BAYER_PATTERNS)}")
    return {colour: divmod(k, 2) for k, colour in enumerate(pattern) if colour != "G"}


def mosaic(rgb: np.ndarray, pattern: str) -> np.ndarray:
    """The one-channel readout ``(H, W)`` of an RGB frame ``(H, W, 3)`` behind the colour
    filter array ``pattern``: each pixel keeps the one colour its filter passes (the
    forward model that :func:`demosaic` inverts; tests and benchmarks make raw frames
    with it)."""
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"an RGB frame (H, W, 3), not shape {rgb.shape}")
    sites = colour_sites(pattern)
    out = rgb[:, :, 1].copy()
    for colour, channel in (("R", 0), ("B", 2)):
        dy, dx = sites[colour]
        out[dy::2, dx::2] = rgb[dy::2, dx::2, channel]
    return out


def _demosaic_band(band: np.ndarray, pattern: str) -> np.ndarray:
    """Eqs. M1-M4 on a float32 band whose first row is an even row of the frame."""
    import cv2  # noqa: PLC0415

    def filt(kernel: np.ndarray) -> np.ndarray:
        return cv2.filter2D(band, cv2.CV_32F, kernel, borderType=cv2.BORDER_REFLECT_101)

    green, row, column, diagonal = (filt(k) for k in (_K_GREEN, _K_ROW, _K_COLUMN,
                                                      _K_DIAGONAL))
    out = np.empty((*band.shape, 3), np.float32)
    sites = colour_sites(pattern)
    (ry, rx), (by, bx) = sites["R"], sites["B"]
    for py in (0, 1):
        for px in (0, 1):
            at = (slice(py, None, 2), slice(px, None, 2))
            if (py, px) == (ry, rx):
                out[(*at, 0)], out[(*at, 1)], out[(*at, 2)] = band[at], green[at], diagonal[at]
            elif (py, px) == (by, bx):
                out[(*at, 0)], out[(*at, 1)], out[(*at, 2)] = diagonal[at], green[at], band[at]
            elif py == ry:  # a green site in a red row: red beside it, blue above and below
                out[(*at, 0)], out[(*at, 1)], out[(*at, 2)] = row[at], band[at], column[at]
            else:  # a green site in a blue row
                out[(*at, 0)], out[(*at, 1)], out[(*at, 2)] = column[at], band[at], row[at]
    return out


def demosaic(mosaic: np.ndarray, pattern: str, band_rows: int = _BAND_ROWS) -> np.ndarray:
    """A raw Bayer frame ``(H, W)`` (uint8 or uint16) to RGB ``(H, W, 3)`` of its dtype.

    Malvar-He-Cutler interpolation (Eqs. M1-M4 of the module's docstring), rounded and
    clipped to ``[0, mosaic.max()]`` (so that ``convert.bit_depth: auto`` reads the same
    significant bits from the result as from the mosaic). Made in bands of ``band_rows``
    rows with two rows of context each side: the same values as one pass over the whole
    frame, with a few bands of float32 in memory instead of the frame's four."""
    if mosaic.ndim != 2:
        raise ValueError(f"a Bayer mosaic has one channel, not shape {mosaic.shape}")
    if mosaic.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"a Bayer mosaic is 8- or 16-bit, not {mosaic.dtype}")
    colour_sites(pattern)
    band_rows = max(2, band_rows - band_rows % 2)
    h = mosaic.shape[0]
    top = float(mosaic.max()) if mosaic.size else 0.0
    out = np.empty((*mosaic.shape, 3), mosaic.dtype)
    for y0 in range(0, h, band_rows):
        y1 = min(h, y0 + band_rows)
        a, b = max(0, y0 - 2), min(h, y1 + 2)  # a is even: the band keeps the pattern
        rgb = _demosaic_band(mosaic[a:b].astype(np.float32), pattern)[y0 - a:y1 - a]
        np.clip(np.rint(rgb, out=rgb), 0.0, top, out=rgb)
        out[y0:y1] = rgb
    return out


def mosaic_likeness(image: np.ndarray, crop: int = 2048) -> float:
    """How much a one-channel frame looks like a Bayer mosaic: the mean absolute difference
    between the pixels of the more alike diagonal of each 2 x 2 block over the mean along
    its sides (a grey frame about 1.2-1.4, pure noise 1.0, a mosaic well under
    :data:`MOSAIC_LIKENESS`). Measured on the central ``crop`` x ``crop`` pixels
    (even-aligned).

    Which diagonal is the more alike does not tell the pattern: it is the greens' where
    the scene is coloured, but a dark red and a dark blue can be nearer each other than
    two greens across an edge (a lenslet frame under a raw sensor's gains did that)."""
    if image.ndim != 2:
        raise ValueError(f"one channel expected, not shape {image.shape}")
    h, w = image.shape
    ch, cw = min(h, crop) // 2 * 2, min(w, crop) // 2 * 2
    y, x = (h - ch) // 4 * 2, (w - cw) // 4 * 2
    x0 = image[y:y + ch, x:x + cw].astype(np.int32)
    p00, p01, p10, p11 = x0[0::2, 0::2], x0[0::2, 1::2], x0[1::2, 0::2], x0[1::2, 1::2]
    main = float(np.mean(np.abs(p00 - p11)))
    anti = float(np.mean(np.abs(p01 - p10)))
    sides = float(np.mean([np.mean(np.abs(p00 - p01)), np.mean(np.abs(p00 - p10)),
                           np.mean(np.abs(p11 - p01)), np.mean(np.abs(p11 - p10))]))
    if sides == 0.0:
        return float("inf")  # a flat frame: nothing to tell
    return min(main, anti) / sides


def mosaic_warning(image: np.ndarray) -> str | None:
    """A warning for a one-channel frame that looks like a raw Bayer mosaic, naming the
    setting that demosaics it; None otherwise."""
    if image.ndim != 2 or min(image.shape) < 4:
        return None
    likeness = mosaic_likeness(image)
    if not likeness < MOSAIC_LIKENESS:
        return None
    return (f"the grey frame looks like a raw Bayer mosaic (its pixels are alike along one "
            f"diagonal of each 2 x 2 block, {likeness:.2f} of the sides' difference; a grey "
            f"frame gives about 1.2-1.4). If it is, give the camera's colour filter array, "
            f"{', '.join(BAYER_PATTERNS)} (its datasheet or its raw files' metadata say "
            f"which), as plenocal convert --bayer PATTERN or convert.bayer in the config, "
            f"and the views come out in colour, without the mosaic's checker pattern")
