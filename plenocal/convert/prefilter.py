"""The lenslet frame's prefilter: bilinear sampling's blur taken back before the views
sample the frame.

Each view samples the frame at ``m_i + R (q_rc - (u - o_i) P_i / T)``
(:mod:`plenocal.convert.render`): positions at every subpixel phase, read by bilinear
interpolation. Between two samples ``x_0, x_1`` at phase ``t`` it gives
``(1 - t) x_0 + t x_1``; for a component of angular frequency ``w`` (radians per pixel)
the value read is ``H_t(w) = (1 - t) + t e^{iw}`` times its sample at 0, where the
signal itself is ``e^{iwt}``. Over a uniform phase the mean power read is
``E|H_t|^2 = 1 - (1 - cos w) / 3``: a third at the sensor's Nyquist frequency
(``w = pi``), whatever the view's sampling. The views come out softer than the frame.

A symmetric 3-tap filter ``[-a, 1 + 2a, -a]`` along the rows and the columns, run once
on the frame, has the response ``P_a(w) = 1 + 2a (1 - cos w)``: 1 at ``w = 0`` (flat
areas and the micro images' vignetting profile keep their values) and rising to
``1 + 4a`` at Nyquist. The expected squared error of the prefiltered interpolation
against the signal, for a component ``w`` (Eq. P1)::

    e(a, w) = E_t | P_a(w) ((1 - t) + t e^{iw}) - e^{iwt} |^2

averaged over the frame's spectrum ``S(w)`` (:func:`expected_error`), is least at
``a`` = 0.10-0.11 for a flat spectrum and for ``1/f`` and ``1/f^2`` ones (natural
images), in one dimension and with the 2-D separable filter alike
(``tests/test_prefilter.py``): :data:`OPTIMAL_A`. Keys' cubic interpolation
does the same job at the sampling (OpenCV's ``INTER_CUBIC``), but reads 16 samples
instead of 4 and took Boys2's whole conversion from 3.8-4.1 to 4.8-5.4 s; the prefilter
is one pass over the frame (6-32 ms on the real frames).

``convert.blend.prefilter`` is 0 (off) by default: with :data:`OPTIMAL_A` the views come
0.3-0.9 dB nearer the simulator's true pinhole renders and hold 1.03-1.17 of TLCT's fine
detail on the real frames, but the calibration made from them leaned: the focal length by
+0.027 % on average over the twenty simulated captures, one of them past issue 32's 0.1 %
(BENCHMARKS.md, "The frame prefiltered against bilinear sampling's blur"). It is for
conversions outside the calibration: the command line ``plenocal convert`` takes it by
default (:data:`plenocal.cli.CLI_CONVERT_DEFAULTS`; a view's geometry does not move with
it, so the workflow's calibration holds for those views).
"""

from __future__ import annotations

import cv2
import numpy as np

#: the least expected squared error of Eq. P1 (flat, 1/f and 1/f^2 spectra; 1-D and 2-D)
OPTIMAL_A = 0.1


def prefilter_kernel(a: float) -> np.ndarray:
    """The 1-D kernel ``[-a, 1 + 2a, -a]`` (float32, sums to 1)."""
    return np.array([-a, 1.0 + 2.0 * a, -a], dtype=np.float32)


def prefilter_response(a: float, w: np.ndarray) -> np.ndarray:
    """``P_a(w) = 1 + 2a (1 - cos w)``: the kernel's frequency response (real: it is
    symmetric) at angular frequencies ``w`` (radians per pixel)."""
    return 1.0 + 2.0 * a * (1.0 - np.cos(w))


def expected_error(a: float, w: np.ndarray, spectrum: np.ndarray,
                   phases: int = 201) -> float:
    """Eq. P1 averaged over the frequencies ``w`` with the weights ``spectrum``: the
    expected squared error of bilinear interpolation at a uniform phase after the
    prefilter ``a``, relative to the signal's power (the phase's mean over ``phases``
    evenly spaced values)."""
    t = ((np.arange(phases) + 0.5) / phases)[:, None]  # the phase's midpoints
    w = np.asarray(w, dtype=float)[None, :]
    read = prefilter_response(a, w) * ((1.0 - t) + t * np.exp(1j * w))
    err = np.mean(np.abs(read - np.exp(1j * w * t)) ** 2, axis=0)
    s = np.asarray(spectrum, dtype=float)
    return float(np.sum(err * s) / np.sum(s))


def prefilter(image: np.ndarray, a: float, in_place: bool = False) -> np.ndarray:
    """``image`` (uint8 / uint16 / float32, grey or multi-channel) filtered along its rows
    and columns by :func:`prefilter_kernel` (border: replicated), in its own type
    (integers rounded and saturated: the overshoot past white or below black at a sharp
    edge is cut, as a sensor would). ``in_place``: written over ``image`` (OpenCV's
    separable filter buffers its rows, so that is exact); a: 0 returns ``image``."""
    if a == 0:
        return image
    k = prefilter_kernel(a)
    dst = image if in_place else None
    return cv2.sepFilter2D(image, -1, k, k, dst=dst, borderType=cv2.BORDER_REPLICATE)
