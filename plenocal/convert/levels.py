"""Grey levels of the lenslet image: how many bits a 16-bit PNG really holds.

Most sensors deliver 10, 12 or 14 bits; written LSB-aligned into a 16-bit PNG the
image holds values up to 1023, 4095 or 16383, and read as 16-bit data it is 1/64 to
1/4 as bright as it should be. ``bit_depth: auto`` takes the smallest of 10, 12, 14,
16 bits that holds the image's maximum (8-bit images are 8 bits); a number (8..16)
states it. Values are then scaled by ``1 / (2^bits - 1)`` to [0, 1].

``auto`` cannot tell a 12-bit image from a dark 16-bit one whose maximum stays below
4096: state ``bit_depth: 16`` for those (the log names the depth it took).
"""

from __future__ import annotations

import cv2
import numpy as np

from plenocal.convert.errors import ConvertError
from plenocal.convert.prefilter import prefilter

AUTO_DEPTHS = (10, 12, 14, 16)


def significant_bits(image: np.ndarray, setting: int | str = "auto", source: str = "") -> int:
    """Bits of data in ``image`` (uint8: 8; uint16: see the module docstring); ``source``:
    the image's file, for the message where ``setting`` is too small for it."""
    if image.dtype == np.uint8:
        return 8
    if image.dtype != np.uint16:
        raise ConvertError(f"lenslet image of type {image.dtype}: need 8- or 16-bit data")
    peak = int(image.max()) if image.size else 0
    if setting != "auto":
        bits = int(setting)
        if peak > (1 << bits) - 1:
            raise ConvertError(f"{source + ': ' if source else ''}convert.bit_depth "
                               f"(--bit-depth): {bits} bits, but the image holds values up "
                               f"to {peak}: set a larger bit depth or 'auto'")
        return bits
    return next(b for b in AUTO_DEPTHS if peak <= (1 << b) - 1)


#: share of a frame's pixels clipped at full scale from which the converter warns that
#: the frame is overexposed, and the grid errors say that the frame, not the file, may be
#: what the grid check failed on (:func:`plenocal.convert.setup.overexposure_hint`); the
#: real frames of shared/real clip 0.3-3.9 %, the simulator's none
OVEREXPOSED_SHARE = 0.2


def clipped_share(image: np.ndarray) -> float:
    """The share of the pixels at full scale in any channel (8-bit data 255, 16-bit data
    ``2^bits - 1`` of :func:`significant_bits`): the frame's overexposed part."""
    if image.size == 0 or image.dtype not in (np.uint8, np.uint16):
        return 0.0
    # the brightest channel by OpenCV's passes over contiguous planes: numpy's any() over
    # the last axis took 188 ms on a 12-MP RGB frame, this 20-odd
    planes = cv2.split(image) if image.ndim == 3 else [image]
    peak = planes[0]
    for plane in planes[1:]:
        peak = cv2.max(peak, plane)
    top = (1 << significant_bits(peak)) - 1
    return cv2.countNonZero(cv2.compare(peak, top, cv2.CMP_EQ)) / peak.size


def to_unit_float(image: np.ndarray, bits: int) -> np.ndarray:
    """float32 in [0, 1] (contiguous) of an 8/16-bit image holding ``bits`` bits."""
    f = np.multiply(image, np.float32(1.0 / ((1 << bits) - 1)), dtype=np.float32)  # one pass
    return np.ascontiguousarray(f)


def render_source(image: np.ndarray, bits: int, prefilter_a: float = 0.0
                  ) -> tuple[np.ndarray, float]:
    """The image the views sample, and the factor that brings its values to [0, 1]: 8-bit
    data as it is; 16-bit data holding ``bits`` bits shifted to the top of the word, so
    that the interpolation's rounding (OpenCV interpolates integers to an integer) falls
    ``16 - bits`` bits below the data's last one. Sampling the integers rather than a
    float copy reads a quarter (8 bit) or half the bytes; the frame is copied only where
    it is shifted or prefiltered (``prefilter_a``: :mod:`plenocal.convert.prefilter`, on
    the shifted integers, so that its rounding too falls below the data's last bit)."""
    # 16-bit: the image holds no value above 2^bits - 1 (significant_bits)
    shift = 0 if image.dtype == np.uint8 else 16 - bits
    if shift:
        src = prefilter(np.left_shift(image, np.uint16(shift)), prefilter_a, in_place=True)
    else:
        src = prefilter(np.ascontiguousarray(image), prefilter_a)
    return src, 1.0 / (((1 << bits) - 1) << shift)
