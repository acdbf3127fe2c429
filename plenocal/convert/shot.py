"""Convert one lenslet image into its N x N subaperture views (the RLC of Fig. 1 (a)).

:class:`ShotConversion` ties the stages together: the microlens grid from
``calib.xml`` (:class:`plenocal.grid.MicrolensGrid`), the output layout
(:func:`plenocal.viewgeom.make_layout`), the patch-size map
(:mod:`plenocal.convert.patchsize`) and the view renderer
(:mod:`plenocal.convert.render`). ``disparity.json``
(:func:`plenocal.artifacts.disparity.disparity_record`) gives the disparity range between
views that Eqs. 1-3 of the paper use.

View spacing. View (r, c) is cut at ``q_rc = ((c - (N-1)/2) q, (r - (N-1)/2) q)`` from
the micro-image centre, ``q = D' sin(45 deg) / N`` by default: the N x N view points
then span a square of side ``(N-1)/N D' sin 45`` inscribed (with a margin of one
``q``) in the safe micro-image disc of diameter ``D' = D - 2 lens_border``.

Disparity between views. The tile of lens ``i`` samples
``m_i + q_rc + s (u - o_i) P / T`` (``s = -1`` Keplerian, ``+1`` Galilean; see
:mod:`plenocal.viewgeom`), so a point whose patch size is ``P`` moves by
``u_(h+1) - u_h = -s q T / P`` output pixels from view (r, c) to view (r, c+1). In the
paper's Eq. 1, ``d = u_h - u_(h+1) = s q T / P``. Keplerian (the simulator, the TSPC
frames): ``-q T / P``, negative everywhere, because the scene lies beyond the plane
conjugate to the MLA, where all views converge, and nearer points have larger ``P``.
Galilean (the Raytrix frames): ``+q T / P``, nearer points have smaller ``P``. In both,
D_max belongs to the nearest object (the paper's sign).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import yaml

from plenocal.artifacts.disparity import disparity_record
from plenocal.config import settings_from, stage_defaults, with_defaults
from plenocal.convert.analysis import ConvertAnalysis
from plenocal.convert.bordercut import BorderCut, measure_border_cut
from plenocal.convert.demosaic import BAYER_PATTERNS, demosaic, mosaic_warning
from plenocal.convert.errors import ConvertError
from plenocal.convert.holes import Confidence, fill_unsupported, weak_box
from plenocal.convert.levels import (
    OVEREXPOSED_SHARE,
    clipped_share,
    render_source,
    significant_bits,
    to_unit_float,
)
from plenocal.convert.patchsize import (
    PatchSizeResult,
    PatchSizeSettings,
    detect_mla_kind,
    estimate_patch_size,
    lattice_mean,
    out_of_range,
    reliability,
    to_gray,
)
from plenocal.convert.render import (
    FOCUS_SPARSE,
    RenderPlan,
    RenderSettings,
    focus_reach,
    make_plans,
    reliability_map,
    render_view,
    rim_reach,
    soften_unreliable,
)
from plenocal.convert.safediameter import SafeDiameter, measure_safe_diameter
from plenocal.convert.threads import Inline, opencv_threads, run_all
from plenocal.convert.vignetting import lens_type_profiles
from plenocal.grid import MicrolensGrid
from plenocal.io import png
from plenocal.io.files import TruncatedImageError, read_image
from plenocal.io.lenslet import CaptureError, png_format, sensor_mismatch
from plenocal.io.raytrix import CalibError, RayCalib, read_calib
from plenocal.names import parse_view, view_names
from plenocal.optics import view_spacing
from plenocal.viewgeom import MLA_KINDS, ViewLayout, make_layout

log = logging.getLogger("plenocal.convert")


def _percentiles(pct: list) -> tuple[float, float]:
    return float(pct[0]), float(pct[1])


_CONVERT = stage_defaults("convert")


@dataclass(frozen=True)
class ConvertSettings:
    """The ``convert`` block of the config (config.schema.yaml documents every key).

    ``tile_size``: output pixels per lens pitch, or ``"auto"``: ``ceil(upsample x``
    the median confident patch size``)`` (the views' natural resolution, ``upsample``
    output pixels per sensor pixel of patch). ``mla``: ``keplerian`` (Raytrix, the
    simulator: micro images inverted) or ``galilean`` (TSPC: upright). ``even_size``:
    crop the views' last column / row where odd (YUV 4:2:0). ``bit_depth``: ``"auto"``
    (16-bit images whose maximum fits 10, 12 or 14 bits are scaled to that range) or
    the number of significant bits (8..16). Defaults: the schema's (``percentiles``:
    ``disparity_percentiles``, ``patch``: ``patch_size``, ``render``: ``blend``)."""

    tile_size: int | str = _CONVERT["tile_size"]
    upsample: float = _CONVERT["upsample"]
    view_spacing_px: float | None = _CONVERT["view_spacing_px"]
    safe_diameter: float | str = _CONVERT["safe_diameter"]  # auto | file | D' in pixels
    percentiles: tuple[float, float] = _percentiles(_CONVERT["disparity_percentiles"])
    mla: str = _CONVERT["mla"]
    even_size: bool = _CONVERT["even_size"]
    bit_depth: int | str = _CONVERT["bit_depth"]
    bayer: str = _CONVERT["bayer"]  # none | a CFA pattern (plenocal.convert.demosaic)
    devignette: bool = _CONVERT["devignette"]
    grid: str = _CONVERT["grid"]  # file | refine | auto (plenocal.convert.gridcheck)
    border_cut: str = _CONVERT["border_cut"]  # auto | off (plenocal.convert.bordercut)
    patch: PatchSizeSettings = field(default_factory=PatchSizeSettings)
    render: RenderSettings = field(default_factory=RenderSettings)

    def __post_init__(self) -> None:
        t = self.tile_size
        if not (t == "auto" or (isinstance(t, int) and not isinstance(t, bool) and t >= 1)):
            raise ConvertError(f"convert.tile_size: 'auto' or a whole number >= 1, not {t!r}")
        if not self.upsample > 0:
            raise ConvertError(f"convert.upsample: must be > 0 (got {self.upsample})")
        if self.mla not in ("auto", *MLA_KINDS):
            raise ConvertError(f"convert.mla: auto, {' or '.join(MLA_KINDS)}, not {self.mla!r} "
                               "(auto: read from the image; see README 'MLA kinds')")
        d = self.safe_diameter
        if not (d in ("auto", "file") or (isinstance(d, (int, float))
                                          and not isinstance(d, bool) and d > 0)):
            raise ConvertError(f"convert.safe_diameter: 'auto', 'file' or a number of pixels "
                               f"> 0, not {d!r}")
        if self.border_cut not in ("auto", "off"):
            raise ConvertError(f"convert.border_cut: 'auto' or 'off', not {self.border_cut!r}")
        b = self.bit_depth
        if not (b == "auto" or (isinstance(b, int) and 8 <= b <= 16)):
            raise ConvertError(f"convert.bit_depth: 'auto' or 8..16, not {b!r}")
        lo, hi = self.percentiles
        if not lo < hi:
            raise ConvertError(f"convert.disparity_percentiles = [{lo:g}, {hi:g}]: the low "
                               "percentile first, below the high one (e.g. [2, 98]); "
                               "reversed, D_min and D_max swap places")
        if self.bayer not in ("none", *BAYER_PATTERNS):
            raise ConvertError(f"convert.bayer: none or a colour filter array of "
                               f"{', '.join(BAYER_PATTERNS)}, not {self.bayer!r}")

    @classmethod
    def from_config(cls, cfg: dict | None) -> ConvertSettings:
        """The settings of the config's ``convert`` block, partial or whole (missing keys:
        the schema's defaults)."""
        cfg = with_defaults("convert", cfg)
        tile, bits = cfg["tile_size"], cfg["bit_depth"]
        return cls(
            tile_size=tile if isinstance(tile, str) else int(tile),
            upsample=float(cfg["upsample"]),
            view_spacing_px=cfg["view_spacing_px"],
            safe_diameter=(cfg["safe_diameter"] if isinstance(cfg["safe_diameter"], str)
                           else float(cfg["safe_diameter"])),
            percentiles=_percentiles(cfg["disparity_percentiles"]),
            mla=str(cfg["mla"]),
            even_size=bool(cfg["even_size"]),
            bit_depth=bits if isinstance(bits, str) else int(bits),
            bayer=str(cfg["bayer"]),
            devignette=bool(cfg["devignette"]),
            grid=str(cfg["grid"]),
            # YAML 1.1 reads a bare ``off`` as false
            border_cut="off" if cfg["border_cut"] is False else str(cfg["border_cut"]),
            patch=settings_from(PatchSizeSettings, cfg["patch_size"]),
            render=settings_from(RenderSettings, cfg["blend"]),
        )


# ---------------------------------------------------------------------------
# Inputs
# ---------------------------------------------------------------------------


def read_sensor_size(camera_yaml: str | Path) -> tuple[int, int] | None:
    """(width, height) from ``camera.yaml`` (sensor_width_px, sensor_height_px), or None."""
    path = Path(camera_yaml)
    try:
        with open(path) as fh:
            doc = yaml.safe_load(fh) or {}
    except OSError as exc:
        raise ConvertError(f"{path}: cannot read the camera datasheet: {exc.strerror}") from None
    except yaml.YAMLError as exc:
        raise ConvertError(f"{path}: not valid YAML: {exc}") from None
    w, h = doc.get("sensor_width_px"), doc.get("sensor_height_px")
    if w is None or h is None:
        return None
    return int(w), int(h)


def load_lenslet(path: str | Path, sensor_size: tuple[int, int] | None = None,
                 bayer: str | None = None) -> np.ndarray:
    """Read a lenslet image; check its size against the datasheet's sensor size.

    ``bayer``: ``convert.bayer``, the colour filter array of a raw one-channel frame,
    which is then demosaiced (:func:`plenocal.convert.demosaic.demosaic`); ``none`` or
    None: the frame as it is (the conversion warns of a grey one that looks like a
    mosaic: :func:`plenocal.convert.demosaic.mosaic_warning`)."""
    path = Path(path)
    try:
        if path.is_file() and png.is_png(path):
            png_format(path)  # a palette or 1-, 2- or 4-bit image: no camera's readout
        img = read_image(path)
    except CaptureError as exc:
        raise ConvertError(str(exc)) from None
    except TruncatedImageError as exc:
        raise ConvertError(f"cannot read the lenslet image: {exc}") from None
    except (OSError, FileNotFoundError) as exc:
        why = str(exc).removeprefix(f"{path}: ")
        raise ConvertError(f"{path}: cannot read the lenslet image ({why}); copy or make it "
                           "again, or give the frame as a PNG") from None
    if img.ndim not in (2, 3) or img.dtype not in (np.uint8, np.uint16) or min(img.shape[:2]) < 8:
        raise ConvertError(f"{path}: not a usable lenslet image (shape {img.shape}, "
                           f"{img.dtype}); need an 8- or 16-bit grey or RGB PNG")
    if sensor_size is not None and (img.shape[1], img.shape[0]) != tuple(sensor_size):
        raise ConvertError(sensor_mismatch(path, (img.shape[1], img.shape[0]), sensor_size))
    if bayer not in (None, "none"):
        if img.ndim != 2:
            raise ConvertError(f"{path}: convert.bayer is {bayer}, but the frame has "
                               f"{img.shape[2]} channels: it is demosaiced already; set "
                               "convert.bayer: none (plenocal convert: leave out --bayer)")
        return demosaic(img, bayer)
    return img


def load_calib(path: str | Path) -> RayCalib:
    try:
        return read_calib(path)
    except CalibError as exc:
        raise ConvertError(str(exc)) from None


def build_grid(calib: RayCalib, width: int, height: int) -> MicrolensGrid:
    """The microlens grid for a ``width`` x ``height`` image, with the size checks.

    The file's offset places one lens (the grid's origin) against the image centre; the
    lattice extends from it over the whole image, so the origin may lie outside the image:
    a crop of a lenslet image whose calib.xml offset was moved with the crop (the lens
    that the offset names then lies outside the crop). Logged, not refused: a Raytrix
    file's offset for the full sensor is a lens or so from the centre, and a crop that
    kept it is judged by the grid check
    (:func:`plenocal.convert.gridcheck.check_grid`), as any other grid is."""
    src = calib.source
    if calib.diameter > min(width, height) / 2:
        raise ConvertError(f"{src}: micro-image diameter {calib.diameter:.1f} px is more than "
                           f"half the {width}x{height} image: wrong calib.xml for this image?")
    try:
        grid = MicrolensGrid(calib, width, height)
    except CalibError as exc:
        raise ConvertError(str(exc)) from None
    ox, oy = grid.origin
    if not (0 <= ox <= width - 1 and 0 <= oy <= height - 1):
        log.info("%s: the grid origin (image centre + offset) lies at (%.1f, %.1f), outside "
                 "the %dx%d lenslet image: read as a crop whose offset moved with it",
                 src, ox, oy, width, height)
    return grid


# ---------------------------------------------------------------------------
# Conversion
# ---------------------------------------------------------------------------


def resolve_tile(setting: int | str, patch: np.ndarray, confident: np.ndarray,
                 upsample: float) -> int:
    """The tile size T: the setting, or for ``auto`` ``ceil(upsample x median P)`` over
    the confident lenses (all lenses where none is confident), at least 2."""
    if setting != "auto":
        return int(setting)
    p = patch[confident] if np.any(confident) else patch
    return max(2, int(math.ceil(upsample * float(np.median(p)) - 1e-6)))


#: how much better (mean best ZNCC, :func:`plenocal.convert.patchsize.detect_mla`) the
#: image must match as the other MLA kind than as the one the settings name before the
#: conversion warns. On the six real frames of shared/real (full frames, this code) the
#: right kind scored 0.84-0.97 and the wrong one 0.16-0.29, the smallest gap 0.57 (Boxer);
#: the simulator's Galilean set-up 0.98 against 0.23-0.26 (README, "MLA kinds"). A frame
#: without texture scores low and close both ways and is not warned about.
MLA_CONTRADICTION = 0.3


def mla_contradiction(kind: str, scores: dict[str, float]) -> str | None:
    """The warning for an MLA kind set by hand that the image contradicts (``scores``:
    each kind's mean best ZNCC), or None. Forced the wrong way, the views are a mosaic of
    misplaced patches (Fujita2 as ``keplerian``, Boys2 as ``galilean``)."""
    other = next(k for k in scores if k != kind)
    if not scores[other] - scores[kind] >= MLA_CONTRADICTION:  # (NaN: no warning)
        return None
    return (f"convert.mla = {kind}, but the image matches as {other} (mean best ZNCC "
            f"{scores[other]:.3f} against {scores[kind]:.3f} as {kind}): the views will be "
            f"a mosaic of misplaced patches; set the kind to auto or {other} (workflow: "
            f"convert.mla or the dataset's mla; command line: --mla)")


def mla_undecided(kind: str, scores: dict[str, float]) -> str | None:
    """The warning for an MLA kind read from the image (``convert.mla: auto``) that the
    image does not decide: the two ways' mean best ZNCC (``scores``) less than
    :data:`MLA_CONTRADICTION` apart, or not measured (NaN), or None. A flat, dark or
    noisy frame matches both ways alike (pure noise: 0.096 and 0.095; a black frame 0 and
    0), and ``kind`` is then a coin's throw: a wrong one makes every view a mosaic."""
    other = next(k for k in scores if k != kind)
    if scores[kind] - scores[other] >= MLA_CONTRADICTION:
        return None
    return (f"the MLA kind cannot be read from this image: it matches as {kind} and as "
            f"{other} alike (mean best ZNCC {scores[kind]:.3f} against {scores[other]:.3f}; "
            f"a clear frame reads {MLA_CONTRADICTION:g} or more apart): {kind} is assumed. "
            "Name the camera's kind (workflow: convert.mla or the dataset's mla; command "
            "line: --mla), or decide it on a frame with texture")


class ShotConversion:
    """One lenslet image: grid, patch sizes, layout and the per-shot render plan.

    ``grid``: a microlens grid to use instead of the one built from ``calib`` (a grid
    refined from the image, for instance); it must belong to an image of this size.
    ``analysis``: this image's measurements made before (:attr:`analysis`, written by
    :func:`plenocal.convert.analysis.write_analysis`): the views are rendered from them
    without measuring the image again (the same views). ``check_mla``: where the settings
    name the MLA kind, read it from the image all the same and warn where the image
    contradicts it (:func:`mla_contradiction`); off for the shots converted with a
    camera's set-up, whose kind was checked on its central shot. ``safe_diameter``: the
    camera's safe diameter ``D'`` decided before (rule ``convert_setup``); None: per
    ``settings.safe_diameter`` (``auto``: measured on this image,
    :mod:`plenocal.convert.safediameter`). ``threads``: the measurements that do not wait
    for each other (the safe diameter, the MLA check, the vignetting profiles, the patch
    sizes) run side by side on that many threads; the same numbers with any number.
    ``log_bits``: log a 16-bit image's significant bits (off for a recording's frames,
    whose bit depth the recording's set-up line gives once). ``least_reach``: the least
    blend reach of every view decided for the camera (rule ``convert_setup``:
    :func:`plenocal.convert.render.focus_reach` on its central shot); None: decided on
    this image. ``border_cut``: the border lenses the main lens cuts, decided for the
    camera (rule ``convert_setup``); None: per ``settings.border_cut`` (``auto``:
    measured on this image, :mod:`plenocal.convert.bordercut`)."""

    def __init__(self, image: np.ndarray, calib: RayCalib, n_views: int,
                 settings: ConvertSettings | None = None, source: str = "<image>",
                 grid: MicrolensGrid | None = None,
                 analysis: ConvertAnalysis | None = None, check_mla: bool = True,
                 safe_diameter: float | None = None, threads: int = 1,
                 log_bits: bool = True, least_reach: int | None = None,
                 border_cut: BorderCut | None = None) -> None:
        self.settings = st = settings or ConvertSettings()
        self.grid_check: dict | None = None  # set by whoever checked the grid
        # each MLA kind's mean best ZNCC as measured on this image (read with auto, or
        # checked where the kind is set), None where not measured: the set-up's check
        # that calib.xml describes the frame (plenocal.convert.setup.unmatched_frame_error)
        self.match_scores: dict[str, float] | None = None
        self.warnings: list[str] = []
        self.calib = calib
        self.n_views = n_views
        H, W = image.shape[:2]
        if grid is not None and (grid.width, grid.height) != (W, H):
            raise ConvertError(f"{source}: the grid was built for {grid.width}x{grid.height}, "
                               f"the image is {W}x{H}")
        self.grid = grid if grid is not None else build_grid(calib, W, H)
        self.bits = significant_bits(image, st.bit_depth, source)
        if image.dtype == np.uint16 and log_bits:
            log.info("%s: 16-bit image with %d significant bits (max %d)", source, self.bits,
                     int(image.max()))
        self._image = image
        # what the views sample: the image's own integers (no float copy of the frame),
        # prefiltered against bilinear sampling's blur where convert.blend.prefilter is set
        # (plenocal.convert.prefilter; 0 in the config, which the workflow's views take,
        # and 0.1 on the command line: plenocal.cli.CLI_CONVERT_DEFAULTS)
        self._render_source, self._render_scale = render_source(image, self.bits,
                                                                st.render.prefilter)
        self._source_float: np.ndarray | None = None
        self._gray: np.ndarray | None = None
        self._threads = threads
        given = analysis is not None
        if not given or (safe_diameter is None and st.safe_diameter == "auto") or (
                border_cut is None and st.border_cut == "auto"):
            self.gray  # noqa: B018  (made once, here, before the threads read it)
        pool = ThreadPoolExecutor(max_workers=threads - 1) if threads > 1 else Inline()
        try:
            safe_job = pool.submit(self._safe_diameter, safe_diameter, source)
            if analysis is None:
                analysis = self._measure(source, check_mla, pool)
            self.safe: SafeDiameter = safe_job.result()
        finally:
            pool.shutdown()
        d_safe = self.safe.diameter_px
        self.border_cut: BorderCut = self._border_cut(border_cut, source)
        q = st.view_spacing_px if st.view_spacing_px is not None else view_spacing(
            d_safe, n_views)
        max_q = math.hypot(1, 1) * (n_views - 1) / 2 * q
        if max_q >= calib.safe_diameter / 2:
            raise ConvertError(f"view spacing q = {q:.3f} px puts the corner views "
                               f"{max_q:.2f} px from the lens centre, outside the safe micro "
                               f"image (radius {calib.safe_diameter / 2:.2f} px): lower "
                               "convert.view_spacing_px or the number of views")
        if given:
            problem = (f"holds {analysis.lenses} lenses, the grid {len(self.grid)}"
                       if analysis.lenses != len(self.grid) else
                       f"was made for a {analysis.mla} MLA, the settings say {st.mla}"
                       if st.mla != "auto" and analysis.mla != st.mla else
                       "has no vignetting profile, the settings devignette"
                       if st.devignette and analysis.profile is None else None)
            if problem:
                raise ConvertError(f"{source}: the conversion analysis {problem}: it belongs "
                                   "to another image or settings; rerun rule convert for "
                                   "this shot")
        self.analysis: ConvertAnalysis = analysis
        self.mla, self.mla_scores = analysis.mla, analysis.mla_scores
        if self.match_scores is None:  # the kind read from the image (auto)
            self.match_scores = analysis.mla_scores
        self.patch: PatchSizeResult = analysis.patch
        self.warnings += [f"{source}: {note}" for note in self.patch.warnings]
        inside = self.grid.inside(0.0)
        tile = resolve_tile(st.tile_size, self.patch.patch[inside],
                            self.patch.confident[inside], st.upsample)
        try:
            self.layout: ViewLayout = make_layout(self.grid, n_views, tile, q, mla=self.mla,
                                                  even=st.even_size,
                                                  insets_px=self.border_cut.insets_px)
        except ValueError as exc:
            raise ConvertError(f"{source} with {calib.source}: {exc}") from None
        self.used_patch = self.patch.patch[self.layout.lens_index]
        # the micro images' vignetting, one profile per lens type (rows of self.profile)
        self.profile, profile_row = ((analysis.profile, analysis.profile_row)
                                     if st.devignette else (None, None))
        # the tight blend, and the wider ones where some view reaches the rim (the corners
        # reach farthest); one geometry for all
        self._median_patch = float(np.median(self.used_patch))
        corner = float(np.hypot(*self.layout.offset_image(0, 0)))
        # a multi-focus MLA whose sharp lenses are too sparse: every view at the wider blend
        # (decided once per camera where a set-up gives it, as D' and q are)
        if least_reach is None:
            focus = self.patch.focus[self.layout.lens_index]
            least_reach = focus_reach(focus)
            if least_reach:
                log.info("%s: the lenses' mean focus weight is %.2f (under %.2f: fewer than "
                         "two of the three nearest lenses see the scene sharp): every view "
                         "takes the wider blend", source, float(focus.mean()), FOCUS_SPARSE)
        self._least_reach = int(least_reach)
        reaches = range(max(self._rim_reach(corner), self._least_reach) + 1)
        # each lens's blend weight: its focus (multi-focus MLAs) times its reliability
        # (a filled size weighs a tenth of a measured one)
        trust = reliability(self.patch.raw, self.patch.patch, self.patch.confident,
                            st.patch.step_px)
        self._blends = [st.render.for_reach(k) for k in reaches]
        # the trust averaged over the lattice (patchsize.lattice_mean): a measured lens
        # among filled ones no longer takes the blend over its whole tile or disc
        self._lens_weight = (self.patch.focus * lattice_mean(
            trust, self.grid.neighbours, st.render.trust_passes))[self.layout.lens_index]
        self._profile_row = (None if profile_row is None
                             else profile_row[self.layout.lens_index])
        self._plans: list[RenderPlan] | None = None  # the whole view's, made on first use
        self._reliable = reliability_map(self.layout,
                                         out_of_range(self.patch)[self.layout.lens_index])
        self._gray = None  # the analysis's; made again if asked for (125 MB at 31 MP)

    def plans_for_rows(self, rows: slice = slice(None)) -> list[RenderPlan]:
        """The render plans (one per blend, :func:`plenocal.convert.render.make_plans`)
        of output ``rows``."""
        return make_plans(self.layout, self.used_patch, self.safe.diameter_px, self._blends,
                          self._lens_weight, self.profile, self._profile_row, rows=rows)

    def blend_plan(self, rows: slice, blend: int, layout: ViewLayout | None = None
                   ) -> RenderPlan:
        """The plan of blend ``blend`` (:meth:`blend_of`) alone over output ``rows``: the
        same numbers as that entry of :meth:`plans_for_rows`, without the others' weights;
        ``layout``: another layout of the same lenses (the micro-image centres moved:
        :mod:`plenocal.convert.centring`), None for the shot's."""
        return make_plans(layout or self.layout, self.used_patch, self.safe.diameter_px,
                          [self._blends[blend]], self._lens_weight, self.profile,
                          self._profile_row, rows=rows)[0]

    @property
    def render_source(self) -> tuple[np.ndarray, float]:
        """What the views sample (the frame's integers, prefiltered where
        ``convert.blend.prefilter`` is set) and the unit that brings it to [0, 1]."""
        return self._render_source, self._render_scale

    @property
    def plan(self) -> RenderPlan:
        """The whole view's plan of the tight blend (made once, on first use)."""
        return self._whole_plans()[0]

    def _whole_plans(self) -> list[RenderPlan]:
        if self._plans is None:
            self._plans = self.plans_for_rows()
        return self._plans

    @property
    def source_float(self) -> np.ndarray:
        """The image as float32 0..1 (made once, on first use: for the measures that take
        a float frame; the views sample the image's integers)."""
        if self._source_float is None:
            self._source_float = to_unit_float(self._image, self.bits)
        return self._source_float

    @property
    def gray(self) -> np.ndarray:
        """The image in grey, float32 0..1 (made once: :func:`frame_gray`)."""
        if self._gray is None:
            self._gray = frame_gray(self._image, self.bits)
        return self._gray

    def _safe_diameter(self, decided: float | None, source: str) -> SafeDiameter:
        """``D'``: ``decided`` (the camera's), or per ``convert.safe_diameter``."""
        file_d = float(self.calib.safe_diameter)
        setting = self.settings.safe_diameter
        if decided is not None:
            return SafeDiameter(float(decided), None, file_d, "setup")
        if setting == "file":
            return SafeDiameter(file_d, None, file_d, "file")
        if setting != "auto":
            d = float(setting)
            if d > self.calib.diameter:
                raise ConvertError(f"convert.safe_diameter = {d:g} px is more than the "
                                   f"micro-image pitch D = {self.calib.diameter:.2f} px of "
                                   f"{self.calib.source}: lower it, or set it to auto")
            return SafeDiameter(d, None, file_d, "setting")
        safe = measure_safe_diameter(self.gray, self.grid)
        log.info("%s: safe diameter D' = %.2f px (%s; calib.xml's D - 2 lens_border = %.2f px)"
                 "%s", source, safe.diameter_px, safe.source, file_d,
                 f": {safe.note}" if safe.note else "")
        return safe

    def _border_cut(self, decided: BorderCut | None, source: str) -> BorderCut:
        """The border lenses left out: ``decided`` (the camera's), or per
        ``convert.border_cut`` (``auto``: measured in the safe disc of this image)."""
        if decided is not None:
            return decided
        if self.settings.border_cut == "off":
            return BorderCut()
        cut = measure_border_cut(self.gray, self.grid, self.safe.diameter_px)
        if cut.any:
            log.info("%s: %s", source, cut.summary())
        return cut

    def _measure(self, source: str, check_mla: bool, pool=None) -> ConvertAnalysis:
        """The image's MLA kind (where ``auto``; where set, checked with ``check_mla``),
        patch sizes and vignetting profiles; what does not wait for the kind runs on
        ``pool`` (an executor) beside the patch sizes. The profiles are measured whether
        or not the views are devignetted: the patch sizes are matched on devignetted
        blocks (:func:`plenocal.convert.patchsize.block_gains`)."""
        st = self.settings
        gray = self.gray
        pool = pool or Inline()
        # here, not on the pool: the matching waits for the profiles, and the pool's
        # worker is measuring the safe diameter meanwhile
        vignetting = lens_type_profiles(gray, self.grid)
        clipped = clipped_share(self._image)
        if clipped >= OVEREXPOSED_SHARE:
            note = (f"{100 * clipped:.0f}% of the frame is clipped at full scale: the views "
                    "carry no detail there, and the patch sizes, the grid check and the "
                    "border cut have less to go on (the real frames of shared/real clip "
                    "4 % at most); expose without clipping where you can")
            log.warning("%s: %s", source, note)
            self.warnings.append(f"{source}: {note}")
        note = mosaic_warning(self._image)  # a raw readout read as grey (convert.bayer)
        if note is not None:
            log.warning("%s: %s", source, note)
            self.warnings.append(f"{source}: {note}")
        mla, scores, check = st.mla, None, None
        if st.mla == "auto":
            # the pool's worker is done with the safe diameter by now (it takes as long
            # as the profiles): the two ways are matched side by side
            mla, k, g = detect_mla_kind(gray, self.grid, st.patch, threads=self._threads)
            scores = {"keplerian": k, "galilean": g}
            log.info("%s: MLA kind from the image: %s (mean best ZNCC: points moving towards "
                     "the neighbour %.3f, away %.3f)", source, mla, k, g)
            note = mla_undecided(mla, scores)
            if note:
                log.warning("%s: %s", source, note)
                self.warnings.append(f"{source}: {note}")
        elif check_mla:
            check = pool.submit(detect_mla_kind, gray, self.grid, st.patch)
        patch = estimate_patch_size(gray, self.grid, st.patch, mla=mla, threads=self._threads,
                                    vignetting=vignetting)
        for note in patch.warnings:
            log.warning("%s: %s", source, note)
        if check is not None:
            _, k, g = check.result()
            self.match_scores = {"keplerian": k, "galilean": g}
            note = mla_contradiction(st.mla, self.match_scores)
            if note:
                log.warning("%s: %s", source, note)
                self.warnings.append(f"{source}: {note}")
        profile, row = vignetting if st.devignette else (None, None)
        return ConvertAnalysis(mla, scores, patch, profile, row)

    @property
    def least_reach(self) -> int:
        """The least blend reach every view takes (:func:`focus_reach`, or the set-up's)."""
        return self._least_reach

    def _rim_reach(self, offset: float) -> int:
        return rim_reach(offset, self._median_patch, self.safe.diameter_px)

    def blend_of(self, r: int, c: int) -> int:
        """Which of :meth:`plans_for_rows`' plans view (r, c) is rendered with: the tight
        one, or a wider one where the view's patches reach past the micro image
        (:func:`rim_reach`, median patch) or the shot's sharp lenses are sparse
        (:func:`focus_reach`)."""
        reach = max(self._rim_reach(float(np.hypot(*self.layout.offset_image(r, c)))),
                    self._least_reach)
        return min(reach, len(self._blends) - 1)

    def plan_for(self, r: int, c: int) -> RenderPlan:
        """The whole view's render plan of view (r, c) (:meth:`blend_of`)."""
        return self._whole_plans()[self.blend_of(r, c)]

    def render_views(self, names: Sequence[str], dtype: type = np.uint8, threads: int = 1
                     ) -> dict[str, np.ndarray]:
        """The views ``names`` (``"r_c"``) as RGB (layout.height x layout.width x 3) of
        ``dtype``: uint8 (0-255) or uint16 (0-65535, for the video formats above 8 bits),
        each softened where the patch sizes were filled
        (:func:`plenocal.convert.render.soften_unreliable`), after its pixels that no
        micro image sees from inside its rim are filled from their neighbours
        (:func:`plenocal.convert.holes.fill_unsupported`).

        Rendered band by band (:data:`PLAN_ROWS` output rows): each band's geometry is
        planned once for every view (so that the plans stay a few MB on any sensor) and
        its views rendered while their part of the frame is in the cache. ``threads``
        bands at a time (OpenCV and numpy let go of the GIL): every band is computed
        alone, so the views are the same bytes with any number of threads."""
        if dtype not in (np.uint8, np.uint16):
            raise ValueError(f"views are uint8 or uint16, not {dtype}")
        H, W = self.layout.height, self.layout.width
        ch = 1 if self._render_source.ndim == 2 else self._render_source.shape[2]
        top = float(np.iinfo(dtype).max)
        todo = [(name, *parse_view(name)) for name in names]
        out = {name: np.empty((H, W, ch), dtype) for name, _, _ in todo}
        # where pixels lack support: name -> [(row, column, confidence box)] (holes.weak_box)
        weak: dict[str, list[tuple[int, int, Confidence]]] = {name: [] for name, _, _ in todo}

        def band(rows: slice) -> None:
            plans = self.plans_for_rows(rows)
            support = np.empty((rows.stop - rows.start, W), np.float32)
            for name, r, c in todo:
                v = render_view(plans[self.blend_of(r, c)], self._render_source, r, c,
                                self._render_scale, support=support)
                out[name][rows] = _round_to(v, top, dtype)
                box = weak_box(support)
                if box is not None:
                    weak[name].append((rows.start + box[0], box[1], box[2]))

        def finish(name: str) -> None:
            if weak[name]:
                fill_unsupported(out[name], weak[name])
            sigma = self.settings.render.unreliable_blur * self.layout.tile
            v = soften_unreliable(out[name], self._reliable, sigma)
            out[name] = np.repeat(v, 3, axis=2) if v.shape[2] == 1 else v

        bands = [slice(y, min(y + PLAN_ROWS, H)) for y in range(0, H, PLAN_ROWS)]
        with opencv_threads(1 if threads > 1 else None):
            run_all(band, bands, threads)
            run_all(finish, list(out), threads)
        return out

    def view(self, r: int, c: int) -> np.ndarray:
        """View (r, c) as uint8 RGB (layout.height x layout.width x 3)."""
        name = f"{r}_{c}"
        return self.render_views([name])[name]

    def view_groups(self, names: Sequence[str] | None = None, threads: int = 1,
                    budget_bytes: int | None = None, dtype: type = np.uint8):
        """Yield the views ``names`` (default: all, row-major) as dicts name -> RGB of
        ``dtype`` (:meth:`render_views`), rendered together in as few groups as keep each
        group's views within ``budget_bytes`` (default :data:`VIEW_BUDGET_BYTES`): one group
        of uint8 views on 12-MP frames; on a 31-MP frame with large patches 25 views take
        615 MB (uint8) or 1.2 GB (uint16)."""
        names = list(view_names(self.n_views) if names is None else names)
        budget = VIEW_BUDGET_BYTES if budget_bytes is None else budget_bytes
        per_view = self.layout.height * self.layout.width * 3 * np.dtype(dtype).itemsize
        size = max(1, min(len(names), budget // max(per_view, 1)))
        groups = -(-len(names) // size)
        size = -(-len(names) // groups)  # even groups
        for a in range(0, len(names), size):
            yield self.render_views(names[a:a + size], dtype, threads=threads)

    def views(self, threads: int = 1):
        """Yield (name, uint8 RGB) for every view, row-major (:meth:`view_groups`)."""
        for group in self.view_groups(threads=threads):
            yield from group.items()

    def disparity(self) -> dict:
        out = disparity_record(self.layout, self.calib, self.used_patch,
                                self.patch.confident[self.layout.lens_index],
                                self.settings.percentiles, self.warnings,
                                safe_diameter=self.safe.diameter_px)
        out["safe_diameter"] = self.safe.to_dict()
        out["border_cut"] = self.border_cut.to_dict()
        out["mla_source"] = "image" if self.mla_scores is not None else "setting"
        if self.mla_scores is not None:
            out["mla_match_scores"] = dict(self.mla_scores)
        if self.grid_check is not None:
            out["grid_check"] = dict(self.grid_check)
        out["tile_source"] = "auto" if self.settings.tile_size == "auto" else "setting"
        out["bit_depth"] = self.bits
        return out

    def patch_picture(self) -> np.ndarray:
        return patch_size_picture(self.layout, self.used_patch,
                                  self.patch.confident[self.layout.lens_index])


#: output rows planned and rendered at a time by :meth:`ShotConversion.render_views`
PLAN_ROWS = 64
#: the most bytes of views :meth:`ShotConversion.view_groups` renders at once (each group
#: plans the views' geometry again: 0.3 s on Boys2, one group there)
VIEW_BUDGET_BYTES = 256 << 20
#: rows of a colour frame turned grey at a time
GRAY_ROWS = 256


def frame_gray(image: np.ndarray, bits: int) -> np.ndarray:
    """``image`` (8- or 16-bit, grey or RGB, holding ``bits`` bits) in grey, float32 0..1,
    what every measurement of a frame reads (:class:`ShotConversion`, the video path's
    later frames). A colour frame is done in bands of :data:`GRAY_ROWS` rows: the same
    numbers as from the whole float frame, without a float copy of it (145 MB at 12 MP)."""
    if image.ndim == 2:
        return to_gray(to_unit_float(image, bits))
    gray = np.empty(image.shape[:2], np.float32)
    for y in range(0, image.shape[0], GRAY_ROWS):
        band = slice(y, y + GRAY_ROWS)
        gray[band] = to_gray(to_unit_float(image[band], bits))
    return gray


def _round_to(v: np.ndarray, top: float, dtype: type) -> np.ndarray:
    """round(top x v) saturated to ``dtype`` (v >= 0: samples and weights are)."""
    if dtype == np.uint8:  # one pass
        return cv2.convertScaleAbs(v, alpha=top).reshape(v.shape)
    v = np.multiply(v, np.float32(top))
    np.rint(v, out=v)
    np.clip(v, 0.0, top, out=v)
    return v.astype(dtype)


def _label(img: np.ndarray, text: str, org: tuple[int, int], scale: float = 0.4) -> None:
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, (255, 255, 255), 1,
                cv2.LINE_AA)


#: the patch-size picture's colour range: these percentiles of the map, so that a few
#: outlying lenses (one wrong match) do not squeeze every other lens into a few colours
PICTURE_PERCENTILES = (1.0, 99.0)


def colour_range(patch: np.ndarray) -> tuple[float, float]:
    """The patch-size picture's colour range: :data:`PICTURE_PERCENTILES` of ``patch``
    (lenses beyond it take the end colours; the bar marks the ends ``<`` and ``>``)."""
    lo, hi = np.percentile(patch, PICTURE_PERCENTILES)
    return float(lo), float(hi)


def patch_size_picture(layout: ViewLayout, patch: np.ndarray, confident: np.ndarray
                       ) -> np.ndarray:
    """The patch-size map at tile resolution (viridis, each lens its tile: the output
    pixels nearest its tile centre, a hexagon; lenses filled from neighbours drawn darker)
    with a colour bar over :func:`colour_range`; uint8 RGB."""
    from plenocal.viewgeom import nearest_slots  # noqa: PLC0415

    idx = np.empty((layout.height, layout.width), np.int32)
    for y in range(0, layout.height, PLAN_ROWS):  # in bands: a few MB on any sensor
        rows = slice(y, min(y + PLAN_ROWS, layout.height))
        idx[rows] = nearest_slots(layout, keep=1, rows=rows)[0][0]
    lo, hi = colour_range(patch)
    span = max(hi - lo, 1e-6)
    level = np.clip(np.rint((patch - lo) / span * 255), 0, 255).astype(np.uint8)
    lut = cv2.applyColorMap(np.arange(256, dtype=np.uint8)[:, None], cv2.COLORMAP_VIRIDIS)[:, 0]
    rgb_lens = lut[level][:, ::-1].astype(np.float32)
    rgb_lens[~confident] *= 0.55
    # each lens's colour, then black as the last entry: a pixel without a lens (-1) takes
    # it, as take reads -1 (one gather for the whole view, not a masked one)
    palette = np.concatenate([rgb_lens.astype(np.uint8), np.zeros((1, 3), np.uint8)])
    img = palette.take(idx, axis=0)
    # colour bar on the right
    h = img.shape[0]
    bar_w, pad, text_w = 16, 8, 70
    panel = np.zeros((h, pad + bar_w + text_w, 3), dtype=np.uint8)
    # the bar's top label (its baseline 4 px below the bar's top) clear of the title's
    # descenders ("[p]" reach 3 px below its baseline, 14)
    top, bottom = 26, max(h - 20, 27)
    ramp = np.linspace(255, 0, bottom - top).astype(np.uint8)
    panel[top:bottom, pad:pad + bar_w] = lut[ramp][:, None, ::-1]
    below, above = bool(np.any(patch < lo)), bool(np.any(patch > hi))
    for frac, mark in ((0.0, "<" if below else ""), (0.5, ""), (1.0, ">" if above else "")):
        y = int(round(bottom - 1 - frac * (bottom - top - 1)))
        _label(panel, f"{mark}{lo + frac * span:.2f}", (pad + bar_w + 4, y + 4))
    _label(panel, "P [px]", (pad, 14))
    return np.ascontiguousarray(np.concatenate([img, panel], axis=1))


def convert_files(lenslet: str | Path, calib_xml: str | Path, camera_yaml: str | Path | None,
                  n_views: int, settings: ConvertSettings | None = None,
                  setup_json: str | Path | None = None,
                  analysis: ConvertAnalysis | None = None, threads: int = 1,
                  grid_foreign: str = _CONVERT["grid_foreign"]) -> ShotConversion:
    """Read the inputs of one shot (with every check) and prepare its conversion.

    ``setup_json``: the camera's ``convert_setup.json`` (rule ``convert_setup``): its MLA
    kind, tile and grid are used. Without it (one image, the command line) the grid is
    checked and chosen here per ``settings.grid``, and ``auto`` settings are read from
    this image; a grid the check finds foreign (another camera's calib.xml) stops here
    as it stops rule ``convert_setup``, unless ``grid_foreign`` is ``warn``
    (``convert.grid_foreign``; :func:`plenocal.convert.setup.foreign_grid_error`).
    ``analysis``: the shot's measurements made before (:mod:`plenocal.convert.analysis`;
    rule ``convert_views``). ``threads``: see :class:`ShotConversion`."""
    from plenocal.convert.renderkernels import warm_in_background  # noqa: PLC0415
    from plenocal.convert.setup import (  # noqa: PLC0415
        centred_where_unverified,
        check_and_grid,
        foreign_grid_error,
        read_setup,
        unmatched_frame_error,
    )

    settings = settings or ConvertSettings()
    warm_in_background()  # numba's set-up while the frame is decoded
    sensor = read_sensor_size(camera_yaml) if camera_yaml is not None else None
    image = load_lenslet(lenslet, sensor, settings.bayer)
    calib = load_calib(calib_xml)
    H, W = image.shape[:2]
    if setup_json is not None:
        setup = read_setup(setup_json)
        setup.check_frame(W, H, str(lenslet), calib)
        shot = ShotConversion(image, calib, n_views, setup.settings(settings),
                              source=str(lenslet), grid=setup.grid(calib, W, H),
                              analysis=analysis, check_mla=False,
                              safe_diameter=setup.safe_diameter_px, threads=threads,
                              least_reach=setup.least_reach, border_cut=setup.border_cut)
        shot.grid_check = setup.grid_check
        return shot
    grid, check = check_and_grid(image, calib, settings.grid)
    log.info("%s", check.summary())
    error = foreign_grid_error(check, calib.source, str(lenslet), grid_foreign, image=image)
    if error is not None:
        raise ConvertError(error)
    shot = ShotConversion(image, calib, n_views, settings, source=str(lenslet), grid=grid,
                          analysis=analysis, threads=threads)
    error = unmatched_frame_error(check, shot.match_scores, calib.source, str(lenslet),
                                  grid_foreign, image=image)
    if error is not None:
        raise ConvertError(error)
    grid, shot, _ = centred_where_unverified(image, calib, n_views, settings, str(lenslet),
                                             grid, check, shot, threads)
    for note in check.warnings:  # after the centring, which may change what they say
        log.warning("%s: %s", lenslet, note)
    shot.grid_check = check.to_dict()
    shot.warnings = [f"{lenslet}: {w}" for w in check.warnings] + shot.warnings
    return shot
