"""Lenslet video: a raw YUV 4:2:0 recording into N x N subaperture videos.

One recording is one camera, so the converter's per-camera decisions - the grid, the MLA
kind, the tile (and with it the one view size of the whole video), the safe diameter and
the view spacing - are made once (:func:`plenocal.convert.setup.decide_setup`, on the
first converted frame or the frame the user names, as rule ``convert_setup`` makes them on
an array's central shot), or taken from a workflow's ``convert_setup.json``. Every frame is
then converted as a shot of that camera (:class:`plenocal.convert.shot.ShotConversion`
with the set-up, as rule ``convert`` converts each shot).

Colour. The converter works in RGB: each frame's (Y, Cb, Cr) planes become RGB
(:func:`plenocal.io.yuv.yuv_to_rgb`, BT.709 limited range by default), held as 16-bit
integers (:func:`lenslet_frame`; a 10-bit frame loses nothing, an 8-bit one is not rounded
to 8-bit RGB), and the views go back to YUV 4:2:0 of the input's bit depth
(:func:`plenocal.io.yuv.rgb_to_yuv`) or to 8-bit RGB PNGs. The views of a frame are those
that converting the same RGB frame as a 16-bit PNG with the same set-up gives (to the
rounding of the output).

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

import dataclasses
import logging
from dataclasses import dataclass

import numpy as np

from plenocal.convert.analysis import ConvertAnalysis
from plenocal.convert.errors import ConvertError
from plenocal.convert.levels import to_unit_float
from plenocal.convert.patchsize import (
    PatchSizeResult,
    estimate_patch_size,
    fill_and_smooth,
    focus_weights,
    to_gray,
)
from plenocal.convert.setup import ConverterSetup, decide_setup
from plenocal.convert.shot import ConvertSettings, ShotConversion
from plenocal.convert.vignetting import lens_type_profiles
from plenocal.grid import MicrolensGrid
from plenocal.io.raytrix import RayCalib
from plenocal.io.yuv import DEFAULT_MATRIX, DEFAULT_RANGE, MATRICES, RANGES, yuv_to_rgb

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
    """One YUV frame as the 16-bit RGB lenslet image the converter reads (uint16, full
    16-bit scale: convert it with ``bit_depth: 16``). Written as a 16-bit PNG it is the
    frame's PNG, whose conversion the video's matches."""
    rgb = yuv_to_rgb(planes, bits, matrix, rng)
    return np.rint(rgb * np.float32(65535.0)).astype(np.uint16)


def video_settings(base: ConvertSettings) -> ConvertSettings:
    """``base`` for the frames of :func:`lenslet_frame` (16 significant bits)."""
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
                 grid_foreign: str | None = None) -> None:
        self.calib = calib
        self.n_views = n_views
        self.base = video_settings(settings)
        self.video = video or VideoSettings()
        self.setup = setup
        self.grid_foreign = grid_foreign
        self._grid: MicrolensGrid | None = None
        self._previous: PatchSizeResult | None = None
        self.held_share: float | None = None  # share of lenses held in the last frame

    def decide(self, image: np.ndarray, source: str) -> ConverterSetup:
        """Decide the set-up on ``image`` (a :func:`lenslet_frame`)."""
        kw = {} if self.grid_foreign is None else {"grid_foreign": self.grid_foreign}
        self.setup, _ = decide_setup(image, self.calib, self.n_views, self.base, source, **kw)
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
        if self.video.temporal == "hold":
            analysis = self._measure(image, st, source)
        shot = ShotConversion(image, self.calib, self.n_views, st, source=source,
                              grid=self._grid, analysis=analysis, check_mla=False,
                              safe_diameter=setup.safe_diameter_px)
        shot.grid_check = setup.grid_check
        return shot

    def _measure(self, image: np.ndarray, st: ConvertSettings, source: str) -> ConvertAnalysis:
        """What :class:`ShotConversion` measures on a frame with a set-up (the kind is the
        set-up's), each lens's size held from the previous frame where it still fits."""
        assert self._grid is not None
        gray = to_gray(to_unit_float(image, 16))
        patch = estimate_patch_size(gray, self._grid, st.patch, mla=st.mla)
        for note in patch.warnings:
            log.warning("%s: %s", source, note)
        first = self._previous is None
        patch, held = hold_patch_sizes(patch, self._previous, self._grid, st,
                                       self.video.hold_margin)
        self.held_share = None if first else float(held.mean())
        self._previous = patch
        profile, row = lens_type_profiles(gray, self._grid) if st.devignette else (None, None)
        return ConvertAnalysis(st.mla, None, patch, profile, row)
