"""Converter speed (issue 3 target: <= 3 s per 4-megapixel lenslet image, 25 views, one core).

    python bench/bench_convert.py [--calib Fujita2.xml] [--size 2048] [--views 5] [--lenslet PNG]

Without ``--lenslet`` a 2048 x 2048 lenslet image is made on the grid of the given
Raytrix calibration (Fujita2 by default: D = 23.2 px, ~9000 lenses) with two textured
planes (patch sizes 4.5 and 7.5 px; synth.lenslets). Everything runs on
one thread (OpenCV, OpenMP, numba). Prints the time of each step, the total for all
N x N views without PNG encoding (the PNG encoding's time beside it), the throughput in
megapixels of lenslet image per second and the best total per 4 megapixels against the
target, and the accuracy of the patch sizes against the truth.
"""

from __future__ import annotations

# run as a script only (bench/one_thread.py says why)
if __name__ == "__main__":
    from one_thread import pin

    pin()

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))  # synth: test inputs

from benchmd import Lines, positive_int, update_sections  # noqa: E402
from synth.lenslets import lenslet_from_patch_size, random_texture  # noqa: E402

from plenocal.convert import ShotConversion  # noqa: E402
from plenocal.grid import MicrolensGrid  # noqa: E402
from plenocal.io.files import read_image  # noqa: E402
from plenocal.io.raytrix import read_calib  # noqa: E402
from plenocal.malloc import no_huge_pages  # noqa: E402

FIXTURES = Path("/work/shared/fixtures/raytrix-calib")


def synthetic_image(calib, size: int) -> tuple[np.ndarray, MicrolensGrid, np.ndarray]:
    grid = MicrolensGrid(calib, size, size)
    tex = random_texture(1024, 1.5, 0)
    near = lenslet_from_patch_size(grid, 7.5, tex, texture_scale=0.5)
    far = lenslet_from_patch_size(grid, 4.5, tex, texture_scale=0.5)
    ys, xs = np.mgrid[0:size, 0:size]
    # whole micro images: lenses left of the middle see the near plane
    owner = np.full((size, size), -1)
    d2 = np.full((size, size), np.inf)
    for k, (cx, cy) in enumerate(grid.centres):
        x0, x1 = int(max(cx - calib.diameter, 0)), int(min(cx + calib.diameter + 1, size))
        y0, y1 = int(max(cy - calib.diameter, 0)), int(min(cy + calib.diameter + 1, size))
        dd = (xs[y0:y1, x0:x1] - cx) ** 2 + (ys[y0:y1, x0:x1] - cy) ** 2
        win = dd < d2[y0:y1, x0:x1]
        d2[y0:y1, x0:x1][win] = dd[win]
        owner[y0:y1, x0:x1][win] = k
    truth = np.where(grid.centres[:, 0] < size / 2, 7.5, 4.5)
    img = np.where((truth[owner] == 7.5)[..., None], near, far)
    return img, grid, truth


def main() -> None:
    no_huge_pages()  # as the command line: its timings are those a user sees
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=None, help="also write the figures into this BENCHMARKS.md")
    ap.add_argument("--calib", default=str(FIXTURES / "Fujita2.xml"))
    ap.add_argument("--size", type=int, default=2048)
    ap.add_argument("--views", type=int, default=5)
    ap.add_argument("--lenslet", default=None)
    ap.add_argument("--repeat", type=positive_int, default=2)
    args = ap.parse_args()
    out = Lines()
    cv2.setNumThreads(1)
    calib = read_calib(args.calib)
    truth = None
    if args.lenslet:
        img = read_image(args.lenslet)
    else:
        img, grid, truth = synthetic_image(calib, args.size)
    mp = img.shape[0] * img.shape[1] / 1e6
    out.say(f"lenslet {img.shape[1]}x{img.shape[0]} ({mp:.2f} MP), {Path(args.calib).name}, "
          f"D = {calib.diameter:.2f} px, {args.views}x{args.views} views, 1 thread")
    best = None
    for rep in range(args.repeat):
        t0 = time.perf_counter()
        shot = ShotConversion(img, calib, args.views)
        t1 = time.perf_counter()
        views = [v for _, v in shot.views()]
        t2 = time.perf_counter()
        encoded = [cv2.imencode(".png", v, [cv2.IMWRITE_PNG_COMPRESSION, 3])[1] for v in views]
        t3 = time.perf_counter()
        total = t2 - t0
        out.say(f"run {rep}: grid + patch sizes + plan {t1 - t0:.2f} s, {len(views)} views "
              f"{t2 - t1:.2f} s ({1000 * (t2 - t1) / len(views):.0f} ms each), total {total:.2f} s "
              f"= {mp / total:.2f} MP/s; PNG encoding {t3 - t2:.2f} s "
              f"({sum(len(e) for e in encoded) / 1e6:.1f} MB)")
        best = total if best is None else min(best, total)
    per4 = best * 4 / mp  # the target is per 4-megapixel image, as bench_real's "s / 4 MP"
    out.say(f"best total {best:.2f} s for {mp:.2f} MP ({mp / best:.2f} MP/s), {per4:.2f} s / "
            f"4 MP; target <= 3 s / 4 MP: {'met' if per4 <= 3.0 else 'NOT met'}")
    L = shot.layout
    out.say(f"views {L.width}x{L.height}, tile {L.tile}, q {L.q:.3f} px, {len(L.lens_index)} used "
          f"lenses of {len(shot.grid)}")
    if truth is not None:
        err = shot.patch.patch - truth
        inner = shot.grid.inside()
        out.say(f"patch size vs truth (used lenses): median |err| "
                f"{np.median(np.abs(err[inner])):.3f}"
              f" px, within 0.25 px {np.mean(np.abs(err[inner]) < 0.25):.1%}, confident "
              f"{shot.patch.confident[inner].mean():.1%}")
    if args.out:
        update_sections(args.out, {"Conversion throughput (one core)": [
            "`python bench/bench_convert.py` (issue 3 target: 3 s per 4-megapixel lenslet "
            "image, 25 views):", "", "```", *out, "```"]})


if __name__ == "__main__":
    main()
