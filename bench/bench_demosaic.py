"""Raw Bayer frames: the demosaicing and the mosaic detector on every real frame.

    python bench/bench_demosaic.py [--frames Boys2 Fujita2 ...] [--patterns RGGB GBRG]

No real raw readout is at hand, so every frame in shared/real/frames (demosaiced colour
frames) is mosaicked again behind each ``--patterns`` array and brought back by
:func:`plenocal.convert.demosaic.demosaic` (Malvar-He-Cutler) and, beside it, by
OpenCV's bilinear Bayer code; each is compared with the frame (PSNR over the pixels 4 or
more from the border, 8-bit). The detector (:func:`mosaic_likeness`) is read on the
frame's grey version, on each mosaic, and on a mosaic with a raw sensor's channel gains
(0.55, 1, 0.7: before white balance). Times: the best of three demosaicings.
"""

from __future__ import annotations

import argparse
import time

import cv2
import numpy as np
from bench_real import REAL, real_frames

from plenocal.convert.demosaic import MOSAIC_LIKENESS, demosaic, mosaic, mosaic_likeness

FRAMES = REAL / "frames"
# OpenCV names a Bayer code by the second row's first two colours (its own convention)
_OPENCV = {"RGGB": cv2.COLOR_BayerBG2RGB, "GRBG": cv2.COLOR_BayerGB2RGB,
           "GBRG": cv2.COLOR_BayerGR2RGB, "BGGR": cv2.COLOR_BayerRG2RGB}
RAW_GAINS = np.array([0.55, 1.0, 0.7])


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    d = (a.astype(np.float64) - b.astype(np.float64))[4:-4, 4:-4]
    return float(10 * np.log10(255.0 ** 2 / np.mean(d ** 2)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", nargs="*", default=None, help="frame names (default: all)")
    ap.add_argument("--patterns", nargs="*", default=["RGGB", "GBRG"], type=str.upper,
                    choices=sorted(_OPENCV), help="Bayer patterns (any case)")
    args = ap.parse_args()
    # as bench_real: a frame not there (or no frames at all) stops it, with the names there
    paths = [FRAMES / f"{name}.png" for name in real_frames(args.frames)]
    print(f"Mosaicked real frames brought back (PSNR dB against the frame); detector "
          f"likeness (a mosaic under {MOSAIC_LIKENESS}):\n")
    print("| frame | MP | pattern | ours dB | OpenCV bilinear dB | ours - OpenCV | ours s "
          "| likeness: grey / mosaic / raw gains |")
    print("|---|---:|---|---:|---:|---:|---:|---|")
    for path in paths:
        rgb = cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB)
        grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
        raw_like = np.clip(rgb * RAW_GAINS, 0, 255).astype(np.uint8)
        for pattern in args.patterns:
            m = mosaic(rgb, pattern)
            times = []
            for _ in range(3):
                t = time.perf_counter()
                ours = demosaic(m, pattern)
                times.append(time.perf_counter() - t)
            a, b = psnr(ours, rgb), psnr(cv2.cvtColor(m, _OPENCV[pattern]), rgb)
            like = (mosaic_likeness(grey), mosaic_likeness(m),
                    mosaic_likeness(mosaic(raw_like, pattern)))
            print(f"| {path.stem} | {rgb.shape[0] * rgb.shape[1] / 1e6:.1f} | {pattern} "
                  f"| {a:.2f} | {b:.2f} | {a - b:+.2f} | {min(times):.2f} "
                  f"| {like[0]:.2f} / {like[1]:.2f} / {like[2]:.2f} |", flush=True)


if __name__ == "__main__":
    main()
