"""PSNR from the errors per ring of pixels (plenocal.verify.scores) against the PSNR of
the cropped images (plenocal.verify.dibr.psnr), by hand on a tiny image, and the errors
for bad input."""

import numpy as np
import pytest

from plenocal.verify.dibr import psnr
from plenocal.verify.scores import error_rings, psnr_from_rings, ring_index, ring_sizes


def test_rings_by_hand():
    # a 4 x 5 image: the outer ring is 14 pixels, the inner one 6
    np.testing.assert_array_equal(ring_index(4, 5).reshape(4, 5), [
        [0, 0, 0, 0, 0],
        [0, 1, 1, 1, 0],
        [0, 1, 1, 1, 0],
        [0, 0, 0, 0, 0]])
    np.testing.assert_array_equal(ring_sizes((4, 5)), [14, 6])
    np.testing.assert_array_equal(ring_sizes((4, 5, 3)), [42, 18])
    a = np.zeros((4, 5))
    b = np.zeros((4, 5))
    b[0, 0] = 0.5  # outer ring: 0.25
    b[1, 2] = 0.1  # inner ring: 0.01
    np.testing.assert_allclose(error_rings(a, b), [0.25, 0.01])
    assert psnr_from_rings(error_rings(a, b), (4, 5), 1) == pytest.approx(
        10 * np.log10(6 / 0.01))
    assert psnr_from_rings(np.zeros(2), (4, 5), 0) == float("inf")


@pytest.mark.parametrize("shape", [(47, 61), (40, 33, 3)])
def test_every_border_gives_the_psnr_of_the_cropped_images(shape):
    rng = np.random.default_rng(3)
    a = rng.random(shape).astype(np.float32)
    b = np.clip(a + rng.normal(0, 0.05, shape), 0, 1).astype(np.float32)
    sse = error_rings(a, b)
    for border in range(0, min(shape[:2]) // 2):
        assert psnr_from_rings(sse, shape, border) == pytest.approx(psnr(a, b, border),
                                                                    abs=1e-9)


def test_bad_input_is_named():
    a = np.zeros((10, 12))
    with pytest.raises(ValueError, match="different shapes"):
        error_rings(a, np.zeros((10, 11)))
    with pytest.raises(ValueError, match="psnr_border_px = 5 leaves no pixel"):
        psnr_from_rings(error_rings(a, a), a.shape, 5)
    with pytest.raises(ValueError, match="ring sums for an image"):
        psnr_from_rings(np.zeros(3), a.shape, 0)
