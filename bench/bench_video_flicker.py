"""Temporal stability of the video converter on a static part of a real sequence (issue 35).

    python bench/bench_video_flicker.py [--seq Boys2 Fujita2 ...] [--margin 0.03]

shared/real/frames holds two frames of each MPEG lenslet sequence: frame 0 and frame 150.
Where the scene did not move between them (the background, the table), the two differ by
coding noise only: what consecutive frames of a static scene differ by. Each sequence's
crop (CROPS) is made into a two-frame 10-bit YUV 4:2:0 clip (BT.709 limited: the frames'
RGB through :func:`plenocal.io.yuv.rgb_to_yuv`) and converted with
:class:`plenocal.convert.video.VideoConverter`, once with ``temporal: off`` (every frame
alone, as its PNG) and once with ``temporal: hold``.

Static lenses: those whose micro image (a box of one pitch about its centre) differs
between the two input frames by less than STATIC_LEVEL (mean absolute grey difference in
8-bit levels: coding noise; moving objects differ by tens). Reported over them: the share
whose patch size changes by more than CHANGE_PX between the frames, the mean |change|,
and the central view's mean absolute temporal difference (8-bit levels of the RGB view)
over the output pixels whose nearest lens is static, beside the input's own (the same
box-mean difference at those lenses: the noise floor the view cannot go under).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import cv2
import numpy as np

# this checkout's package and test helpers, not an installed copy (a worktree measures its
# own code)
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from test_convert_real import REAL, crop  # noqa: E402

from plenocal.convert import ConvertSettings, ShotConversion  # noqa: E402
from plenocal.convert.analysis import ConvertAnalysis  # noqa: E402
from plenocal.convert.render import blend_disagreement  # noqa: E402
from plenocal.convert.video import VideoConverter, VideoSettings, lenslet_frame  # noqa: E402
from plenocal.io.yuv import rgb_to_yuv  # noqa: E402
from plenocal.viewgeom import nearest_lenses  # noqa: E402

# (x0, y0, w, h): crops holding static background and moving parts (frame 0 vs 150)
CROPS = {
    "Boys2": (1800, 0, 2176, 1600),
    "Fujita2": (0, 0, 1400, 1100),
    "Boxer-IrishMan-Gladiator2": (0, 0, 1800, 1400),
}
STATIC_LEVEL = 4.0
CHANGE_PX = 0.25


def _pair(seq: str) -> tuple[list[np.ndarray], object]:
    a, calib = crop(seq, *CROPS[seq])
    x0, y0, w, h = CROPS[seq]
    b = cv2.imread(str(REAL / "frames" / f"{seq}_f150.png"))[y0:y0 + h, x0:x0 + w, ::-1]
    frames = []
    for rgb in (a, np.ascontiguousarray(b)):
        planes = rgb_to_yuv(rgb.astype(np.float32) / 255.0, 10)
        frames.append(lenslet_frame(planes, 10))
    return frames, calib


def measure(seq: str, margin: float) -> dict:
    frames, calib = _pair(seq)
    out = {}
    for mode in ("off", "hold"):
        conv = VideoConverter(calib, 5, ConvertSettings(), VideoSettings(temporal=mode,
                                                                        hold_margin=margin))
        shots, t = [], []
        for k, img in enumerate(frames):
            t0 = time.perf_counter()
            shots.append(conv.convert(img, f"{seq}[{k}]"))
            shots[-1].view(2, 2)
            t.append(time.perf_counter() - t0)
        s0, s1 = shots
        grid = s0.grid
        g = [cv2.cvtColor(f, cv2.COLOR_RGB2GRAY).astype(np.float32) / 257.0 for f in frames]
        D = int(round(grid.diameter))
        box = cv2.blur(np.abs(g[0] - g[1]), (D, D))
        c = np.rint(grid.centres).astype(int)
        inside = ((c[:, 0] >= 0) & (c[:, 0] < box.shape[1]) & (c[:, 1] >= 0)
                  & (c[:, 1] < box.shape[0]))
        lens_diff = np.full(len(grid), np.inf)
        lens_diff[inside] = box[c[inside, 1], c[inside, 0]]
        used = s0.layout.lens_index
        static = lens_diff[used] < STATIC_LEVEL
        dP = np.abs(s1.used_patch - s0.used_patch)[static]
        v0, v1 = (s.view(2, 2).astype(np.float32) for s in (s0, s1))
        idx, _ = nearest_lenses(s0.layout, k=1)
        idx = idx[..., 0]
        mask = (idx >= 0) & static[np.maximum(idx, 0)]
        # the views' change that the patch sizes make: frame 1 rendered with its own sizes
        # against frame 1 rendered with frame 0's (the input's own change cancels)
        a1 = s1.analysis
        same = ShotConversion(frames[1], calib, 5, s1.settings, grid=grid,
                              analysis=ConvertAnalysis(a1.mla, None, s0.patch, a1.profile,
                                                       a1.profile_row),
                              check_mla=False, safe_diameter=s1.safe.diameter_px)
        vs = same.view(2, 2).astype(np.float32)
        conf0 = s0.patch.confident[used][static]
        conf1 = s1.patch.confident[used][static]
        out[mode] = {
            "patch_view_diff": float(np.abs(v1 - vs).mean(axis=2)[mask].mean()),
            "changed_confident": float(((dP > CHANGE_PX) & conf0 & conf1).mean()),
            "blend_disagreement": float(blend_disagreement(s1.plan_for(2, 2), s1.source_float, 2,
                                                           2)),
            "static_lenses": int(static.sum()), "lenses": int(len(used)),
            "changed_share": float((dP > CHANGE_PX).mean()),
            "mean_abs_dP": float(dP.mean()),
            "view_diff": float(np.abs(v1 - v0).mean(axis=2)[mask].mean()),
            "input_diff": float(lens_diff[used][static].mean()),
            "held_share": conv.held_share, "s_per_frame": float(np.mean(t)),
            "view": f"{s0.layout.width}x{s0.layout.height}",
        }
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seq", nargs="+", default=list(CROPS), choices=list(CROPS),
                    metavar="SEQ", help="the sequences with a crop defined (CROPS): "
                                        f"{', '.join(CROPS)} (default: all)")
    ap.add_argument("--margin", type=float, default=VideoSettings().hold_margin)
    args = ap.parse_args()
    cv2.setNumThreads(1)
    print("| sequence | static lenses | mode | P changed > 0.25 px (both confident) | "
          "mean abs dP (px) | view diff (levels) | of it the patch sizes' | input diff | "
          "held | blend disagreement, frame 1 | s/frame |")
    print("|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for seq in args.seq:
        r = measure(seq, args.margin)
        for mode, m in r.items():
            held = "-" if m["held_share"] is None else f"{100 * m['held_share']:.0f} %"
            print(f"| {seq} ({m['view']}) | {m['static_lenses']} / {m['lenses']} | {mode} | "
                  f"{100 * m['changed_share']:.1f} % ({100 * m['changed_confident']:.1f} %) | "
                  f"{m['mean_abs_dP']:.3f} | {m['view_diff']:.2f} | "
                  f"{m['patch_view_diff']:.2f} | {m['input_diff']:.2f} | {held} | "
                  f"{m['blend_disagreement']:.3f} | {m['s_per_frame']:.2f} |", flush=True)


if __name__ == "__main__":
    main()
