"""16-bit normalised-disparity depth maps for the MPEG tools (RVS, DERS, IVDE, TMIV).

``L = round((2^16 - 1) (1/z - 1/far) / (1/near - 1/far))`` for a z-depth ``z``
(metres) and the camera's ``Depth_range`` [near, far]: near -> 65535, far -> 0.
The camera JSON declares ``HasInvalidDepth: true``, so level 0 means "no depth":
invalid pixels (z <= 0 or not finite) are written as 0 and valid ones are clipped to
[1, 65535]. This is the project's one 16-bit depth encoder.

Raw YUV 4:2:0 files (depth and textures) have chroma planes of ``W // 2 x H // 2``,
the layout RVS 4.0 reads (OpenCV's ``Size / 2``); for even sizes that is the standard
layout, for odd sizes the usual ``(W + 1) // 2`` differs, so views of even size
(``convert.even_size``) are the portable choice. Textures are written in OpenCV's
full-range YUV (``cv2.COLOR_RGB2YUV``), the conversion RVS inverts.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from plenocal.io.files import atomic_write_bytes, write_image

MAX_LEVEL = 2 ** 16 - 1


def depth16(z: np.ndarray, near: float, far: float, invalid_zero: bool = True) -> np.ndarray:
    """z-depth (0 = invalid) to 16-bit normalised disparity levels (uint16)."""
    if not 0 < near < far:
        raise ValueError(f"depth range must satisfy 0 < near < far (got {near}, {far})")
    z = np.asarray(z, dtype=np.float64)
    ok = np.isfinite(z) & (z > 0)
    inv = np.zeros_like(z)
    inv[ok] = 1.0 / z[ok]
    level = np.rint(MAX_LEVEL * (inv - 1.0 / far) / (1.0 / near - 1.0 / far))
    level = np.clip(level, 1 if invalid_zero else 0, MAX_LEVEL)
    if invalid_zero:
        level = np.where(ok, level, 0)
    return np.asarray(level).astype(np.uint16)


def depth_from16(level: np.ndarray, near: float, far: float,
                 invalid_zero: bool = True) -> np.ndarray:
    """Inverse of :func:`depth16` (float64 metres; 0 where the level is 0 and
    ``invalid_zero``)."""
    lv = np.asarray(level, dtype=np.float64)
    inv = lv / MAX_LEVEL * (1.0 / near - 1.0 / far) + 1.0 / far
    z = 1.0 / inv
    if invalid_zero:
        z = np.where(lv == 0, 0.0, z)
    return z


def write_depth16_png(path: str | Path, z: np.ndarray, near: float, far: float) -> None:
    """A 16-bit grey PNG of the levels."""
    write_image(path, depth16(z, near, far))


def write_depth16_yuv(path: str | Path, z: np.ndarray, near: float, far: float) -> None:
    """One frame of raw YUV 4:2:0, 16 bits little-endian (``DepthColorSpace: YUV420``):
    the levels in Y, the chroma planes (W // 2 x H // 2) at mid-grey 32768."""
    y = depth16(z, near, far)
    h, w = y.shape
    c = np.full((h // 2, w // 2), 1 << 15, dtype="<u2")
    data = y.astype("<u2").tobytes() + c.tobytes() + c.tobytes()
    atomic_write_bytes(path, data)


def texture_yuv420(rgb: np.ndarray) -> bytes:
    """One frame of raw 8-bit YUV 4:2:0 of an RGB uint8 image: full-range YUV
    (``cv2.COLOR_RGB2YUV``), chroma averaged over 2 x 2 pixels (W // 2 x H // 2)."""
    import cv2  # noqa: PLC0415

    rgb = np.asarray(rgb)
    if rgb.dtype != np.uint8 or rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError("texture_yuv420 needs an RGB uint8 image (H, W, 3)")
    yuv = cv2.cvtColor(rgb, cv2.COLOR_RGB2YUV).astype(np.float32)
    h, w = rgb.shape[:2]
    h2, w2 = h // 2, w // 2
    ch = yuv[: 2 * h2, : 2 * w2, 1:].reshape(h2, 2, w2, 2, 2).mean(axis=(1, 3))
    planes = [yuv[..., 0], ch[..., 0], ch[..., 1]]
    return b"".join(np.clip(np.rint(p), 0, 255).astype(np.uint8).tobytes() for p in planes)


def write_texture_yuv(path: str | Path, rgb: np.ndarray) -> None:
    """A texture as one frame of raw 8-bit YUV 4:2:0 (``ColorSpace: YUV420``)."""
    atomic_write_bytes(path, texture_yuv420(rgb))
