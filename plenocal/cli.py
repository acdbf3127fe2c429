"""``plenocal convert``: one lenslet image and its calib.xml into N x N subaperture views,
as RLC / TLCT users expect, writing what the workflow's rule ``convert`` writes.

    plenocal convert LENSLET CALIB.xml -o DIR [--views N] [--galilean | --mla KIND]
        [--tile-size auto|N] [--grid file|refine|auto] [--bit-depth auto|N] [--bayer CFA]
        [--set key=value ...] [--setup convert_setup.json]
    plenocal convert RECORDING.yuv CALIB.xml -o DIR [--size WxH] [--bit-depth N]
        [--frames A:B] [--format png|yuv] [--setup-frame K] [--temporal hold|off] ...

Options map onto the keys of the config's ``convert`` block (``mla``, ``tile_size``,
``grid``, ``bit_depth``, ``bayer``; ``--set`` reaches any other key, dotted for nested
blocks, e.g. ``--set patch_size.block_samples=9``); the block is checked against config.schema.yaml
and completed with its defaults (as the workflow's rule ``convert`` gets it; the
workflow's config.yaml fixes ``tile_size: 6`` for its synthetic ground truth, the command
line keeps the schema's ``auto``) and goes through :meth:`ConvertSettings.from_config`.
One default differs from the workflow's: the command line prefilters the frame
(``blend.prefilter`` 0.1, :data:`CLI_CONVERT_DEFAULTS`; ``--set blend.prefilter=0`` gives
the workflow's views to the bit).
Progress goes to stderr; errors (a missing file, a malformed calib.xml, a bad option or
key, a full disk) print one line naming the file or key and exit with status 2. A stop
(Ctrl-C, or SIGTERM from ``kill`` or a cluster) prints one line and exits with status 130;
either way the output folder is left as it was (:func:`plenocal.io.files.staged_outputs`).
"""

from __future__ import annotations

import argparse
import dataclasses
import errno
import logging
import os
import signal
import sys
import tempfile
import threading
import time
from collections.abc import Mapping
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import yaml

from plenocal.config import deep_update, stage_defaults
from plenocal.convert.demosaic import BAYER_PATTERNS
from plenocal.convert.errors import ConvertError
from plenocal.convert.outfolder import check_output_folder, still_claims
from plenocal.convert.prefilter import OPTIMAL_A
from plenocal.convert.video import TEMPORAL_MODES
from plenocal.io.png import VIEW_BITS_CHOICES, view_dtype
from plenocal.io.yuv import (
    DEFAULT_MATRIX,
    DEFAULT_RANGE,
    MATRICES,
    RANGES,
    YuvError,
    resolve_format,
)
from plenocal.versions import version_text

EXIT_USAGE = 2
EXIT_INTERRUPTED = 130  # a shell's status for a process stopped by Ctrl-C (128 + SIGINT)
#: the most views a side: 99 x 99 views; each is a viewpoint within one micro image's
#: safe diameter, tens of pixels wide on every camera measured, so more gives only copies
MAX_VIEWS = 99
#: convert keys a set-up (--setup) decides for every frame: given with it, refused
SETUP_KEYS = ("mla", "tile_size", "grid", "safe_diameter", "upsample", "border_cut")

CONVERT_HELP = """\
Convert one lenslet image into its N x N subaperture views (the RLC of the paper,
Fig. 1 (a)). DIR receives what the workflow's conversion stage writes for a shot (the frame
prefiltered against bilinear sampling's blur, blend.prefilter 0.1, where the workflow's
views for the calibration are not; --set blend.prefilter=0 gives those):

  <r>_<c>.png        view (r, c) for r, c = 0..N-1 (uint8 RGB); r grows as the viewpoint
                     moves down, c as it moves right
  patch_size.npy     patch size (px) of every lens used by the views
  patch_size.png     the patch-size map with a colour bar (dark: filled from neighbours)
  disparity.json     the disparity range between adjacent views (paper's Eq. 1 sign),
                     the view geometry, patch-size statistics and the grid check

A raw YUV 4:2:0 recording (LENSLET ending in .yuv: planar I420, 8 bit, or 9-16 bit as
little-endian 16-bit words; size and bit depth from an MPEG-style name such as
Boys2_3976x2956_30fps_10bit.yuv or clip_1920x1080_yuv420p10le.yuv, or from --size and
--bit-depth) is converted frame by frame with one set-up (grid, MLA kind, tile and view
size, safe diameter: decided on --setup-frame, or read from --setup). DIR receives:

  --format png       frame_<k>/<r>_<c>.png and frame_<k>/disparity.json per frame (k:
                     the frame's index in the file, 5 digits)
  --format yuv       v_<r>_<c>_<W>x<H>_<b>bit_<pix_fmt>.yuv: one YUV 4:2:0 video per
                     view, of the input's bit depth (the byte layout RVS and TMIV read)
  convert_setup.json the set-up every frame was converted with (the workflow's format)
  video.json         input format, colour, per-frame patch-size statistics and times
"""


def _value(text: str):
    """A --set value as YAML reads it (numbers, booleans, lists), else the string."""
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError:
        return text


def _set_key(cfg: dict, dotted: str, value) -> None:
    keys = dotted.split(".")
    node = cfg
    for k in keys[:-1]:
        child = node.get(k)
        if not isinstance(child, dict):
            child = node[k] = {}
        node = child
    node[keys[-1]] = value


def _auto_or_int(parser: argparse.ArgumentParser, flag: str, help_text: str, lo: int,
                 hi: int | None = None) -> None:
    """An option that takes ``auto`` or a whole number in ``lo..hi``, left to the
    converter's default when not given."""
    parser.add_argument(flag, type=_int_or_auto(lo, hi), default=None, metavar="auto|N",
                        help=help_text + ". Default: the converter's default")


def _int_or_auto(lo: int, hi: int | None):
    """The argparse type of ``auto`` or a whole number in ``lo..hi`` (argparse names the
    option in its message)."""
    def parse(text: str) -> str | int:
        if text == "auto":
            return "auto"
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"'auto' or a whole number, not {text!r}"
                                             ) from None
        if v < lo or (hi is not None and v > hi):
            span = f">= {lo}" if hi is None else f"{lo}..{hi}"
            raise argparse.ArgumentTypeError(f"'auto' or a whole number {span} (got {v})")
        return v
    return parse


class _VersionAction(argparse.Action):
    """``--version``: :func:`version_text` on one line (argparse's own action wraps it to
    the terminal), read only when asked for."""

    def __init__(self, option_strings, dest, help=None):  # noqa: A002  (argparse's name)
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        print(version_text())
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="plenocal",
        description="Calibration of plenoptic 2.0 camera arrays. The workflow runs through "
                    "snakemake; this command converts single lenslet images.")
    ap.add_argument("--version", action=_VersionAction,
                    help="plenocal's version and those of the libraries that decide its "
                         "outputs' bytes, then exit")
    sub = ap.add_subparsers(dest="command", required=True, metavar="COMMAND")
    c = sub.add_parser("convert", help="lenslet image + calib.xml -> N x N views",
                       description=CONVERT_HELP,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    c.add_argument("lenslet", metavar="LENSLET",
                   help="the lenslet (raw plenoptic) image: 8- or 16-bit grey or RGB PNG (or "
                        "a raw Bayer mosaic with --bayer), the full sensor readout the "
                        "calib.xml belongs to; or a raw YUV 4:2:0 recording (.yuv, below)")
    c.add_argument("calib", metavar="CALIB.xml",
                   help="the camera's RayCalibData file (Raytrix calib.xml: micro-image "
                        "diameter, grid offset and rotation, lens types)")
    c.add_argument("-o", "--out", required=True, metavar="DIR",
                   help="output folder (created; files in it with the same names are "
                        "replaced when the run succeeds: the outputs are made in a hidden "
                        "folder inside it and moved into place at the end, so a run that "
                        "fails or is stopped leaves the folder as it was; a folder holding "
                        "an earlier conversion's files that this one would not replace, "
                        "e.g. the views of another --views, is refused before the work)")
    c.add_argument("--views", type=int, default=stage_defaults("dataset")["views"], metavar="N",
                   help="N x N views (default %(default)s, a dataset's in config.schema.yaml, "
                        f"as TLCT); N odd (the centre is a view), 1..{MAX_VIEWS}")
    kind = c.add_mutually_exclusive_group()
    kind.add_argument("--galilean", action="store_const", const="galilean", dest="mla",
                      help="the MLA is Galilean (micro images upright: a point moves away "
                           "from the neighbouring lens); same as --mla galilean")
    kind.add_argument("--mla", choices=("auto", "keplerian", "galilean"), default=None,
                      help="MLA kind (convert.mla): keplerian (micro images inverted: a point "
                           "moves towards the neighbouring lens), galilean (upright), or auto "
                           "(read from the image by matching both ways; the default, and the "
                           "choice unless the frame has no texture; the README's 'MLA kinds' "
                           "says what it finds on real cameras)")
    _auto_or_int(c, "--tile-size",
                 "output pixels per micro-image pitch (convert.tile_size): auto (from the "
                 "patch sizes: the views' natural resolution) or a number >= 2", lo=2)
    c.add_argument("--grid", choices=("file", "refine", "auto"), default=None,
                   help="microlens grid (convert.grid): file (calib.xml as it is), refine "
                        "(fit the lattice to the micro-image centres in the image), auto "
                        "(refine when the file's grid drifts more than 1 px from the micro "
                        "images, see plenocal.convert.gridcheck; where the check cannot "
                        "measure them, move the file's lattice onto the centres the corner "
                        "views agree on, plenocal.convert.centring). The check always runs and "
                        "lands in disparity.json. Default: auto")
    c.add_argument("--bayer", choices=BAYER_PATTERNS, default=None, metavar="PATTERN",
                   help="the frame is a sensor's raw one-channel readout behind this colour "
                        "filter array, its top-left 2 x 2 block row by row: "
                        f"{', '.join(BAYER_PATTERNS)} (convert.bayer); it is demosaiced "
                        "first. Default: none (a grey frame that looks like a mosaic is "
                        "warned of)")
    _auto_or_int(c, "--bit-depth",
                 "significant bits of a 16-bit image (convert.bit_depth): auto (10, 12 or "
                 "14 bits recognised from the maximum) or 8..16", lo=8, hi=16)
    c.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="any other key of the config's convert block (config.schema.yaml), "
                        "dotted for nested ones (e.g. --set upsample=1.5 --set "
                        "patch_size.block_samples=9); values are read as YAML; repeatable")
    c.add_argument("--setup", metavar="convert_setup.json", default=None,
                   help="convert with these per-camera decisions (grid, MLA kind, tile, safe "
                        "diameter and view spacing) instead of deciding them on the frame: "
                        "the workflow's results/<dataset>/views/convert_setup.json, or one "
                        "this command wrote for a recording; PNG and YUV input")
    v = c.add_argument_group("raw YUV 4:2:0 input (LENSLET ending in .yuv)")
    v.add_argument("--size", type=frame_size, default=None, metavar="WxH",
                   help="frame size, where the file name does not state it (e.g. 3976x2956)")
    v.add_argument("--frames", default=None, metavar="A:B",
                   help="the frames to convert, a Python slice of the file's frames: A:B is A "
                        "up to B with B excluded (0:10 = the first ten), A:, :B, A:B:STEP, "
                        "negatives count from the end; a single number is that frame; a "
                        "bound past the file is refused, not clamped. Default: all")
    v.add_argument("--format", choices=("png", "yuv"), default="png", dest="out_format",
                   help="png (default): a folder of PNG views per frame; yuv: one YUV 4:2:0 "
                        "video per view, of the input's bit depth")
    v.add_argument("--setup-frame", type=int, default=None, metavar="K",
                   help="the frame (index in the file) the set-up is decided on. Default: "
                        "the first converted frame")
    # these three default to None so that one given with a PNG is refused, not ignored
    v.add_argument("--yuv-matrix", choices=tuple(MATRICES), default=None,
                   help=f"YCbCr colour matrix of the input and the output (default "
                        f"{DEFAULT_MATRIX}, MPEG's usual for these sequences)")
    v.add_argument("--yuv-range", choices=RANGES, default=None,
                   help=f"YCbCr range: limited (16-235 luma at 8 bit) or full (default "
                        f"{DEFAULT_RANGE})")
    v.add_argument("--temporal", choices=TEMPORAL_MODES, default=None,
                   help="hold (default): a lens keeps the previous frame's patch size where "
                        "it still matches nearly as well (no flicker on static scenes); "
                        "off: every frame converted alone, as its PNG")
    c.add_argument("--png-bits", type=int, choices=VIEW_BITS_CHOICES, default=None,
                   metavar="8|16",
                   help="bits per sample of the PNG views: 8 (default; what every image tool "
                        "reads) or 16, which keeps the levels of a frame of more than 8 bits "
                        "(a 10-, 12- or 16-bit PNG or recording) and the blend's fractions "
                        "of a level; not with --format yuv, whose videos are of the input's "
                        "bit depth")
    c.add_argument("--threads", type=_threads, default=None, metavar="N",
                   help="threads that render and write the views (the same bytes with any "
                        "number). Default: the cores this process may use")
    c.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")
    return ap


def _threads(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"a whole number >= 1, not {text!r}")
    return n


def default_threads() -> int:
    """The cores this process may use (its CPU affinity, e.g. a cluster job's share)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def frame_size(text: str) -> tuple[int, int]:
    """An ``argparse`` type: ``WxH`` (e.g. 3976x2956) as (width, height), each at least 2."""
    w, sep, h = text.lower().partition("x")
    try:
        size = int(w), int(h)
    except ValueError:
        size = (0, 0)
    if not sep or min(size) < 2:
        raise argparse.ArgumentTypeError(f"WIDTHxHEIGHT, e.g. 3976x2956, not {text!r}")
    return size


#: what ``plenocal convert`` sets over the config's ``convert`` defaults: the frame
#: prefiltered against bilinear sampling's blur (``blend.prefilter``,
#: :data:`plenocal.convert.prefilter.OPTIMAL_A`). Its views are for people, view synthesis,
#: TMIV and NeRF; the workflow's feed the calibration's SIFT, which leaned the focal length
#: on prefiltered views (+0.027 % on average over twenty simulated captures), so the
#: config's default stays 0. The filter moves no view's geometry (an affine fit of a
#: prefiltered view onto a plain one: scale within 0.0014 %, centre within 0.007 px), so a
#: calibration made from the workflow's views holds for these. ``--set
#: blend.prefilter=0`` gives the workflow's views, to the bit (BENCHMARKS.md, "The command
#: line's views prefiltered, the workflow's not").
CLI_CONVERT_DEFAULTS = {"blend": {"prefilter": OPTIMAL_A}}


def convert_config(args: argparse.Namespace) -> dict:
    """The convert block the options describe: :data:`CLI_CONVERT_DEFAULTS`, then
    ``--set``, then the named options (each later one wins)."""
    cfg = deep_update(CLI_CONVERT_DEFAULTS, {})
    for item in args.set:
        key, sep, val = item.partition("=")
        if not sep or not key.strip():
            raise ConvertError(f"--set {item!r}: expected KEY=VALUE")
        _set_key(cfg, key.strip(), _value(val))
    if args.mla is not None:
        cfg["mla"] = args.mla
    if args.tile_size is not None:
        cfg["tile_size"] = args.tile_size
    if args.bit_depth is not None:
        cfg["bit_depth"] = args.bit_depth
    if args.bayer is not None:
        cfg["bayer"] = args.bayer
    if args.grid is not None:
        cfg["grid"] = args.grid
    return cfg


def command_line_block(block: Mapping | None = None) -> dict:
    """The convert block ``plenocal convert`` converts with for the keys ``block`` sets
    (nested blocks as dicts): :data:`CLI_CONVERT_DEFAULTS` under them, checked and completed
    as :func:`validate_convert_block` does (what bench/bench_real.py measures)."""
    return validate_convert_block(deep_update(CLI_CONVERT_DEFAULTS, block or {}))


def validate_convert_block(block: dict) -> dict:
    """A ``convert`` block checked against config.schema.yaml and completed with its
    defaults, as the workflow's rule ``convert`` gets it. Unknown keys and bad values
    raise ConfigError naming the key (:func:`plenocal.config.with_defaults` fills a block
    without checking it)."""
    from plenocal.config import validate_config  # noqa: PLC0415

    return validate_config({"datasets": {"cli": {}}, "convert": dict(block)})["convert"]


def run_convert(args: argparse.Namespace, log: logging.Logger) -> None:
    import cv2  # noqa: F401, PLC0415  (cv2 before anything that may import pycolmap)

    from plenocal.convert import ConvertSettings, convert_files  # noqa: PLC0415

    t0 = time.perf_counter()
    if args.views < 1 or args.views % 2 == 0 or args.views > MAX_VIEWS:
        raise ConvertError(f"--views: an odd number 1..{MAX_VIEWS}, so that the central view "
                           f"is one of them (got {args.views})")
    if not str(args.out).strip():
        raise ConvertError("-o: an empty path; name the output folder (an unset variable?)")
    if args.setup is not None:
        _refuse_setup_overrides(args)
    block = validate_convert_block(convert_config(args))
    settings = ConvertSettings.from_config(block)
    for path, what in ((args.lenslet, "lenslet image"), (args.calib, "calib.xml"),
                       (args.setup, "convert_setup.json")):
        if path is not None and Path(path).is_dir():
            raise ConvertError(f"{path}: a folder, where the {what} file is asked for (one "
                               "file a command: convert a folder's frames one by one)")
        if path is not None and not Path(path).exists():
            raise ConvertError(f"{path}: {what} not found")
        if path is not None and not Path(path).is_file():
            raise ConvertError(f"{path}: not a regular file (a device or a pipe), where the "
                               f"{what} file is asked for: save it to a file and name that")
    if args.setup is not None:
        _refuse_other_views(args)
    if args.png_bits is not None and args.out_format != "png":
        raise ConvertError(f"--png-bits {args.png_bits} with --format {args.out_format}: the "
                           "PNG views' bits; the YUV videos are of the input's bit depth")
    video = Path(args.lenslet).suffix.lower() == ".yuv"
    if args.out_format == "yuv" and not settings.even_size:
        raise ConvertError("--format yuv with convert.even_size false: YUV 4:2:0 videos need "
                           "views of even width and height (the codecs, TMIV and RVS read "
                           "no other); leave even_size as it is, or write PNGs")
    if not video:
        given = [flag for flag, value in (("--size", args.size), ("--frames", args.frames),
                                          ("--setup-frame", args.setup_frame),
                                          ("--yuv-matrix", args.yuv_matrix),
                                          ("--yuv-range", args.yuv_range),
                                          ("--temporal", args.temporal))
                 if value is not None] + (["--format yuv"] if args.out_format == "yuv" else [])
        if given:
            raise ConvertError(f"{' and '.join(given)}: for a raw YUV recording (LENSLET "
                               f"ending in .yuv); {args.lenslet} is one image")
    elif settings.bayer != "none":
        raise ConvertError(f"convert.bayer {settings.bayer}: for a raw one-channel PNG frame; "
                           f"{args.lenslet} is a YUV recording, in colour already")
    out = Path(args.out)
    made = not out.exists()
    try:  # before the work: a folder that cannot be made fails now, not after the analysis
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConvertError(f"{out}: cannot make the output folder ({exc.strerror or exc})"
                           ) from None
    try:  # nor one this user cannot write to
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as exc:
        raise ConvertError(f"{out}: cannot write to the output folder ({exc.strerror or exc}):"
                           " choose another with -o") from None
    if not video:  # a recording's frames are known once the file is (convert_recording)
        claims = still_claims(args.views)
        for path in (args.lenslet, args.calib, args.setup):
            if (path is not None and Path(path).resolve().parent == out.resolve()
                    and claims(Path(path).name)):
                raise ConvertError(f"{path}: an input where the conversion writes one of its "
                                   f"outputs ({Path(path).name}): it would be replaced. Move "
                                   "it, or choose another folder with -o")
        check_output_folder(out, claims, f"{args.views} x {args.views} views of one image")
    try:
        if video:
            run_convert_video(args, settings, block, log)
            return
        threads = args.threads or default_threads()
        shot = convert_files(args.lenslet, args.calib, None, args.views, settings,
                             setup_json=args.setup, threads=threads,
                             grid_foreign=block["grid_foreign"])
        _write_conversion(args, shot, out, threads, settings, log, t0)
    except BaseException:
        if made and not any(out.iterdir()):
            out.rmdir()  # an input the conversion refused leaves no empty folder behind
        raise


def _refuse_other_views(args: argparse.Namespace) -> None:
    """ConvertError where ``--views`` is not the N the ``--setup`` was decided for
    (:func:`plenocal.convert.setup.views_decided`): its views would be other cameras than
    the calibration's, under the same names."""
    from plenocal.convert.setup import read_setup, views_decided  # noqa: PLC0415

    n = views_decided(read_setup(args.setup))
    if n is not None and n != args.views:
        raise ConvertError(f"--views {args.views} with --setup {args.setup}: the set-up was "
                           f"decided for {n} x {n} views (its view spacing is D' sin 45 deg / "
                           f"{n}), and views of another number are other cameras than the "
                           f"calibration's; give --views {n}, or leave --setup out")


def _refuse_setup_overrides(args: argparse.Namespace) -> None:
    """ConvertError where an option sets what ``--setup`` decides (:data:`SETUP_KEYS`): the
    set-up would win without a word."""
    given = [flag for flag, value in (("--mla", args.mla), ("--tile-size", args.tile_size),
                                      ("--grid", args.grid)) if value is not None]
    given += [f"--set {item}" for item in args.set
              if item.partition("=")[0].strip().split(".")[0] in SETUP_KEYS]
    if given:
        raise ConvertError(f"{' and '.join(given)} with --setup {args.setup}: the set-up "
                           f"decides {', '.join(SETUP_KEYS)} for every frame; leave "
                           f"{'them' if len(given) > 1 else 'it'} out, or leave --setup out to "
                           "decide on this frame")


def _write_conversion(args: argparse.Namespace, shot, out: Path, threads: int, settings,
                      log: logging.Logger, t0: float) -> None:
    """The views, patch sizes and disparity.json of one converted image, made in a staging
    folder and moved into ``out`` at the end, disparity.json last
    (:func:`plenocal.io.files.staged_outputs`): a rerun that fails leaves the previous
    run's files as they were, not half of them replaced."""
    from plenocal.convert.setup import grid_words  # noqa: PLC0415
    from plenocal.convert.threads import Inline  # noqa: PLC0415
    from plenocal.io.files import (  # noqa: PLC0415
        staged_outputs,
        write_image,
        write_images,
        write_json,
        write_npy,
    )

    log.info("%s: %dx%d, %s: D = %.2f px; grid: %s (convert.grid %s)", args.lenslet,
             shot.grid.width, shot.grid.height, args.calib, shot.calib.diameter,
             grid_words(shot.grid_check), settings.grid)
    stats = shot.disparity()
    # the range disparity.json's D range is taken over first (the percentiles of the
    # matched lenses), then every lens's: a filled lens, or a lone matched one, may take a
    # size nothing around it measured (BENCHMARKS.md, "Filled lenses pulled out of the
    # confident range by the smoothing")
    p_lo, p_hi = stats["patch_size_px"]["range"]
    log.info("patch sizes %.2f..%.2f px (percentiles %g and %g of the matched lenses; "
             "%.2f..%.2f over all, median %.2f, %.0f%% matched); views %dx%d; %.2f s",
             p_lo, p_hi, *stats["percentiles"], stats["patch_size_px"]["min"],
             stats["patch_size_px"]["max"], stats["patch_size_px"]["median"],
             100 * stats["patch_size_px"]["confident_share"], stats["width"],
             stats["height"], time.perf_counter() - t0)
    if shot.border_cut.any:
        log.info("%s", shot.border_cut.summary())
    n = args.views * args.views
    with staged_outputs(out, last=("disparity.json",)) as stage:
        write_npy(stage / "patch_size.npy", shot.used_patch)
        t1, done = time.perf_counter(), 0
        # the patch-size picture beside the views where there are threads (their bands
        # leave the cores gaps: two threads render 1.5x as fast as one), before them on one
        side = ThreadPoolExecutor(max_workers=1) if threads > 1 else Inline()
        try:
            picture = side.submit(lambda: write_image(stage / "patch_size.png",
                                                      shot.patch_picture()))
            for views in shot.view_groups(threads=threads, dtype=view_dtype(args.png_bits)):
                write_images(((stage / f"{name}.png", img) for name, img in views.items()),
                             threads)
                done += len(views)
                views.clear()  # before the next group is rendered
                log.info("%d/%d views of %dx%d rendered and written on %d thread(s); %.2f s",
                         done, n, stats["width"], stats["height"], threads,
                         time.perf_counter() - t1)
            picture.result()
        finally:
            side.shutdown()
        write_json(stage / "disparity.json", stats)
    log.info("%s: %d views, disparity.json, patch_size.npy/.png; %.2f s in all", out, n,
             time.perf_counter() - t0)


def run_convert_video(args: argparse.Namespace, settings, block: dict,
                      log: logging.Logger) -> None:
    """A raw YUV recording (plenocal.convert.video.convert_recording)."""
    from plenocal.convert.setup import read_setup  # noqa: PLC0415
    from plenocal.convert.shot import load_calib  # noqa: PLC0415
    from plenocal.convert.video import VideoSettings, convert_recording  # noqa: PLC0415

    bits = args.bit_depth if isinstance(args.bit_depth, int) else None
    if bits is not None and not 8 <= bits <= 16:
        raise ConvertError(f"--bit-depth {bits}: a YUV file holds 8..16 bits")
    try:  # the recording's format first: the commonest mistake with raw video
        resolve_format(args.lenslet, args.size, bits)
    except YuvError as exc:
        raise ConvertError(str(exc)) from None
    t0 = time.perf_counter()
    doc = convert_recording(
        args.lenslet, load_calib(args.calib), args.out, args.views,
        dataclasses.replace(settings, bit_depth="auto"),
        VideoSettings(**{key: value for key, value in (
            ("matrix", args.yuv_matrix), ("range", args.yuv_range),
            ("temporal", args.temporal)) if value is not None}),
        size=args.size, bits=bits, frames=args.frames, out_format=args.out_format,
        png_bits=args.png_bits,
        setup_frame=args.setup_frame,
        setup=None if args.setup is None else read_setup(args.setup),
        grid_foreign=block["grid_foreign"], threads=args.threads or default_threads())
    v = doc["views"]
    log.info("%s: %d frames, %d views of %dx%d (%s); %.2f s in all", args.out,
             len(doc["frames"]), v["n"] ** 2, v["width"], v["height"], v["format"],
             time.perf_counter() - t0)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(stream=sys.stderr, level=logging.WARNING if args.quiet else logging.INFO,
                        format="plenocal: %(message)s", force=True)
    log = logging.getLogger("plenocal.cli")
    from plenocal.config import ConfigError  # noqa: PLC0415
    from plenocal.io.raytrix import CalibError  # noqa: PLC0415
    from plenocal.malloc import no_huge_pages  # noqa: PLC0415

    # numpy's arrays on ordinary pages: where the kernel compacts memory for the huge
    # pages numpy asks for, that took 15-30 % of a 12-MP frame's time (plenocal.malloc)
    no_huge_pages()

    # a stop by the cluster or `kill` runs the clean-up as Ctrl-C does: the staging
    # folder and a folder this run made are removed (plenocal.io.files.staged_outputs)
    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _terminated) if main_thread else None
    try:
        if args.command == "convert":
            run_convert(args, log)
    except KeyboardInterrupt:
        print(f"plenocal {args.command}: stopped; nothing of this run was kept in "
              f"{args.out}", file=sys.stderr)
        return EXIT_INTERRUPTED
    except (ConvertError, CalibError, ConfigError, YuvError, OSError) as exc:
        print(f"plenocal {args.command}: error: {_error_text(exc, args)}", file=sys.stderr)
        return EXIT_USAGE
    finally:
        if main_thread:
            signal.signal(signal.SIGTERM, previous)
    return 0


def _terminated(signum: int, frame) -> None:
    """SIGTERM as a KeyboardInterrupt: the same clean-up and message as Ctrl-C."""
    raise KeyboardInterrupt


def _error_text(exc: Exception, args: argparse.Namespace) -> str:
    """The one line an error prints: a full disk or quota names the output folder and the
    remedy, where the system's own words name nothing."""
    if isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT):
        where = exc.filename or args.out
        return (f"{where}: {exc.strerror} while writing the outputs; free space there or choose "
                f"another folder with -o (nothing of this run was kept in {args.out})")
    return str(exc)


if __name__ == "__main__":
    sys.exit(main())
