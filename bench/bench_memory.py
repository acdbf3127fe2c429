"""Peak memory and time of ``plenocal convert`` on Raytrix-class sensors (issue 35: at most
1 GB on a 31-MP frame), the right MLA kind and the wrong one.

    python bench/bench_memory.py [--sizes 6464x4852 7716x5364] [--rounds 1] [--out BENCHMARKS.md]

For each size a frame is made once (not timed) on the grid of the R32 fixture's
calib.xml (``shared/fixtures/raytrix-calib/TempleBoatGiantR32.xml``: 190-um lenses of
about 34 px), one textured plane at patch size 7 on every lens (``synth.lenslets``,
Keplerian micro images), and converted as a user does, whole processes in the user's
environment with the command line's default threads (the cores the process may use: two on
the 2-core machine of the published figures; the header says how many), this checkout first
on PYTHONPATH:

- ``plenocal convert FRAME XML -o DIR --views 5``: the command line's defaults;
- the same with ``--png-bits 16``: views of twice the bytes;
- the same with ``--mla galilean``: the wrong kind. The converter warns that the views will
  be a mosaic; almost no lens matches, every patch size is filled and the views are about
  1.5x as wide, with most of their pixels weak (:mod:`plenocal.convert.holes`). A user's
  mistake, and the shape of any frame whose lenses mostly fail to match (a dark or flat
  frame): it must not take the machine's memory.

Each run: the wall time and the peak RSS (``/usr/bin/time -f %M``, as ``bench_real.py``
measures TLCT and ours), and the central view's size. Reported: the largest peak and the
median time over the rounds, against the 1-GB ceiling (R42's 7716 x 5364 is 41 MP: the
same ceiling is asked of it, as issue 35's "bounded on 40-MP sensors").
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))  # synth: test inputs

from bench_real import USER_ENV, measure, plenocal_cmd, png_size  # noqa: E402
from benchmd import Lines, positive_int, update_sections  # noqa: E402

from plenocal.cli import default_threads, frame_size  # noqa: E402

CALIB = Path("/work/shared/fixtures/raytrix-calib/TempleBoatGiantR32.xml")
#: the patch size of the frame's one plane (px; the R32 fixture's lenses are about 34 px)
PATCH_PX = 7.0
CEILING_BYTES = 10**9  # 1 GB, not GiB: the stricter reading
#: name -> extra arguments of ``plenocal convert``
VARIANTS = {
    "defaults": [],
    "--png-bits 16": ["--png-bits", "16"],
    "--mla galilean (wrong)": ["--mla", "galilean"],
}


def make_frame(size: tuple[int, int], path: Path) -> None:
    """The frame of the module docstring, written as an 8-bit RGB PNG."""
    import cv2  # noqa: PLC0415
    from synth.lenslets import lenslet_from_patch_size, random_texture  # noqa: PLC0415

    from plenocal.grid import MicrolensGrid  # noqa: PLC0415
    from plenocal.io.raytrix import read_calib  # noqa: PLC0415

    grid = MicrolensGrid(read_calib(CALIB), *size)
    img = lenslet_from_patch_size(grid, PATCH_PX, random_texture(2048, 1.5, 7))
    cv2.imwrite(str(path), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", nargs="+", type=frame_size,
                    default=[(6464, 4852), (7716, 5364)], metavar="WxH",
                    help="frame sizes WxH (default: R32's 31 MP and R42's 41 MP)")
    ap.add_argument("--rounds", type=positive_int, default=1)
    ap.add_argument("--views", type=int, default=5)
    ap.add_argument("--out", default=None, help="also write the figures into this BENCHMARKS.md")
    args = ap.parse_args()
    if not CALIB.is_file():
        sys.exit(f"{CALIB}: missing (the shared fixtures)")
    pypath = os.pathsep.join(p for p in (str(ROOT), USER_ENV.get("PYTHONPATH")) if p)
    env = {**USER_ENV, "PYTHONPATH": pypath}
    out = Lines()
    sizes = " ".join(f"{w}x{h}" for w, h in args.sizes)
    out.say(f"`python bench/bench_memory.py --sizes {sizes} --rounds "
            f"{args.rounds}` ({os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at "
            f"the start): `plenocal convert FRAME {CALIB.name} -o DIR --views {args.views}` and "
            f"its variants, whole processes ({default_threads()} threads: the command "
            f"line's default, the cores it may use). Peak RSS the largest over the "
            f"rounds, time the median. Ceiling (issue 35): 1 GB on a 31-MP frame.")
    out.say("")
    out.head("frame", "MP", "variant", "s", "peak GB", "central view", "within 1 GB")
    worst = 0
    with tempfile.TemporaryDirectory(prefix="bench_memory_") as tmp:
        work = Path(tmp)
        for W, H in args.sizes:
            frame = work / f"frame_{W}x{H}.png"
            t0 = time.perf_counter()
            make_frame((W, H), frame)
            print(f"{frame.name}: made in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
            for name, extra in VARIANTS.items():
                walls, peaks = [], []
                views = work / "views"
                for _ in range(args.rounds):
                    shutil.rmtree(views, ignore_errors=True)
                    wall, peak = measure([*plenocal_cmd(), "convert", str(frame), str(CALIB),
                                          "-o", str(views), "--views", str(args.views), *extra],
                                         env, work)
                    walls.append(wall)
                    peaks.append(peak)
                h = (args.views - 1) // 2
                vw, vh = png_size(views / f"{h}_{h}.png")
                worst = max(worst, max(peaks))
                out.say(f"| {W}x{H} | {W * H / 1e6:.1f} | {name} | {statistics.median(walls):.1f} "
                        f"| {max(peaks) / 1e9:.2f} | {vw}x{vh} | "
                        f"{'yes' if max(peaks) <= CEILING_BYTES else '**no**'} |")
            frame.unlink()
    out.say("")
    out.say(f"Largest peak {worst / 1e9:.2f} GB: the ceiling "
            f"{'met' if worst <= CEILING_BYTES else 'NOT met'}.")
    if args.out:
        update_sections(args.out, {"Peak memory on 31- and 41-MP frames (bench_memory.py)": out})


if __name__ == "__main__":
    main()
