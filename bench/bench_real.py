"""The converter on real lenslet frames (issue 12): every frame in shared/real/frames.

    python bench/bench_real.py [--out BENCHMARKS.md] [--frames Boys2 Fujita2 ...]
                               [--views 5] [--grid auto|file|refine] [--grid-ab] [--mla table|auto]
                               [--pictures bench/out]
    python bench/bench_real.py --tlct PATH/tlct [--rounds 3] [--frames ...] [--out BENCHMARKS.md]

For each frame (its RayCalibData xml beside it): the grid check (plenocal.convert.gridcheck:
the file grid's drift from the micro-image centres, refined or not under ``--grid``), then
the conversion of all N x N views on one core (OpenCV, OpenMP, numba: one thread), timed
without PNG encoding: the check, the preparation (patch sizes, layout, render plan) and
the views. Reported: the view size, the confident share of patch sizes, the grid drift,
and against the reference converter's central view where shared/real/reference has one
(TLCT v1.6.0 / RLC 4.0): the SSIM after alignment and the sharpness ratio
(plenocal.convert.compare; targets 0.85 and 0.8) and the sizes.

MLA kind per frame (RayCalibData does not say): a table in the converter's naming
(``convert.mla``, README "MLA kinds": ``keplerian`` = micro images inverted, a point
moves towards the neighbouring lens). shared/real/README.md calls the Raytrix MLAs
Keplerian and the TSPC ones Galilean; the converter's own detection (``mla: auto``)
finds the reverse in its naming on all six frames, by a wide margin (README "MLA kinds"),
and with the README's kinds the Raytrix views are mosaics (Fujita2: 16 % of patch sizes
confident, T = 4, against 67 %, T = 8). The table follows the detection: Raytrix frames
(Fujita2, Origami, Boxer-IrishMan-Gladiator2, R42_klein_crop) ``galilean``, TSPC frames
(Boys2, HandTools) ``keplerian``. ``--mla auto`` lets the converter read it instead; a
frame not in the table gets the default. Everything else is what the command line
``plenocal convert`` converts with (:func:`plenocal.cli.command_line_block`:
config.schema.yaml's ``convert`` defaults, the frame prefiltered).

Local measures (issue 33), for the central view and the two corner views 0_0 and
(N-1)_(N-1) of every frame against TLCT's views of the same frame (``centre.png``,
``v000.png``, ``v024.png``; :mod:`plenocal.convert.localcheck`): the worst textured tile
(SSIM on a 6 x 6 grid over the tiles where the reference has texture; target >= 0.85 for
the central view) and the microlens lattice's trace (dB at the lattice's frequencies;
target: at most TLCT's, on every view), each trace with its distance z from the measure's
floor on the same view (:func:`plenocal.convert.localcheck.lattice_trace`). The later
frames (``<seq>_f150.png``) use their sequence's xml.

Pictures (``--pictures``, git-ignored bench/out/): ``<frame>.png`` side by side at the
central view's height: the raw frame (area-downscaled) | our central view | the
reference's (where there is one) | the patch-size map; and ``<frame>_centre.png``, our
central view at full size, to look at at 100 %.

Speed against TLCT (``--tlct``, issue 35; instead of the above): whole processes, as a user
runs them, alternating on the same machine. For each frame, R rounds (``--rounds``) of:
TLCT v1.6.0 (shared/tools/tlct: the sequence's ``cfg/<seq>.calib.cfg`` and
``<seq>.convert.sh`` arguments, ``OMP_NUM_THREADS=2`` as its README says, N x N views) on
the frame converted once beforehand, not timed, to raw yuv420p 8-bit (ffmpeg: ``--ffmpeg``,
else the imageio-ffmpeg wheel's, else the PATH's); then ``plenocal convert FRAME XML -o
DIR --views N --mla KIND`` (PNG in, PNG out) and the same on TLCT's yuv file with
``--format yuv --size WxH --bit-depth 8`` (YUV in, YUV out), in the environment this
script was started in (not its one-thread settings) with this checkout first on
PYTHONPATH. Each run: the wall time (perf_counter around it) and the child's peak RSS
(``/usr/bin/time -f %M``; a process that forks the command otherwise: os.wait4 on a child
of this script itself would count this script's memory, which the child starts with).
Reported per frame: the median wall time of each, ours / TLCT's (target <= 1, aim 0.5),
the largest peak RSS of each (target: ours <= 1 GB on a 31-MP frame) and the central
view's size of each. Frames without a TLCT cfg (R42_klein_crop) get ours only.
"""

from __future__ import annotations

import os

#: the environment a user runs ``plenocal convert`` in (``--tlct``): before the one-thread
#: settings below, which are for the in-process measures
USER_ENV = dict(os.environ)
# run as a script only (bench/one_thread.py says why)
if __name__ == "__main__":
    from one_thread import pin

    pin()

import argparse  # noqa: E402
import re  # noqa: E402
import shutil  # noqa: E402
import statistics  # noqa: E402
import struct  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmd import (  # noqa: E402
    Lines,
    add_keep_history,
    binary_problem,
    positive_int,
    update_sections,
)

from plenocal.cli import command_line_block  # noqa: E402
from plenocal.convert import ConvertSettings, ShotConversion  # noqa: E402
from plenocal.convert.gridcheck import grid_for_mode, refine_grid  # noqa: E402
from plenocal.convert.localcheck import local_compare  # noqa: E402
from plenocal.convert.setup import centred_where_unverified, centring_shift  # noqa: E402
from plenocal.convert.shot import build_grid, load_calib, load_lenslet  # noqa: E402
from plenocal.io.files import read_image, write_image  # noqa: E402
from plenocal.malloc import no_huge_pages  # noqa: E402
from plenocal.names import central_view  # noqa: E402

REAL = ROOT.parent / "shared" / "real"
TLCT_CFG = REAL.parent / "tools" / "tlct" / "cfg"
# RayCalibData does not say which kind an MLA is; in the converter's naming (see the
# module docstring: the reverse of shared/real/README.md's, as the converter measures it)
MLA = {
    "Boys2": "keplerian",  # TSPC (Tsinghua)
    "HandTools": "keplerian",  # TSPC
    "Fujita2": "galilean",  # Raytrix
    "Origami": "galilean",  # Raytrix
    "Boxer-IrishMan-Gladiator2": "galilean",  # Raytrix
    "R42_klein_crop": "galilean",  # Raytrix R42
}
HEADING = "Real frames (bench_real.py)"
SPEED_HEADING = "Speed against TLCT (issue 35)"
LATER = "_f150"  # later frames of a sequence: <seq>_f150.png, read with <seq>.xml
#: our view, TLCT's view of the same position (shared/real/reference/<frame>/)
LOCAL_VIEWS = (("centre", "centre"), ("first corner", "v000"), ("last corner", "v024"))


def grid_cell(refined: bool, check) -> str:
    """The table's grid column: refined (the lattice fitted to the image), centred (the
    file's moved onto the centres the corner views agree on), or the file's."""
    if refined:
        return "yes"
    shift = centring_shift(check.centring)
    return "no" if shift is None else f"centred ({shift[0]:+.2f}, {shift[1]:+.2f})"


def sequence(name: str) -> str:
    """The sequence a frame belongs to (its xml and MLA kind)."""
    return name[: -len(LATER)] if name.endswith(LATER) else name


def local_views(n: int) -> dict[str, tuple[int, int]]:
    """Our view (r, c) for each entry of :data:`LOCAL_VIEWS`."""
    h = (n - 1) // 2
    return {"centre": (h, h), "first corner": (0, 0), "last corner": (n - 1, n - 1)}


def _fit_height(img: np.ndarray, h: int) -> np.ndarray:
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    w = max(1, int(round(img.shape[1] * h / img.shape[0])))
    interp = cv2.INTER_AREA if img.shape[0] > h else cv2.INTER_LINEAR
    return cv2.resize(np.ascontiguousarray(img[..., :3]), (w, h), interpolation=interp)


def side_by_side(panels: list[tuple[str, np.ndarray]], h: int) -> np.ndarray:
    gap = np.full((h, 8, 3), 255, np.uint8)
    parts = []
    for label, img in panels:
        p = _fit_height(img, h).copy()
        cv2.putText(p, label, (8, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (0, 0, 0), 3, cv2.LINE_AA)
        cv2.putText(p, label, (8, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (255, 255, 255), 1,
                    cv2.LINE_AA)
        parts += [p, gap]
    return np.concatenate(parts[:-1], axis=1)


def _to8(img: np.ndarray) -> np.ndarray:
    if img.dtype == np.uint16:
        top = max(int(img.max()), 1)
        return np.clip(img.astype(np.float32) * (255.0 / top), 0, 255).astype(np.uint8)
    return img


def tspc_corners(name: str, grid, check) -> tuple[float, float] | None:
    """Largest distance from the four corner micro-image centres that the TSPC tools
    measured (``<frame>_TSPC_corners_calib.xml``) to the nearest lens of the file's grid
    and of the fitted lattice (px), where the frame has such a file."""
    import defusedxml.ElementTree as ET  # noqa: PLC0415

    path = REAL / "frames" / f"{name}_TSPC_corners_calib.xml"
    if not path.is_file() or not check.fitted:
        return None
    root = ET.parse(path).getroot()
    pts = np.array([[float(root.find(f"centers/{k}/{a}").text) for a in "xy"]
                    for k in ("ltop", "rtop", "lbot", "rbot")])
    fitted = refine_grid(grid, check)
    return tuple(float(max(np.linalg.norm(g.centres - p, axis=1).min() for p in pts))
                 for g in (grid, fitted))


def _aspect(view: np.ndarray, frame: np.ndarray) -> float | None:
    """``view``'s x scale over its y scale against the lenslet frame it was made from
    (:func:`plenocal.convert.compare.sensor_aspect`); None where the two cannot be aligned."""
    from plenocal.convert.compare import sensor_aspect  # noqa: PLC0415

    try:
        return sensor_aspect(view, frame)[0]
    except ValueError:  # ConvertError: not aligned
        return None


def aspect_cell(aspect: dict) -> str:
    """The table's cell of the central views' aspects against the frame (ours / the
    reference's, x scale over y scale: 1 is the sensor's square pixels)."""
    return " / ".join("-" if aspect[k] is None else f"{aspect[k]:.3f}" for k in ("ours", "ref"))


def bench_frame(name: str, views: int, grid_mode: str, pictures: Path | None,
                compare, mla_mode: str = "table", grid_ab: bool = False) -> dict:
    lenslet = REAL / "frames" / f"{name}.png"
    calib = load_calib(REAL / "frames" / f"{sequence(name)}.xml")
    image = load_lenslet(lenslet)
    H, W = image.shape[:2]
    seq = sequence(name)
    cfg = command_line_block({"grid": grid_mode, **({"mla": MLA[seq]} if seq in MLA
                                                     and mla_mode == "table" else {})})
    settings = ConvertSettings.from_config(cfg)
    t0 = time.perf_counter()
    file_grid = build_grid(calib, W, H)
    grid, check = grid_for_mode(image, file_grid, grid_mode)
    t_check = time.perf_counter() - t0
    refined = check.refined
    corners = tspc_corners(sequence(name), file_grid, check)
    t1 = time.perf_counter()
    shot = ShotConversion(image, calib, views, settings, source=str(lenslet), grid=grid)
    # as the command line: an unverified grid moved onto the centres the corner views agree
    # on (plenocal.convert.centring), the frame measured again on it
    grid, shot, _ = centred_where_unverified(image, calib, views, settings, str(lenslet), grid,
                                             check, shot)
    t_prep = time.perf_counter() - t1
    t2 = time.perf_counter()
    centre_name = central_view(views)
    wanted = {f"{r}_{c}": key for key, (r, c) in local_views(views).items()}
    kept = {}
    for vname, img in shot.views():
        if vname in wanted:
            kept[wanted[vname]] = img
    centre = kept["centre"]
    t_views = time.perf_counter() - t2
    stats = shot.disparity()
    row = {
        "name": name, "size": f"{W}x{H}", "mp": W * H / 1e6, "mla": getattr(shot, "mla",
                                                                             cfg.get("mla")),
        "t_check": t_check, "t_prep": t_prep, "t_views": t_views,
        "t_total": t_check + t_prep + t_views, "view": (stats["width"], stats["height"]),
        "confident": stats["patch_size_px"]["confident_share"],
        "median_patch": stats["patch_size_px"]["median"], "check": check, "refined": refined,
        "cmp": None, "corners": corners, "local": {},
        "safe": shot.safe, "q": shot.layout.q,
        "filled": stats["patch_size_px"]["filled_share"], "cut": shot.border_cut,
    }
    for key, ref_name in LOCAL_VIEWS:
        ref_view = REAL / "reference" / name / f"{ref_name}.png"
        if not ref_view.is_file():
            continue
        try:
            row["local"][key] = local_compare(kept[key], read_image(ref_view),
                                              shot.layout.basis)
        except ValueError as exc:  # ConvertError: alignment failed
            row["local"][key] = {"error": str(exc)}
    ref_path = REAL / "reference" / name / "centre.png"
    ref = read_image(ref_path) if ref_path.is_file() else None
    if ref is not None and compare is not None:
        try:
            row["cmp"] = compare(centre, ref)
        except ValueError as exc:  # ConvertError: alignment failed
            row["cmp"] = {"error": str(exc)}
    # the central view's aspect against the frame itself (square pixels: 1), and the
    # reference's (plenocal.convert.compare.sensor_aspect)
    row["aspect"] = {"ours": _aspect(centre, image),
                     "ref": _aspect(ref, image) if ref is not None else None}
    if grid_ab and refined:
        # the same conversion on the file's grid, for what the refinement changed
        file_shot = ShotConversion(image, calib, views, settings, source=str(lenslet),
                                   grid=file_grid)
        r_c = tuple(int(v) for v in centre_name.split("_"))
        fstats = file_shot.disparity()
        row["file_grid"] = {"confident": fstats["patch_size_px"]["confident_share"],
                            "cmp": None}
        if ref is not None and compare is not None:
            try:
                row["file_grid"]["cmp"] = compare(file_shot.view(*r_c), ref)
            except ValueError as exc:
                row["file_grid"]["cmp"] = {"error": str(exc)}
    if pictures is not None:
        pictures.mkdir(parents=True, exist_ok=True)
        h = centre.shape[0]
        panels = [("raw frame", _to8(image)), ("ours (centre)", centre)]
        if ref is not None:
            panels.append(("reference (TLCT)", ref))
        panels.append(("patch size", shot.patch_picture()))
        write_image(pictures / f"{name}.png", side_by_side(panels, h))
        write_image(pictures / f"{name}_centre.png", centre)
        for key, (r, c) in local_views(views).items():
            if key != "centre":
                write_image(pictures / f"{name}_{r}_{c}.png", kept[key])
    return row


# --- speed against TLCT (--tlct, issue 35): whole processes, alternating -------------------

TIME = Path("/usr/bin/time")
#: where /usr/bin/time is missing: fork the command from a small process and report its
#: ru_maxrss (os.wait4 on a child of this script would count this script's own memory,
#: which a forked child starts with)
_LAUNCHER = ("import os, sys\npid = os.fork()\nif pid == 0:\n    os.execvp(sys.argv[2], "
             "sys.argv[2:])\n_, st, ru = os.wait4(pid, 0)\nopen(sys.argv[1], 'w').write("
             "str(ru.ru_maxrss))\nsys.exit(os.waitstatus_to_exitcode(st))\n")
VARIANTS = ("tlct", "png", "yuv")  # the order of the runs in a round


def png_size(path: Path) -> tuple[int, int]:
    """Width, height from a PNG's header."""
    with open(path, "rb") as f:
        return struct.unpack(">II", f.read(24)[16:24])


def ffmpeg_exe(given: str | None) -> str:
    if given:
        return given
    try:
        import imageio_ffmpeg  # noqa: PLC0415

        return imageio_ffmpeg.get_ffmpeg_exe()
    except ImportError:
        found = shutil.which("ffmpeg")
        if found is None:
            sys.exit("no ffmpeg: pip install imageio-ffmpeg, or give --ffmpeg")
        return found


def plenocal_cmd() -> list[str]:
    """``plenocal`` as installed beside this Python (not a version manager's shim)."""
    script = Path(sys.executable).parent / "plenocal"
    if script.is_file():
        return [str(script)]
    return [sys.executable, "-c", "import sys; from plenocal.cli import main; sys.exit(main())"]


def measure(cmd: list[str], env: dict, work: Path) -> tuple[float, int]:
    """Run ``cmd``: its wall time (s) and its peak RSS (bytes); output to work/log.txt."""
    rss_file = work / "rss.txt"
    rss_file.unlink(missing_ok=True)
    if TIME.is_file():
        wrapped = [str(TIME), "-f", "%M", "-o", str(rss_file), *cmd]
    else:
        wrapped = [sys.executable, "-I", "-S", "-c", _LAUNCHER, str(rss_file), *cmd]
    with open(work / "log.txt", "wb") as log:
        t0 = time.perf_counter()
        proc = subprocess.run(wrapped, env=env, stdout=log, stderr=subprocess.STDOUT)
        wall = time.perf_counter() - t0
    if proc.returncode != 0:
        tail = (work / "log.txt").read_text(errors="replace")[-2000:]
        raise RuntimeError(f"{' '.join(cmd)}: exit {proc.returncode}\n{tail}")
    kb = int(rss_file.read_text().split()[-1])
    return wall, kb * 1024


def speed_frame(name: str, tlct: str, rounds: int, views: int, ffmpeg: str, work: Path,
                mla_mode: str) -> dict:
    """R rounds of TLCT, ours PNG -> PNG, ours YUV -> YUV on one frame (see the docstring)."""
    seq = sequence(name)
    frame, xml = REAL / "frames" / f"{name}.png", REAL / "frames" / f"{seq}.xml"
    W, H = png_size(frame)
    cfg, cfg_args = TLCT_CFG / f"{seq}.calib.cfg", TLCT_CFG / f"{seq}.convert.sh"
    has_tlct = cfg.is_file()
    yuv = work / f"{name}_{W}x{H}_8bit.yuv"
    subprocess.run([ffmpeg, "-v", "error", "-y", "-i", str(frame), "-pix_fmt", "yuv420p",
                    "-f", "rawvideo", str(yuv)], check=True)  # not timed
    mla = ["--mla", MLA[seq]] if mla_mode == "table" and seq in MLA else []
    ours = [*plenocal_cmd(), "convert"]
    outs = {v: work / f"out_{v}" for v in VARIANTS}
    cmds = {
        "tlct": [tlct, str(cfg), "-i", str(yuv), "-o", str(outs["tlct"]), "--views",
                 str(views), "-b", "0", "-e", "1",
                 *(cfg_args.read_text().split() if cfg_args.is_file() else [])],
        "png": [*ours, str(frame), str(xml), "-o", str(outs["png"]), "--views", str(views),
                *mla],
        "yuv": [*ours, str(yuv), str(xml), "-o", str(outs["yuv"]), "--views", str(views),
                *mla, "--format", "yuv", "--size", f"{W}x{H}", "--bit-depth", "8"],
    }
    pypath = os.pathsep.join(p for p in (str(ROOT), USER_ENV.get("PYTHONPATH")) if p)
    envs = {"tlct": {**USER_ENV, "OMP_NUM_THREADS": "2"},
            "png": {**USER_ENV, "PYTHONPATH": pypath}, "yuv": {**USER_ENV, "PYTHONPATH": pypath}}
    runs = [v for v in VARIANTS if has_tlct or v != "tlct"]
    walls = {v: [] for v in runs}
    rss = {v: [] for v in runs}
    failed: dict[str, str] = {}  # a converter that stops on this frame: its last words
    for _ in range(rounds):
        for v in runs:
            if v in failed:
                continue
            shutil.rmtree(outs[v], ignore_errors=True)
            try:
                wall, peak = measure(cmds[v], envs[v], work)
            except RuntimeError as exc:
                lines = [x for x in str(exc).splitlines() if x.strip()]
                failed[v] = lines[-1][:300] if lines else "failed"
                print(f"{name} {v}: failed: {failed[v]}", file=sys.stderr)
                continue
            walls[v].append(wall)
            rss[v].append(peak)
    runs = [v for v in runs if v not in failed]
    # the central view's size, from the last round's files
    h = (views - 1) // 2
    sizes = {"png": png_size(outs["png"] / f"{h}_{h}.png")} if "png" in runs else {}
    pats = {"tlct": rf"v{h * views + h:03d}-(\d+)x(\d+)\.yuv", "yuv": rf"v_{h}_{h}_(\d+)x(\d+)_"}
    for v, pat in pats.items():
        if v in runs:
            found = [m for f in outs[v].iterdir() if (m := re.match(pat, f.name))]
            sizes[v] = tuple(int(x) for x in found[0].groups()) if found else None
    counts = {"tlct": len(list(outs["tlct"].glob("v*.yuv"))) if "tlct" in runs else None,
              "png": sum(bool(re.fullmatch(r"\d+_\d+\.png", f.name))
                         for f in outs["png"].iterdir()) if "png" in runs else None,
              "yuv": len(list(outs["yuv"].glob("v_*.yuv"))) if "yuv" in runs else None}
    for v in VARIANTS:
        shutil.rmtree(outs[v], ignore_errors=True)
    yuv.unlink()
    return {"name": name, "mp": W * H / 1e6, "mla": mla[1] if mla else "auto",
            "wall": {v: statistics.median(t) for v, t in walls.items() if t}, "walls": walls,
            "rss": {v: max(r) for v, r in rss.items() if r}, "size": sizes, "count": counts,
            "failed": failed}


def tlct_problem(path: Path) -> str | None:
    """Why ``path`` cannot be TLCT's binary (not a file, not executable), None where it
    can: checked before any frame, as a run per round reported it only as "failed" (and on
    a frame without a TLCT cfg not at all)."""
    what = binary_problem(path)
    return what and (f"{what}; give TLCT's binary (built by shared/tools/tlct/build.sh, its "
                     "README.md)")


def speed_main(args: argparse.Namespace, frames: list[str]) -> None:
    tlct = str(Path(args.tlct).resolve())
    ffmpeg = ffmpeg_exe(args.ffmpeg)
    # as speed_frame passes it: the table's kind (the MLA column) or none (--mla auto)
    mla = " --mla KIND" if args.mla == "table" else ""
    out = Lines()
    out.say(f"Whole processes alternating on one machine ({os.cpu_count()} cores, load average "
            f"{os.getloadavg()[0]:.1f} at the start; other jobs share the cores), {args.rounds} "
            f"round(s) per frame of: TLCT v1.6.0 (its cfg and convert.sh arguments from "
            f"shared/tools/tlct, OMP_NUM_THREADS=2, on the frame as raw yuv420p 8-bit made "
            f"beforehand), `plenocal convert FRAME XML -o DIR --views {args.views}{mla}` "
            f"(PNG in, PNG out), and the same on TLCT's yuv file with `--format yuv --size WxH "
            f"--bit-depth 8` (YUV in, YUV out), in the user's environment; {args.views} x "
            f"{args.views} views. Time: the median wall time of the process; memory: its peak "
            f"RSS (largest over the rounds; `/usr/bin/time -f %M`). View: the central view's "
            f"size.")
    out.say("Targets (issue 35): ours / TLCT <= 1.0 (aim 0.5); ours at most 1 GB peak on a "
            "31-MP frame.")
    out.say("")
    out.head("frame", "MP", "MLA", "TLCT s", "ours PNG s", "ours YUV s", "PNG / TLCT",
             "YUV / TLCT", "TLCT GB", "ours PNG GB", "ours YUV GB", "view TLCT",
             "view ours PNG / YUV")
    rows = []
    for name in frames:
        with tempfile.TemporaryDirectory(prefix=f"bench_tlct_{name}_") as tmp:
            r = speed_frame(name, tlct, args.rounds, args.views, ffmpeg, Path(tmp), args.mla)
        rows.append(r)
        w, m, sz = r["wall"], r["rss"], r["size"]

        def dims(v: str, sz: dict = sz) -> str:
            return "x".join(map(str, sz[v])) if sz.get(v) else "-"

        def sec(v: str, w: dict = w, r: dict = r) -> str:
            return f"{w[v]:.2f}" if v in w else ("failed" if v in r["failed"] else "-")

        def ratio(v: str, w: dict = w) -> str:
            return f"{w[v] / w['tlct']:.2f}" if v in w and "tlct" in w else "-"

        def gb(v: str, m: dict = m) -> str:
            return f"{m[v] / 1e9:.2f}" if v in m else "-"

        out.say(f"| {name} | {r['mp']:.1f} | {r['mla']} | {sec('tlct')} | {sec('png')} | "
                f"{sec('yuv')} | {ratio('png')} | {ratio('yuv')} | {gb('tlct')} | {gb('png')} "
                f"| {gb('yuv')} | {dims('tlct')} | {dims('png')} / {dims('yuv')} |")
        for v, why in r["failed"].items():
            out.say(f"(!) {name}: {v} stopped: {why}")
        n2 = args.views ** 2
        short = {v: c for v, c in r["count"].items() if c is not None and c != n2}
        if short:
            out.say(f"(!) {name}: views written {short}, not {n2}")
    def median_ratio(v: str) -> str:
        rs = [r["wall"][v] / r["wall"]["tlct"] for r in rows if {v, "tlct"} <= set(r["wall"])]
        return f"{statistics.median(rs):.2f} (worst {max(rs):.2f})" if rs else "-"

    if any("tlct" in r["wall"] for r in rows):
        out.say("")
        out.say(f"Median over the frames of ours / TLCT: PNG {median_ratio('png')}, YUV "
                f"{median_ratio('yuv')}; load average {os.getloadavg()[0]:.1f} at the end.")
    if args.out:
        update_sections(args.out, {SPEED_HEADING: list(out)}, keep_history=args.keep_history)


def pictures_text(pictures: Path | None) -> str:
    """The header's words for where the pictures went (``--pictures``)."""
    if pictures is None:
        return "none (--pictures '')"
    shown = pictures.resolve()
    shown = shown.relative_to(ROOT) if shown.is_relative_to(ROOT) else pictures
    return (f"{shown}/<frame>.png (raw | ours | reference | patch sizes) and "
            "<frame>_centre.png")


def real_frames(wanted: list[str] | None) -> list[str]:
    """The frames of ``shared/real/frames`` to measure (all if ``wanted`` is None or empty).

    Stops with the path and the remedy where the folder is missing or holds no frame, or a
    wanted frame is not there: an empty table must not pass for a measured one.
    """
    folder = REAL / "frames"
    frames = sorted(p.stem for p in folder.glob("*.png"))
    if not frames:
        raise SystemExit(f"no lenslet frames (*.png) in {folder}: the benchmark reads the "
                         f"shared folder beside the repository ({ROOT.parent / 'shared'}); "
                         f"run it from a checkout that has ../shared/real, or link it there")
    missing = sorted(set(wanted or ()) - set(frames))
    if missing:
        raise SystemExit(f"--frames {' '.join(missing)}: not in {folder} (there: "
                         f"{', '.join(frames)})")
    return [f for f in frames if f in wanted] if wanted else frames


def main() -> None:
    no_huge_pages()  # as the command line: its timings are those a user sees
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=None, help="also write the figures into this BENCHMARKS.md")
    add_keep_history(ap)
    ap.add_argument("--frames", nargs="*", default=None, help="frame names (default: all)")
    ap.add_argument("--views", type=int, default=5)
    ap.add_argument("--grid", default="auto", choices=("file", "refine", "auto"))
    ap.add_argument("--grid-ab", action="store_true",
                    help="where the grid was refined, convert on the file's grid too and "
                         "report both (not timed)")
    ap.add_argument("--mla", default="table", choices=("table", "auto"),
                    help="MLA kind from the table in this script, or read by the converter")
    ap.add_argument("--pictures", default=str(Path(__file__).resolve().parent / "out"),
                    help="folder for the side-by-side pictures ('' for none)")
    ap.add_argument("--tlct", default=None, metavar="PATH",
                    help="TLCT's binary: measure speed and peak memory against it instead "
                         "(whole processes, see the docstring)")
    ap.add_argument("--rounds", type=positive_int, default=3,
                    help="rounds per frame under --tlct")
    ap.add_argument("--ffmpeg", default=None,
                    help="ffmpeg for the yuv input under --tlct (default: imageio-ffmpeg's)")
    args = ap.parse_args()
    if args.tlct is not None:
        problem = tlct_problem(Path(args.tlct))
        if problem:
            ap.error(f"--tlct {args.tlct}: {problem}")
    cv2.setNumThreads(1)
    try:
        from plenocal.convert.compare import compare_to_reference as compare  # noqa: PLC0415
    except ImportError:
        compare = None
    frames = real_frames(args.frames)
    if args.tlct:
        speed_main(args, frames)
        return
    pictures = Path(args.pictures) if args.pictures else None
    out = Lines()
    kinds = ("the table in bench/bench_real.py (converter naming)" if args.mla == "table"
             else "read by the converter")
    out.say(f"{args.views} x {args.views} views per frame, one thread, `convert.grid: "
            f"{args.grid}`, the schema's convert defaults otherwise (as `plenocal convert`); "
            f"MLA kind: {kinds}. Times without PNG encoding: grid check, preparation (patch "
            "sizes, layout, plan; on a grid the check cannot confirm, the corner views' "
            "centring and the frame measured again), all views.")
    load0 = os.getloadavg()[0]
    out.say(f"Machine: {os.cpu_count()} cores, load average {load0:.1f} at the start (other "
            "jobs share the cores: times above ~1 per core are inflated accordingly).")
    out.say("Targets (issue 12): at most 3 s per 4 MP for all views on one core; central view "
            "at least the reference's size, SSIM >= 0.85 and sharpness >= 0.8 against it "
            f"(plenocal.convert.compare). Pictures: {pictures_text(pictures)}. Aspect: the "
            "central view's x scale over its y scale against the frame, both blurred until "
            "no micro image is left (plenocal.convert.compare.sensor_aspect): 1 for the "
            "sensor's square pixels.")
    if compare is None:
        out.say("(plenocal.convert.compare not present: no comparison with the reference)")
    out.say("")
    out.head("frame", "size", "MLA", "check s", "prepare s", "views s", "total s", "s / 4 MP",
             "view", "ref. view", "confident", "grid drift max / rms px",
             "grid refined / centred", "SSIM", "sharpness", "aspect ours / ref.")
    rows = []
    for name in frames:
        r = bench_frame(name, args.views, args.grid, pictures, compare, args.mla, args.grid_ab)
        rows.append(r)
        ck, cmp = r["check"], r["cmp"] or {}
        ref_size = "x".join(str(v) for v in cmp["reference_size"]) if "reference_size" in cmp \
            else "-"
        ssim = f"{cmp['ssim']:.3f}" if "ssim" in cmp else ("failed" if "error" in cmp else "-")
        sharp = f"{cmp['sharpness_ratio']:.2f}" if "sharpness_ratio" in cmp else "-"
        drift = (f"{ck.drift_max_px:.2f} / {ck.drift_rms_px:.2f}"
                 + (" (foreign)" if ck.foreign else "")
                 + ("" if ck.verified else " (unverified)"))
        out.say(f"| {name} | {r['size']} | {r['mla']} | {r['t_check']:.2f} | {r['t_prep']:.2f} "
                f"| {r['t_views']:.2f} | {r['t_total']:.2f} | {r['t_total'] * 4 / r['mp']:.2f} "
                f"| {r['view'][0]}x{r['view'][1]} | {ref_size} | {100 * r['confident']:.0f}% "
                f"| {drift} | {grid_cell(r['refined'], ck)} | {ssim} | {sharp} "
                f"| {aspect_cell(r['aspect'])} |")
    out.say("")
    out.say("Grid check per frame (fitted lattice minus the file's grid at the lens nearest each "
            "corner and the centre, px; lenses measured; fitted pitch and rotation against "
            "the file's; the fit's residual; where the TSPC tools measured the four corner "
            "micro images: the largest distance from them to the file's grid and to the "
            "fitted lattice):")
    out.say("")
    out.say("| frame | measured | top left | top right | centre | bottom left | bottom right "
            "| pitch | rotation deg | residual px | TSPC corners: file / fit px |")
    out.say("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        ck = r["check"]
        if not ck.fitted:
            out.say(f"| {r['name']} | {100 * ck.measured_share:.0f}% | not fitted ||||||||")
            continue
        cells = " | ".join(
            f"({ck.regions[k]['fit_dx_px']:+.1f}, {ck.regions[k]['fit_dy_px']:+.1f})"
            for k in ("top_left", "top_right", "centre", "bottom_left", "bottom_right"))
        tspc = "-" if r["corners"] is None else "{:.1f} / {:.1f}".format(*r["corners"])
        out.say(f"| {r['name']} | {100 * ck.measured_share:.0f}% | {cells} | "
                f"x{ck.pitch_ratio:.5f} | {ck.rotation_deg:+.4f} | {ck.residual_rms_px:.2f} "
                f"| {tspc} |")
    out.say("")
    out.say("Local measures against TLCT's views of the same frame (issue 33; "
            "plenocal.convert.localcheck): the worst textured tile's SSIM (6 x 6 grid; "
            "target >= 0.85 for the centre) and the lattice trace, ours / TLCT's, dB "
            "(target: ours at most TLCT's); z: each trace's distance from the measure's floor "
            "on the same view (the trace at its lattice's frequencies turned by 10-50 deg, "
            "where no lattice is), in standard deviations of the floor over the turns: a "
            "view within about 2 of its floor shows no lattice the measure can see. D' the "
            "safe diameter the views were cut with "
            "(measured, or calib.xml's D - 2), q the view spacing; filled: the share of "
            "lenses whose patch size was filled, not measured; cut: the border lens rows the "
            "views leave out, their micro images cut by the main lens "
            "(plenocal.convert.bordercut).")
    out.say("")
    out.say("| frame | D' px (file) | q px | filled | cut | " + " | ".join(
        f"{k}: worst tile | {k}: lattice dB" for k, _ in LOCAL_VIEWS) + " |")
    out.say("|---|---|---|---|---|" + "---|---|" * len(LOCAL_VIEWS))
    for r in rows:
        cells = []
        for key, _ in LOCAL_VIEWS:
            lc = r["local"].get(key)
            if lc is None:
                cells += ["-", "-"]
            elif "error" in lc:
                cells += ["failed", "failed"]
            else:
                flag = "" if lc["lattice_db"] <= lc["ref_lattice_db"] else " (over)"
                cells += [f"{lc['worst_tile_ssim']:.3f}",
                          f"{lc['lattice_db']:.1f} / {lc['ref_lattice_db']:.1f}{flag}; "
                          f"z {lc['lattice_z']:+.1f} / {lc['ref_lattice_z']:+.1f}"]
        safe = r["safe"]
        cut = ", ".join(f"{b} {n}" for b, n in r["cut"].bands.items() if n) or "-"
        out.say(f"| {r['name']} | {safe.diameter_px:.1f} ({safe.file_px:.1f}) | {r['q']:.2f} "
                f"| {100 * r['filled']:.0f}% | {cut} | " + " | ".join(cells) + " |")
    ab = [r for r in rows if "file_grid" in r]
    if ab:
        out.say("")
        out.say("The refined grid against the file's (the same conversion otherwise; central "
                "view against the reference):")
        out.say("")
        out.say("| frame | grid drift max px | confident: file / refined | SSIM: file / "
                "refined | sharpness: file / refined |")
        out.say("|---|---|---|---|---|")
        for r in ab:
            f, c = r["file_grid"]["cmp"] or {}, r["cmp"] or {}

            def pair(key: str, fmt: str, a: dict = f, b: dict = c) -> str:
                if key in a and key in b:
                    return f"{a[key]:{fmt}} / {b[key]:{fmt}}"
                return "-"

            out.say(f"| {r['name']} | {r['check'].drift_max_px:.2f} | "
                    f"{100 * r['file_grid']['confident']:.0f}% / {100 * r['confident']:.0f}% "
                    f"| {pair('ssim', '.3f')} | {pair('sharpness_ratio', '.2f')} |")
    if args.out:
        update_sections(args.out, {HEADING: list(out)}, keep_history=args.keep_history)


if __name__ == "__main__":
    main()
