"""Lenslet video: a raw YUV 4:2:0 recording into N x N subaperture videos.

One recording is one camera, so the converter's per-camera decisions - the grid, the MLA
kind, the tile (and with it the one view size of the whole video), the safe diameter and
the view spacing - are made once (:func:`plenocal.convert.setup.decide_setup`, on the
first converted frame or the frame the user names, as rule ``convert_setup`` makes them on
an array's central shot), or taken from a workflow's ``convert_setup.json``. Every frame is
then converted as a shot of that camera (:class:`plenocal.convert.shot.ShotConversion`
with the set-up, as rule ``convert`` converts each shot).

Colour. The converter works in RGB: each frame's (Y, Cb, Cr) planes become RGB
(:func:`plenocal.io.yuv.yuv_to_rgb`, BT.709 limited range by default), held as integers
of the recording's depth (:func:`lenslet_frame`: 8-bit RGB for an 8-bit recording, as its
PNG would be; 16-bit for more bits, where a 10-bit frame loses nothing), and the views
(8-bit RGB, 16-bit for a deeper recording's videos) go back to YUV 4:2:0 of the input's
bit depth (:func:`plenocal.io.yuv.rgb_to_yuv`) or to 8-bit RGB PNGs. The views of a
frame are those that converting the same RGB frame as a PNG with the same set-up gives (to
the rounding of the output; the same 8-bit views for an 8-bit recording).

Temporal stability (:func:`hold_patch_sizes`, ``temporal: hold``, the default). Coding
noise moves each lens's best match from frame to frame on a static scene, and the patch
size with it: the tiles change scale and the view shimmers. A lens keeps its previous
frame's (matched) patch size where that size still matches within ``hold_margin`` (mean
ZNCC) of this frame's best; where the scene moved, the old size matches worse and the lens
takes the new one. The hold is a function of the frame and the previous frame's result:
deterministic, and two identical consecutive frames give identical views (the second
holds every size of the first). ``temporal: off`` converts every frame alone, as its PNG
would be. The README ("Lenslet video") gives the flicker measured with and without it.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import re
import time
from collections.abc import Iterator
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from plenocal.convert.analysis import ConvertAnalysis
from plenocal.convert.errors import ConvertError
from plenocal.convert.levels import significant_bits
from plenocal.convert.outfolder import check_output_folder, recording_claims, stale_view_videos
from plenocal.convert.patchsize import (
    PatchSizeResult,
    estimate_patch_size,
    fill_and_smooth,
    focus_weights,
)
from plenocal.convert.setup import ConverterSetup, decide_setup, write_setup
from plenocal.convert.shot import ConvertSettings, ShotConversion, frame_gray
from plenocal.convert.threads import map_threads
from plenocal.convert.vignetting import lens_type_profiles
from plenocal.grid import MicrolensGrid
from plenocal.io.files import dumps_json, staged_outputs, write_images, write_json
from plenocal.io.png import view_dtype
from plenocal.io.raytrix import RayCalib
from plenocal.io.yuv import (
    DEFAULT_MATRIX,
    DEFAULT_RANGE,
    MATRICES,
    RANGES,
    YuvError,
    YuvFormat,
    frame_count,
    integer_rgb_to_yuv,
    mpeg_name,
    read_frame,
    resolve_format,
    write_frame,
    yuv_to_rgb,
)
from plenocal.names import frame_folder, view_names
from plenocal.viewgeom import remembered_slots

log = logging.getLogger("plenocal.convert")

TEMPORAL_MODES = ("hold", "off")


@dataclass(frozen=True)
class VideoSettings:
    """How a YUV recording is read and converted (module docstring): ``matrix`` / ``range``
    of its YCbCr (:mod:`plenocal.io.yuv`), ``temporal`` ``hold`` | ``off``, and
    ``hold_margin``: how much better (mean ZNCC over the lens's neighbour pairs) this
    frame's best patch size must match than the previous frame's before a lens leaves the
    previous one."""

    matrix: str = DEFAULT_MATRIX
    range: str = DEFAULT_RANGE
    temporal: str = "hold"
    hold_margin: float = 0.05

    def __post_init__(self) -> None:
        if self.matrix not in MATRICES:
            raise ConvertError(f"YUV matrix {self.matrix!r}: one of {', '.join(MATRICES)}")
        if self.range not in RANGES:
            raise ConvertError(f"YUV range {self.range!r}: one of {', '.join(RANGES)}")
        if self.temporal not in TEMPORAL_MODES:
            raise ConvertError(f"temporal {self.temporal!r}: one of {', '.join(TEMPORAL_MODES)}")
        if not self.hold_margin >= 0:
            raise ConvertError(f"hold margin {self.hold_margin}: must be >= 0")


def lenslet_frame(planes: tuple[np.ndarray, np.ndarray, np.ndarray], bits: int,
                  matrix: str = DEFAULT_MATRIX, rng: str = DEFAULT_RANGE) -> np.ndarray:
    """One YUV frame as the RGB lenslet image the converter reads: an 8-bit frame as uint8
    RGB (each channel rounded once, as the frame's 8-bit PNG holds it: the views sample 8-bit
    frames 2-3x as fast as 16-bit ones, OpenCV's remap having a vector path for 8-bit data
    only), more bits as uint16 at full 16-bit scale (convert it with ``bit_depth: 16``,
    :func:`video_settings`). Written as a PNG it is the frame's PNG, whose conversion the
    video's matches."""
    H, W = planes[0].shape
    dtype, top = (np.uint8, 255.0) if bits <= 8 else (np.uint16, 65535.0)
    out = np.empty((H, W, 3), dtype)
    for a in range(0, H, FRAME_ROWS):  # in bands: a float frame is 6 bytes a pixel
        rows = slice(a, min(a + FRAME_ROWS, H))
        rgb = yuv_to_rgb(planes, bits, matrix, rng, rows=rows)
        out[rows] = np.rint(rgb * np.float32(top)).astype(dtype)
    return out


#: rows of a frame turned from YUV into RGB at a time (even: a 2 x 2 chroma block is never
#: cut)
FRAME_ROWS = 256


def view_to_yuv(view: np.ndarray, bits: int, matrix: str = DEFAULT_MATRIX,
                rng: str = DEFAULT_RANGE) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The (Y, Cb, Cr) planes of an 8- or 16-bit RGB view (:func:`plenocal.io.yuv.rgb_to_yuv`
    of view / 255 or / 65535): one compiled pass, without a float copy of the view (98 MB
    and as much again in temporaries for a view of a 31-MP frame;
    :func:`plenocal.io.yuv.integer_rgb_to_yuv`)."""
    return integer_rgb_to_yuv(view, bits, matrix, rng)


def video_settings(base: ConvertSettings) -> ConvertSettings:
    """``base`` for the frames of :func:`lenslet_frame` (16 significant bits where they are
    16-bit; an 8-bit frame is 8 bits whatever ``bit_depth`` says)."""
    return dataclasses.replace(base, bit_depth=16)


def _score_at(scores: np.ndarray, candidates: np.ndarray, size: np.ndarray) -> np.ndarray:
    """Each lens's score at its own ``size``, linear between the candidates (-inf outside
    the candidates or where a neighbouring candidate is not allowed)."""
    n, c = scores.shape
    pos = (size - candidates[0]) / (candidates[1] - candidates[0])
    ok = np.isfinite(pos) & (pos >= 0) & (pos <= c - 1)
    i0 = np.clip(np.floor(np.nan_to_num(pos)).astype(int), 0, c - 2)
    f = np.clip(np.nan_to_num(pos) - i0, 0.0, 1.0)
    rows = np.arange(n)
    a, b = scores[rows, i0], scores[rows, i0 + 1]
    with np.errstate(invalid="ignore"):
        out = np.where(f <= 0, a, np.where(f >= 1, b, (1 - f) * a + f * b))
    return np.where(ok & np.isfinite(out), out, -np.inf)


def hold_patch_sizes(current: PatchSizeResult, previous: PatchSizeResult | None,
                     grid: MicrolensGrid, settings: ConvertSettings, margin: float
                     ) -> tuple[PatchSizeResult, np.ndarray]:
    """``current`` with each lens's matched size replaced by ``previous``'s where that still
    matches within ``margin`` of the best (module docstring); the map is then filled and
    smoothed again as :func:`plenocal.convert.patchsize.estimate_patch_size` does (also
    without a previous frame, so that every frame's map is made by the same arithmetic).
    Returns the result and the (n,) mask of held lenses."""
    if current.scores is None or current.fallback is None:
        raise ConvertError("the patch-size result carries no scores: it was read from an "
                           "analysis file, not measured; the temporal hold needs them")
    st = settings.patch
    cand = current.candidates
    raw, conf = current.raw.astype(np.float32), current.confidence.astype(np.float32)
    held = np.zeros(len(raw), dtype=bool)
    if previous is not None:
        best = np.max(current.scores, axis=1)
        at_prev = _score_at(current.scores, cand, previous.raw)
        held = (np.isfinite(previous.raw) & np.isfinite(current.raw) & np.isfinite(at_prev)
                & (best - at_prev <= margin))
        raw = np.where(held, previous.raw, raw).astype(np.float32)
        # a held lens keeps the confidence it had (a lens hovering about min_confidence
        # would otherwise switch between its size and a filled one), a moved one takes this
        # frame's
        conf = np.where(held, np.maximum(conf, previous.confidence), conf).astype(np.float32)
    conf = np.where(current.confidence > 0, conf, 0.0).astype(np.float32)
    patch, _ = fill_and_smooth(raw, conf, grid.neighbours, grid.centres / grid.diameter,
                               st.min_confidence, st.smooth_iterations, current.fallback)
    patch = np.clip(patch, cand[0], cand[-1]).astype(np.float32)
    result = dataclasses.replace(
        current, patch=patch, raw=raw, confidence=conf, confident=conf >= st.min_confidence,
        focus=focus_weights(grid, patch, st.focus_softness, st.focus_floor))
    return result, held


class VideoConverter:
    """Converts the frames of one recording with one set-up (module docstring).

    ``setup``: the camera's decisions (a workflow's ``convert_setup.json``), or None:
    decided on the first frame given to :meth:`convert` (or call :meth:`decide` with the
    frame to decide on)."""

    def __init__(self, calib: RayCalib, n_views: int, settings: ConvertSettings,
                 video: VideoSettings | None = None, setup: ConverterSetup | None = None,
                 grid_foreign: str | None = None, threads: int = 1) -> None:
        self.calib = calib
        self.threads = threads
        self.n_views = n_views
        self.base = video_settings(settings)
        self.video = video or VideoSettings()
        self.setup = setup
        self.grid_foreign = grid_foreign
        self._grid: MicrolensGrid | None = None
        self._previous: PatchSizeResult | None = None
        self.held_share: float | None = None  # share of lenses held in the last frame
        # the decision's measurements of its frame, (source, analysis): that frame's
        # conversion takes them instead of measuring the frame again
        self._decided: tuple[str, ConvertAnalysis] | None = None

    def decide(self, image: np.ndarray, source: str) -> ConverterSetup:
        """Decide the set-up on ``image`` (a :func:`lenslet_frame`); its measurements
        (patch sizes, vignetting profiles) serve :meth:`convert` of the frame named
        ``source``, the same numbers as measured again: the decision measures on the
        set-up's grid, its kind and its patch settings."""
        kw = {} if self.grid_foreign is None else {"grid_foreign": self.grid_foreign}
        self.setup, shot = decide_setup(image, self.calib, self.n_views, self.base, source,
                                        threads=self.threads, **kw)
        self._decided = (source, shot.analysis)
        return self.setup

    def convert(self, image: np.ndarray, source: str) -> ShotConversion:
        """The conversion of one frame (a :func:`lenslet_frame`)."""
        if self.setup is None:
            self.decide(image, source)
        setup = self.setup
        assert setup is not None
        H, W = image.shape[:2]
        if self._grid is None or (self._grid.width, self._grid.height) != (W, H):
            self._grid = setup.grid(self.calib, W, H)
        st = setup.settings(self.base)
        analysis = None
        self.held_share = None
        decided, self._decided = self._decided, None
        if decided is not None and decided[0] == source and self._previous is None:
            # the frame the set-up was decided on, converted first: measured already
            analysis = dataclasses.replace(decided[1], mla_scores=None)
            if self.video.temporal == "hold":
                analysis = self._hold(analysis, st)
        elif self.video.temporal == "hold":
            analysis = self._hold(self._measure(image, st, source), st)
        shot = ShotConversion(image, self.calib, self.n_views, st, source=source,
                              grid=self._grid, analysis=analysis, check_mla=False,
                              safe_diameter=setup.safe_diameter_px, threads=self.threads,
                              log_bits=False, least_reach=setup.least_reach,
                              border_cut=setup.border_cut)
        shot.grid_check = setup.grid_check
        return shot

    def _measure(self, image: np.ndarray, st: ConvertSettings, source: str) -> ConvertAnalysis:
        """What :class:`ShotConversion` measures on a frame with a set-up (the kind is the
        set-up's), on the same grey image: an 8-bit frame's 8 bits, a deeper frame's 16
        (:func:`lenslet_frame`). An 8-bit frame read as 16 bits is 257 times too dark, and
        the matching then finds no lens it can trust: every lens that moved was filled
        from its neighbours, not measured."""
        assert self._grid is not None
        gray = frame_gray(image, significant_bits(image, st.bit_depth))
        vignetting = lens_type_profiles(gray, self._grid)
        patch = estimate_patch_size(gray, self._grid, st.patch, mla=st.mla,
                                    threads=self.threads, vignetting=vignetting)
        for note in patch.warnings:
            log.warning("%s: %s", source, note)
        profile, row = vignetting if st.devignette else (None, None)
        return ConvertAnalysis(st.mla, None, patch, profile, row)

    def _hold(self, analysis: ConvertAnalysis, st: ConvertSettings) -> ConvertAnalysis:
        """``analysis`` with each lens's size held from the previous frame where it still
        fits (:func:`hold_patch_sizes`); the frame becomes the previous one."""
        assert self._grid is not None
        first = self._previous is None
        patch, held = hold_patch_sizes(analysis.patch, self._previous, self._grid, st,
                                       self.video.hold_margin)
        self.held_share = None if first else float(held.mean())
        self._previous = patch
        return dataclasses.replace(analysis, patch=patch)


# ---------------------------------------------------------------------------
# A recording: frames in, per-view videos or per-frame PNGs out
# ---------------------------------------------------------------------------

OUTPUT_FORMATS = ("png", "yuv")


def _depth_note(bits: int) -> str:
    """How a recording of ``bits`` bits is read (:func:`lenslet_frame`), for the log."""
    if bits <= 8:
        return "8-bit recording, converted on its 8 bits"
    return f"{bits}-bit recording, its frames read as 16-bit words (16 significant bits)"


def parse_frames(text: str | None, count: int, source: str = "--frames") -> range:
    """The frames ``text`` names among ``count``, as a Python slice of ``range(count)``:
    ``A:B`` (A up to B, B excluded), ``A:``, ``:B``, ``A:B:S``, negative numbers from the
    end; a single ``A`` is frame A alone. None: all."""
    frames = range(count)
    if text is None:
        return frames
    try:
        parts = [int(p) if p.strip() else None for p in text.split(":")]
        if len(parts) == 1:
            k = parts[0]
            if k is None:
                raise ValueError
            chosen = frames[k:k + 1] if k != -1 else frames[-1:]
        elif len(parts) <= 3:
            chosen = frames[slice(*parts)]
        else:
            raise ValueError
    except (ValueError, TypeError):
        raise ConvertError(f"{source} {text!r}: expected A:B (Python slice, end excluded), "
                           "A:B:STEP or one frame number") from None
    _check_bounds(text, parts, count, source)
    if len(chosen) == 0:
        order = ("B must come after A" if len(parts) < 3 or (parts[2] or 1) > 0
                 else "with a negative STEP, B must come before A")
        raise ConvertError(f"{source} {text!r}: selects none of the file's {count} frames "
                           f"(0..{count - 1}; A:B is A up to B, B excluded, so {order})")
    return chosen


def _check_bounds(text: str, parts: list[int | None], count: int, source: str) -> None:
    """Refuse a bound of ``--frames`` past the file's ``count`` frames: a Python slice
    would clamp it, and ``0:300`` on a 3-frame file would convert 3 frames without a
    word. A frame (a single number, or A) lies in ``-count..count - 1``; the end B, one
    past the last frame taken, in ``-count..count`` (with a negative STEP,
    ``-count - 1..count - 1``). An open bound (``A:``, ``:B``) is the file's own."""
    backwards = len(parts) == 3 and (parts[2] or 1) < 0
    for i, k in enumerate(parts[:2]):
        if k is None:
            continue
        is_end = len(parts) > 1 and i == 1
        low, high = -count, count - 1
        if is_end:
            low, high = (low - 1, high) if backwards else (low, high + 1)
        if not low <= k <= high:
            what = "end" if is_end else "frame"
            raise ConvertError(
                f"{source} {text!r}: {what} {k} is past the file's {count} frames "
                f"(0..{count - 1}); leave the bound open (A: or :B) to reach the file's "
                "end, or check --size and the bit depth, which set the frame count")


class ViewVideos:
    """One YUV 4:2:0 file per view in ``folder`` (:func:`plenocal.io.yuv.mpeg_name`), each
    frame appended by opening the view's file for that write alone: any number of views
    within the system's limit on open files (1,024 by default on Linux, where 33 x 33 views
    held open at once failed). :func:`convert_recording` writes them in a staging folder
    (:func:`plenocal.io.files.staged_outputs`), so a failed run leaves none behind."""

    def __init__(self, folder: Path, names: list[str], fmt: YuvFormat) -> None:
        self.fmt = fmt
        self.paths = {n: folder / mpeg_name(f"v_{n}", fmt) for n in names}
        for path in self.paths.values():
            path.write_bytes(b"")  # every view's file, empty, before the first frame

    def write(self, name: str, planes: tuple[np.ndarray, np.ndarray, np.ndarray]) -> None:
        with open(self.paths[name], "ab") as fh:
            write_frame(fh, planes, self.fmt)


class OncePerRecording(logging.Filter):
    """Lets each warning of a recording through once: a later frame's warning that reads
    the same but for its numbers (the frame's index, its shares and sizes) is counted, not
    logged, and :meth:`summary` gives the counts. Three hundred frames of a recording whose
    calibration file cuts the patch-size search would otherwise say the same three hundred
    times."""

    def __init__(self) -> None:
        super().__init__()
        self.repeats: dict[str, tuple[str, int]] = {}  # key: (first message, later count)

    @staticmethod
    def key(message: str) -> str:
        return re.sub(r"\d+(?:\.\d+)?", "#", message)

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno != logging.WARNING:
            return True
        message = record.getMessage()
        k = self.key(message)
        if k not in self.repeats:
            self.repeats[k] = (message, 0)
            return True
        first, n = self.repeats[k]
        self.repeats[k] = (first, n + 1)
        return False

    def summary(self) -> list[str]:
        """One line per warning that came again: its first words and how often."""
        return [f"the warning \"{first[:80]}...\" came again on {n} more frame(s) of this "
                "recording (said once)" for first, n in self.repeats.values() if n]


@contextlib.contextmanager
def warnings_once(logger: logging.Logger = log) -> Iterator[OncePerRecording]:
    """:class:`OncePerRecording` on ``logger`` while the block runs; the repeats' counts
    logged at its end (also when it fails)."""
    once = OncePerRecording()
    logger.addFilter(once)
    try:
        yield once
    finally:
        logger.removeFilter(once)
        for line in once.summary():
            logger.warning(line)


def convert_recording(path: str | Path, calib: RayCalib, out: str | Path, n_views: int,
                      settings: ConvertSettings, video: VideoSettings | None = None,
                      size: tuple[int, int] | None = None, bits: int | None = None,
                      frames: str | None = None, out_format: str = "png",
                      setup_frame: int | None = None, setup: ConverterSetup | None = None,
                      grid_foreign: str | None = None, threads: int = 1,
                      png_bits: int | None = None) -> dict:
    """Convert the frames ``frames`` (:func:`parse_frames`) of the raw YUV 4:2:0 file
    ``path`` (format: :func:`plenocal.io.yuv.resolve_format` with ``size`` / ``bits``) into
    ``out``: ``yuv``, one video per view of the input's bit depth
    (``v_<r>_<c>_<W>x<H>_<b>bit_<pix_fmt>.yuv``), or ``png``, a folder ``frame_<k>`` per frame
    (``k``: the frame's index in the file, 5 digits) with the views and ``disparity.json``.
    The set-up (``setup``, or decided on frame ``setup_frame``, default the first converted
    one; negative: from the end) is written to ``out/convert_setup.json``, what was done to
    ``out/video.json``. All of it is made in a staging folder inside ``out`` and moved into
    place at the end, video.json last (:func:`plenocal.io.files.staged_outputs`): a run
    that fails leaves ``out`` as it was.
    Progress per frame on the ``plenocal.convert`` logger; ``threads``: the views of a frame
    are rendered on that many threads (the same bytes with any number). ``png_bits``: the PNG
    views' bits per sample (:func:`plenocal.io.png.view_dtype`; a recording of more than 8
    bits keeps its levels at 16). Returns the video.json record."""
    path = Path(path)
    out = Path(out)
    video = video or VideoSettings()
    if out_format not in OUTPUT_FORMATS:
        raise ConvertError(f"output format {out_format!r}: one of {', '.join(OUTPUT_FORMATS)}")
    try:
        fmt = resolve_format(path, size, bits)
    except YuvError as exc:
        raise ConvertError(str(exc)) from None
    count = frame_count(path, fmt)
    chosen = parse_frames(frames, count)
    # an earlier conversion's files that this one would not replace stop it now, before
    # the set-up's analysis (plenocal.convert.outfolder)
    check_output_folder(out, recording_claims(n_views, chosen, out_format),
                        f"{n_views} x {n_views} views of frames {chosen[0]}..{chosen[-1]}"
                        + (f" every {chosen.step}" if chosen.step != 1 else "")
                        + f" as {out_format}", n_views=n_views if out_format == "png" else None)
    log.info("%s: %s", path.name, _depth_note(fmt.bits))
    if setup is not None and setup_frame is not None:
        raise ConvertError(f"--setup-frame {setup_frame} with --setup: the set-up is read from "
                           "the file, not decided on a frame; give one of the two")
    if setup is not None:
        setup.check_frame(fmt.width, fmt.height, path.name, calib)
    from plenocal.convert.renderkernels import warm_in_background  # noqa: PLC0415

    warm_in_background()  # numba's set-up while the first frame is read and analysed
    with warnings_once():  # each frame's warnings said once for the recording
        return _convert_recording(path, fmt, count, chosen, calib, out, n_views, settings,
                                  video, out_format, setup_frame, setup, grid_foreign,
                                  threads, view_dtype(png_bits))


def _convert_recording(path: Path, fmt: YuvFormat, count: int, chosen: range,
                       calib: RayCalib, out: Path, n_views: int, settings: ConvertSettings,
                       video: VideoSettings, out_format: str, setup_frame: int | None,
                       setup: ConverterSetup | None, grid_foreign: str | None,
                       threads: int, png_dtype: type) -> dict:
    """:func:`convert_recording` from its set-up on (the arguments checked, the output
    folder free)."""
    conv = VideoConverter(calib, n_views, settings, video, setup, grid_foreign, threads)
    decided_frame: tuple[int, np.ndarray] | None = None
    if setup is None:
        k = chosen[0] if setup_frame is None else setup_frame
        if not -count <= k < count:
            raise ConvertError(f"--setup-frame {k}: the file holds frames 0..{count - 1} "
                               "(negative numbers count from the end, as in --frames)")
        k %= count
        t0 = time.perf_counter()
        image = lenslet_frame(read_frame(path, fmt, k), fmt.bits, video.matrix, video.range)
        conv.decide(image, f"{path.name}[{k}]")
        if k == chosen[0]:  # converted first: not read and turned into RGB again
            decided_frame = (k, image)
        del image
        log.info("%s: set-up decided on frame %d (MLA %s, tile %d px per lens pitch, D' "
                 "%.2f px); %.2f s", path.name, k, conv.setup.mla, conv.setup.tile,
                 conv.setup.safe_diameter_px or float("nan"), time.perf_counter() - t0)
    assert conv.setup is not None
    if out_format == "png":
        _check_chunk_setup(out, conv.setup, chosen)
    if conv.setup.border_cut.any:
        log.info("%s: %s", path.name, conv.setup.border_cut.summary())
    out.mkdir(parents=True, exist_ok=True)
    # everything is made in a staging folder and moved into ``out`` at the end, video.json
    # last: a run that fails or is stopped leaves the previous run's files as they were
    with staged_outputs(out, last=("video.json",)) as stage:
        doc = _convert_frames(path, fmt, count, chosen, conv, stage, n_views, video,
                              out_format, threads, decided_frame, png_dtype=png_dtype)
    if out_format == "yuv":  # this run's views' videos at an earlier run's size replaced
        for old in stale_view_videos(out, set(doc["views"]["files"].values())):
            old.unlink()
            log.info("%s: removed, an earlier run's video of the same view", old.name)
    return doc


def _check_chunk_setup(out: Path, setup: ConverterSetup, chosen: range) -> None:
    """A recording converted in chunks of ``--frames`` into one folder: the frame folders
    an earlier chunk left there were made with the set-up in its ``convert_setup.json``.
    A chunk that decided its own set-up on another frame (no ``--setup``) may differ (the
    safe diameter, so the views' spacing, read 15.48 px on one frame and 15.04 on the next)
    and would put two set-ups in one folder, the earlier one no longer recorded: refused
    unless the two are the same."""
    old = out / "convert_setup.json"
    own = {frame_folder(k) for k in chosen}
    kept = sorted(p.name for p in out.glob("frame_*") if p.is_dir() and p.name not in own)
    if not kept or not old.is_file():
        return
    if old.read_text() == dumps_json(setup.to_dict()):
        return
    raise ConvertError(
        f"{out}: {', '.join(kept[:3])}{' ...' if len(kept) > 3 else ''} were converted with "
        f"{old}, and this run decided another set-up on its own frame: pass --setup {old} "
        "to convert the recording's further frames with the same set-up, or write them to "
        "another folder")


def _convert_frames(path: Path, fmt: YuvFormat, count: int, chosen: range,
                    conv: VideoConverter, out: Path, n_views: int, video: VideoSettings,
                    out_format: str, threads: int,
                    first: tuple[int, np.ndarray] | None = None, *, png_dtype: type) -> dict:
    """:func:`convert_recording`'s frames, written to ``out`` (its staging folder).
    ``first``: (frame number, its :func:`lenslet_frame`) where it was read already (the
    set-up's frame); handed on, not kept. ``png_dtype``: the PNG views' samples."""
    assert conv.setup is not None
    write_setup(out / "convert_setup.json", conv.setup)
    names = view_names(n_views)
    writer: ViewVideos | None = None
    records: list[dict] = []
    view_fmt: YuvFormat | None = None
    # the frames share one layout: the renderer's nearest-lens tables are made once (a
    # recording of one frame keeps none: nothing would ask again)
    slots = contextlib.ExitStack()
    if len(chosen) > 1:
        slots.enter_context(remembered_slots())
    try:
        for i, k in enumerate(chosen):
            t0 = time.perf_counter()
            if first is not None and first[0] == k:
                image, first = first[1], None
            else:
                image = lenslet_frame(read_frame(path, fmt, k), fmt.bits, video.matrix,
                                      video.range)
            shot = conv.convert(image, f"{path.name}[{k}]")
            L = shot.layout
            if view_fmt is None:
                view_fmt = YuvFormat(L.width, L.height, fmt.bits)
                if out_format == "yuv":
                    writer = ViewVideos(out, names, view_fmt)
            elif (L.width, L.height) != (view_fmt.width, view_fmt.height):
                raise ConvertError(f"{path.name}[{k}]: views of {L.width}x{L.height}, the "
                                   f"video's are {view_fmt.width}x{view_fmt.height}")
            folder = out / frame_folder(k)
            if out_format == "png":
                folder.mkdir()
            # views in groups within the converter's memory budget: 16-bit for YUV videos
            # of more than 8 bits (rounded again to the input's depth there), 8-bit for
            # 8-bit videos, whose frames are 8-bit RGB (lenslet_frame): twice as many views
            # in the budget (one group on a 12-MP frame, where 16-bit views took two, each
            # planning the frame again) and a third of the softening time; PNGs as asked
            if writer is not None:
                dtype = np.uint16 if fmt.bits > 8 else np.uint8
            else:
                dtype = png_dtype
            for views in shot.view_groups(threads=threads, dtype=dtype):
                if writer is not None:  # made side by side, written in view order
                    to_yuv = partial(view_to_yuv, bits=fmt.bits, matrix=video.matrix,
                                     rng=video.range)
                    group = list(views)
                    for a in range(0, len(group), max(threads, 1)):  # planes of a few views
                        part = group[a:a + max(threads, 1)]
                        planes = map_threads(to_yuv, [views[n] for n in part], threads)
                        for name, yuv in zip(part, planes, strict=True):
                            writer.write(name, yuv)
                else:
                    write_images(((folder / f"{name}.png", view)
                                  for name, view in views.items()), threads)
                views.clear()  # before the next group is rendered
            stats = shot.disparity()
            if out_format == "png":
                write_json(folder / "disparity.json", stats)
            p = stats["patch_size_px"]
            rec = {"frame": k, "patch_median_px": p["median"],
                   "confident_share": p["confident_share"], "held_share": conv.held_share}
            records.append(rec)
            log.info("frame %d (%d/%d): patch sizes median %.2f px, %.0f%% confident%s; "
                     "%.2f s", k, i + 1, len(chosen), p["median"], 100 * p["confident_share"],
                     "" if conv.held_share is None
                     else f", {100 * conv.held_share:.0f}% held from the previous frame",
                     time.perf_counter() - t0)
    finally:
        slots.close()
    assert view_fmt is not None
    doc = {"format": "plenocal.video", "version": 1, "input": str(path),
           "input_format": {"width": fmt.width, "height": fmt.height, "bits": fmt.bits,
                            "pix_fmt": fmt.pix_fmt, "frames": count},
           "colour": {"matrix": video.matrix, "range": video.range},
           "temporal": {"mode": video.temporal, "hold_margin": video.hold_margin},
           "views": {"n": n_views, "width": view_fmt.width, "height": view_fmt.height,
                     "format": out_format,
                     "bits": fmt.bits if writer is not None else 8 * np.dtype(png_dtype).itemsize,
                     "files": ({n: writer.paths[n].name for n in names}
                               if writer is not None else None)},
           "set_up": {"decided_on": conv.setup.decided_on, "file": "convert_setup.json"},
           "frames": records}
    write_json(out / "video.json", doc)
    return doc
