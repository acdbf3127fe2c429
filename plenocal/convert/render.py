"""Subaperture view rendering: tiles of every microlens, blended with a fade-out weight.

Output pixel ``u`` of view (r, c) takes, from each of its candidate lenses ``i`` (the
lens whose tile centre is nearest and its lattice neighbours,
:func:`plenocal.viewgeom.nearest_lenses`), the sensor sample at
``m_i + R (q_rc - (u - o_i) P_i / T)`` (:meth:`ViewLayout.sensor_points`, bilinear,
``cv2.remap``), and blends them with the weight::

    w_i = max(0, 1 - (d_i / R_f)^2)^2  *  rim(|x_i|)

``d_i`` is the distance from ``u`` to the tile centre ``o_i`` in tile units (the
fade-out: no seams between tiles), ``x_i`` the sampled point's offset from the
micro-image centre and ``rim`` a ramp from 1 inside the micro image to 0 at
``D'/2 - rim_px`` (so that corner views, whose patches reach the rim of the micro
image, take those pixels from a neighbour lens that sees the point closer to its
centre), times ``(1 - (|x_i| / (D'/2))^2)^centre_power`` (the same preference,
smooth: real microlenses blur and distort towards their rim; power 1 lowers the
corner views' blend disagreement of the TSPC frames by 1-11 %, and on the simulator
raises corner views by 0.1-1.6 dB for 0.03-0.05 dB less in the central views). Multi-focus MLAs also
multiply by each lens's focus weight (:func:`plenocal.convert.patchsize.focus_weights`),
and every lens by its trust (:func:`plenocal.convert.patchsize.reliability`, averaged over
the lattice: ``trust_passes``).
A tiny floor keeps the nearest lens when every candidate is at the rim; a pixel whose
in-rim weight (:func:`pixel_support`) is that small is then taken from its supported
neighbours (:mod:`plenocal.convert.holes`). Each sample is divided by the micro images'
vignetting profile at its radius (:mod:`plenocal.convert.vignetting`).

The radial weight and gain are tables over the squared radius (:data:`RADIAL_LEVELS`
entries: no square root per sample; the steps are finest at the rim, where the weight
falls fastest), and the samples are read through OpenCV's fixed-point maps (positions to
1/32 px, as :func:`cv2.convertMaps` rounds them; the interpolation 1.5x as fast as from
float maps, whose conversion OpenCV 5 no longer does inside the remap). The weights, the
maps and the blend are compiled passes (:mod:`plenocal.convert.renderkernels`), the same
bits as the numpy and OpenCV calls of :func:`view_weights` and :func:`slot_samples`, which
stay for the measures that read a slot's samples on their own
(:mod:`plenocal.convert.centring`, :func:`blend_disagreement`).

The frame the samples are read from may be prefiltered once against bilinear
interpolation's blur (``convert.blend.prefilter``, :mod:`plenocal.convert.prefilter`: off
in the config, which the workflow's views take; on in ``plenocal convert``).

Everything that does not depend on the view is computed once per shot
(:class:`RenderPlan`): the candidate lenses, their tile weights and the sampling
positions of the central view; view (r, c) only adds the constant ``R q_rc``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from plenocal.config import stage_defaults
from plenocal.convert.holes import box_of
from plenocal.convert.vignetting import gains
from plenocal.viewgeom import ViewLayout, candidates_within, nearest_lenses, nearest_slots

_FLOOR = 1e-3
#: entries of the radial tables, evenly spaced in the squared radius from 0 to
#: :data:`RADIAL_BEYOND_PX` past the rim's end (the last entry for everything farther):
#: steps of 0.02-0.06 px of radius at the rim on micro images of 16-50 px (the tables were
#: every 0.05 px of radius before)
RADIAL_LEVELS = 256
RADIAL_BEYOND_PX = 2.0


_BLEND = stage_defaults("convert.blend")


@dataclass(frozen=True)
class RenderSettings:
    """The view renderer's blend; defaults: ``convert.blend`` of config.schema.yaml."""
    fade_radius: float = _BLEND["fade_radius"]  # R_f, tile units
    rim_px: float = _BLEND["rim_px"]  # samples closer than this to D'/2 get no weight
    rim_ramp_px: float = _BLEND["rim_ramp_px"]  # width of the rim ramp
    slots: int = _BLEND["slots"]  # lenses blended per output pixel (a 4th: >= 0.87 tile away)
    centre_power: float = _BLEND["centre_power"]  # weight (1 - (rho / (D'/2))^2)^power
    # views whose patches reach past the micro image (rim_reach 1): a wide blend
    wide_slots: int = _BLEND["wide_slots"]
    wide_fade_radius: float = _BLEND["wide_fade_radius"]
    wide_centre_power: float = _BLEND["wide_centre_power"]
    # views whose patches' sides pass the micro image (rim_reach 2): a wider one
    wider_slots: int = _BLEND["wider_slots"]
    wider_fade_radius: float = _BLEND["wider_fade_radius"]
    wider_centre_power: float = _BLEND["wider_centre_power"]
    # passes of the lattice mean over the lenses' trust (patchsize.lattice_mean); 0: each
    # lens its own (a measured lens among filled ones then weighs ten times each)
    trust_passes: int = _BLEND["trust_passes"]
    unreliable_blur: float = _BLEND["unreliable_blur"]  # tile units; 0: off
    prefilter: float = _BLEND["prefilter"]  # a of the frame's prefilter; 0: off

    def wide(self) -> RenderSettings:
        """The blend of the views whose patches reach past the micro image."""
        return replace(self, slots=max(self.slots, self.wide_slots),
                       fade_radius=max(self.fade_radius, self.wide_fade_radius),
                       centre_power=max(self.centre_power, self.wide_centre_power))

    def wider(self) -> RenderSettings:
        """The blend of the views whose patches' sides pass the micro image."""
        wide = self.wide()
        return replace(self, slots=max(wide.slots, self.wider_slots),
                       fade_radius=max(wide.fade_radius, self.wider_fade_radius),
                       centre_power=self.wider_centre_power)

    def for_reach(self, reach: int) -> RenderSettings:
        """The blend of a view of :func:`rim_reach` ``reach``."""
        return (self, self.wide(), self.wider())[reach]


def rim_reach(offset_px: float, patch_px: float, safe_diameter: float) -> int:
    """How far the patches of a view centred ``offset_px`` from the micro-image centre
    (``|q_rc|``) reach with a typical patch of ``patch_px`` (P): 0 - inside the micro
    image; 1 - the patch's far corner, ``|q_rc| + P / sqrt(2)``, past ``D'/2``; 2 - the
    middle of its far side, ``|q_rc| + P / 2``, past it too (a whole side of the patch
    outside: the corner views of frames with large patches).

    Past the rim every lens blended into an output pixel by the tight blend (the three
    nearest tiles) may sample its blurred, vignetted rim, and the views show the lens
    lattice (TSPC frames' corner views at 1, a faint mottling of flat areas at 2); a
    wider blend (more lenses, a wider fade, a stronger centre weight) lets each point come
    from a lens that sees it nearer its centre. It costs sharpness where no lens is at
    the rim (-0.45 dB on the simulator's central view) and a third of a view's time per
    extra lens, so each view takes the narrowest blend its reach allows."""
    half = safe_diameter / 2.0
    if offset_px + patch_px / 2.0 > half:
        return 2
    return int(offset_px + patch_px / math.sqrt(2.0) > half)


#: mean focus weight of a shot's lenses under which its sharp lenses are too sparse for
#: the tight and wide blends: fewer than two of the three tiles nearest a pixel weigh
FOCUS_SPARSE = 2.0 / 3.0


def focus_reach(focus: np.ndarray) -> int:
    """The least :func:`rim_reach` every view of a shot is blended at, from its used
    lenses' focus weights (:func:`plenocal.convert.patchsize.focus_weights`): 2, the wider
    blend, where their mean is under :data:`FOCUS_SPARSE`; else 0 (each view by its reach).

    A multi-focus MLA puts each lens type on every third lens, so the three tiles nearest
    any output pixel hold one lens of each type. Where the scene lies in two or more types'
    depth ranges, two or three of them weigh; where it lies in one type's range only (far
    content on a Raytrix camera: R42_klein_crop, virtual depth 5.5 against the ranges 1-3,
    2.8-4 and 3.8-100), the other two weigh the focus floor, and each pixel takes one lens.
    Every sharp lens then paints a region about sqrt 3 tiles wide from one micro image, in
    the off-centre views out to its rim: specks and hexagon fragments at the sub-lattice's
    pitch (R42's corner and edge views, issue 33). The wider blend (its fade radius 1.6
    tiles, 7 lenses) holds the nearest sharp lenses of that sub-lattice (the nearest within
    1 tile of any pixel, the next within 1.73). One type's MLA weighs every lens 1: 0."""
    f = np.asarray(focus, dtype=np.float64)
    return 2 if f.size and float(f.mean()) < FOCUS_SPARSE else 0


def reaches_rim(offset_px: float, patch_px: float, safe_diameter: float) -> bool:
    """Whether the view's patches reach past the micro image (:func:`rim_reach` >= 1)."""
    return rim_reach(offset_px, patch_px, safe_diameter) >= 1


@dataclass
class RenderPlan:
    """The per-shot geometry of output rows ``rows`` (every view's; all rows, or a band of
    them: :meth:`plenocal.convert.shot.ShotConversion.render_views` plans band by band
    so that the arrays stay small; h below is the band's height). The sampling positions
    and offsets of the central view (``map_x`` ... ``off_y``) are made from the slots'
    lenses when first asked for (the compiled renderer computes them per pixel:
    :mod:`plenocal.convert.renderkernels`)."""
    layout: ViewLayout
    lens: np.ndarray  # (K, h, W) int32 each slot's used lens, -1 where none
    tile_weight: np.ndarray  # (K, h, W) float32
    weight_table: np.ndarray  # (RADIAL_LEVELS,) radial weight (rim x centre + floor)
    gain_table: np.ndarray  # (T, RADIAL_LEVELS) 1 / vignetting profile per lens type
    radial_scale: float  # table entry per squared px of radius (radial_tables)
    lens_scale: np.ndarray  # (m,) float32 sign x P / T per used lens
    lens_row: np.ndarray  # (m,) int64 each used lens's row of gain_table
    # (4, m) float32 rows: each used lens's tile centre x, y and micro-image centre x, y
    centres: np.ndarray
    rows: slice = field(default_factory=lambda: slice(None))  # the output rows covered
    # (h, W) float32 the floor's share of a pixel's weight: floor x the slots' tile weights
    floor_weight: np.ndarray | None = None
    _maps: tuple[np.ndarray, ...] | None = field(default=None, repr=False)

    def _sampling(self) -> tuple[np.ndarray, ...]:
        """(map_x, map_y, off_x, off_y), each (K, h, W) float32: the central view's
        sensor samples (-1e4 where a slot has no lens) and their offsets from the
        micro-image centres, ``s (u - o_i) P_i / T`` (:meth:`ViewLayout.sensor_points`)."""
        if self._maps is None:
            lay = self.layout
            K, H, W = self.lens.shape
            f = np.float32
            ys = np.arange(lay.height, dtype=f)[self.rows][:, None]
            xs = np.arange(W, dtype=f)[None, :]
            tcx, tcy, lcx, lcy = self.centres
            maps = tuple(np.empty((K, H, W), f) for _ in range(4))
            map_x, map_y, off_x, off_y = maps
            for k in range(K):
                have = self.lens[k] >= 0
                li = np.where(have, self.lens[k], 0)
                sk = self.lens_scale.take(li)
                np.multiply(xs - tcx.take(li), sk, out=off_x[k])
                np.multiply(ys - tcy.take(li), sk, out=off_y[k])
                np.add(off_x[k], lcx.take(li), out=map_x[k])
                np.add(off_y[k], lcy.take(li), out=map_y[k])
                map_x[k][~have] = -1e4
                map_y[k][~have] = -1e4
            self._maps = maps
        return self._maps

    @property
    def map_x(self) -> np.ndarray:  # (K, h, W) float32 sensor x sampled, central view
        return self._sampling()[0]

    @property
    def map_y(self) -> np.ndarray:
        return self._sampling()[1]

    @property
    def off_x(self) -> np.ndarray:  # (K, h, W) offset from the micro-image centre
        return self._sampling()[2]

    @property
    def off_y(self) -> np.ndarray:
        return self._sampling()[3]

    @property
    def gain_base(self) -> np.ndarray | None:
        """(K, h, W) intp: RADIAL_LEVELS x the gain_table row of each slot's lens (T > 1)."""
        if len(self.gain_table) <= 1:
            return None
        return self.lens_row.take(np.maximum(self.lens, 0)) * RADIAL_LEVELS


def make_plan(layout: ViewLayout, patch: np.ndarray, safe_diameter: float,
              settings: RenderSettings | None = None, focus: np.ndarray | None = None,
              profile: np.ndarray | None = None,
              profile_row: np.ndarray | None = None) -> RenderPlan:
    """Precompute the per-shot geometry. ``patch``: (m,) patch size per used lens, in
    ``layout.lens_index`` order; ``focus``: (m,) focus weight per used lens (multi-focus
    MLAs: lenses that see their point blurred get less weight), None for all 1;
    ``profile``: the micro images' vignetting profile, (n,) or one row per lens type
    (T, n) with ``profile_row`` (m,) the row of each used lens
    (:func:`plenocal.convert.vignetting.lens_type_profiles`); None for no correction."""
    return make_plans(layout, patch, safe_diameter, [settings or RenderSettings()], focus,
                      profile, profile_row)[0]


def make_plans(layout: ViewLayout, patch: np.ndarray, safe_diameter: float,
               blends: list[RenderSettings], focus: np.ndarray | None = None,
               profile: np.ndarray | None = None,
               profile_row: np.ndarray | None = None,
               rows: slice = slice(None)) -> list[RenderPlan]:
    """One :class:`RenderPlan` per blend in ``blends``, sharing the geometry: the nearest
    tiles are found once for the most slots, and a blend of fewer slots takes the first
    (nearest) of them (views of the arrays, no copy). ``rows``: the output rows to plan
    (a slice with step 1; all by default); a band's plan holds the same numbers as those
    rows of the whole view's. See :func:`make_plan` for the other arguments."""
    patch = np.asarray(patch, dtype=np.float64)
    if patch.shape != (len(layout.lens_index),):
        raise ValueError(f"need one patch size per used lens ({len(layout.lens_index)}), "
                         f"got {patch.shape}")
    # every lens within the widest blend's radius is a candidate (a blend that missed one
    # with weight would change at the candidates' borders: a seam)
    idx, dist2 = nearest_slots(layout, keep=max(b.slots for b in blends),
                               k=candidates_within(max(b.fade_radius for b in blends)),
                               rows=rows)
    K = idx.shape[0]
    have = idx >= 0
    f = np.float32
    # the central view (q_rc = 0) samples m_i + s (u - o_i) P_i / T (ViewLayout.sensor_points)
    lens_scale = (layout.sign * patch / layout.tile).astype(f)
    centres = np.array([layout.tile_centres[:, 0], layout.tile_centres[:, 1],
                        layout.lens_centres[:, 0], layout.lens_centres[:, 1]], dtype=f)
    focus_w = None if focus is None else np.asarray(focus, dtype=f).take(np.maximum(idx, 0))
    lens_row = np.zeros(len(patch), np.int64)
    if profile is not None and np.ndim(profile) == 2 and len(profile) > 1:
        if profile_row is None or np.shape(profile_row) != patch.shape:
            raise ValueError("a profile per lens type needs profile_row, one row per used lens")
        lens_row = np.asarray(profile_row, dtype=np.int64)
    plans = []
    for blend in blends:
        k = min(blend.slots, K)
        R = blend.fade_radius
        wt = 1.0 - dist2[:k] * f(1.0 / (R * R))
        np.maximum(wt, f(0.0), out=wt)
        wt *= wt
        if focus_w is not None:
            wt *= focus_w[:k]
        wt[~have[:k]] = 0.0
        # the nearest lens always keeps a tiny weight (every pixel has a lens within 0.577)
        np.maximum(wt[0], np.where(have[0], f(_FLOOR), f(0.0)), out=wt[0])
        weight_table, gain_tab, radial_scale = radial_tables(safe_diameter, blend, profile)
        plans.append(RenderPlan(
            layout=layout, lens=idx[:k], tile_weight=wt, weight_table=weight_table,
            gain_table=gain_tab, radial_scale=radial_scale, lens_scale=lens_scale,
            centres=centres,
            lens_row=lens_row if len(gain_tab) > 1 else np.zeros(len(patch), np.int64),
            rows=rows, floor_weight=wt.sum(axis=0) * f(_FLOOR)))
    return plans


def radial_tables(safe_diameter: float, settings: RenderSettings,
                  profile: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, float]:
    """The sample's weight ``rim x (1 - (rho / (D'/2))^2)^centre_power + floor``
    (:data:`RADIAL_LEVELS`,) and its vignetting gain (T, :data:`RADIAL_LEVELS`), one row per
    row of ``profile``, at the squared radii ``rho^2 = j / scale`` (entry ``j``), and
    ``scale``: from the micro-image centre to :data:`RADIAL_BEYOND_PX` past the rim's end
    (the weight is the floor there, and the last entry holds for everything farther).
    A sample's entry is ``round(scale rho^2)`` (:func:`radial_entries`)."""
    rim_radius = safe_diameter / 2.0 - settings.rim_px
    end = max(rim_radius, 0.0) + RADIAL_BEYOND_PX
    scale = (RADIAL_LEVELS - 1) / (end * end)
    r = np.sqrt(np.arange(RADIAL_LEVELS) / scale)
    w = np.clip((rim_radius - r) / settings.rim_ramp_px, 0.0, 1.0)
    if settings.centre_power > 0:
        half = safe_diameter / 2.0
        w = w * np.clip(1.0 - (r / half) ** 2, 0.0, 1.0) ** settings.centre_power
    w = w + _FLOOR
    if profile is None:
        g = np.ones((1, len(r)))
    else:
        g = gains(np.atleast_2d(profile), r)
    return w.astype(np.float32), g.astype(np.float32), float(scale)


def radial_entries(off_x: np.ndarray, off_y: np.ndarray, o: np.ndarray, scale: float
                   ) -> np.ndarray:
    """uint8 radial-table entries (:func:`radial_tables`) of the samples whose offsets from
    their micro-image centres are ``(off_x, off_y) + o`` (float32 arrays of one shape):
    ``min(round(scale ((off_x + o_x)^2 + (off_y + o_y)^2)), RADIAL_LEVELS - 1)``, in numpy's
    IEEE operations (the same bits wherever the arrays sit)."""
    x = off_x + np.float32(o[0])
    y = off_y + np.float32(o[1])
    x *= x
    y *= y
    x += y
    x *= np.float32(scale)
    x += np.float32(0.5)
    np.minimum(x, np.float32(RADIAL_LEVELS - 1), out=x)
    return x.astype(np.uint8)


BAND_ROWS = 32  # rows rendered at a time: every per-pixel array of a band stays in cache


def view_weights(plan: RenderPlan, r: int, c: int, with_gain: bool = False,
                 rows: slice = slice(None), unit: float = 1.0,
                 support: np.ndarray | None = None) -> np.ndarray:
    """(K, h, W) normalised blend weights of view (r, c) over ``rows`` of the plan's
    arrays (all by default), times ``unit``; with ``with_gain`` each multiplied by its
    sample's vignetting gain (1 / micro-image profile). ``support``: an (h, W) float32
    array that receives each pixel's support (:func:`pixel_support`)."""
    o = plan.layout.offset_image(r, c)
    off_x, off_y, tile_weight = plan.off_x[:, rows], plan.off_y[:, rows], plan.tile_weight[:, rows]
    K, H, W = off_x.shape
    w = np.empty((K, H, W), np.float32)
    gain = np.empty((K, H, W), np.float32) if with_gain else None
    total = np.zeros((H, W), np.float32)
    for k in range(K):
        entry = radial_entries(off_x[k], off_y[k], o, plan.radial_scale)
        np.multiply(cv2.LUT(entry, plan.weight_table), tile_weight[k], out=w[k])
        total += w[k]
        if gain is not None:
            if plan.gain_base is None:  # one profile (or none): a LUT
                gain[k] = cv2.LUT(entry, plan.gain_table[0])
            else:  # a profile per lens type: the row of each sample's lens
                plan.gain_table.take(plan.gain_base[k, rows] + entry, out=gain[k], mode="clip")
    if support is not None:
        pixel_support(plan, total, rows, out=support)
    np.maximum(total, np.float32(1e-12), out=total)
    np.divide(np.float32(unit), total, out=total)
    w *= total
    if gain is not None:
        w *= gain
    return w


def slot_samples(plan: RenderPlan, source: np.ndarray, k: int, offset: np.ndarray,
                 rows: slice = slice(None)) -> np.ndarray:
    """Slot ``k``'s samples of ``source`` over the plan's ``rows`` for a view whose offset
    from the micro-image centres is ``offset`` (x, y) px (:meth:`ViewLayout.offset_image`):
    bilinear, at positions rounded to 1/32 px (OpenCV's fixed-point maps: the module
    docstring), the border replicated; ``source``'s type."""
    xy, frac = cv2.convertMaps(plan.map_x[k, rows] + np.float32(offset[0]),
                               plan.map_y[k, rows] + np.float32(offset[1]), cv2.CV_16SC2)
    return cv2.remap(source, xy, frac, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def render_view(plan: RenderPlan, source: np.ndarray, r: int, c: int,
                unit: float = 1.0, support: np.ndarray | None = None) -> np.ndarray:
    """View (r, c) over the plan's rows as float32 (h, W, C): ``unit`` times the units of
    ``source`` (a float32, or an 8- or 16-bit image: OpenCV interpolates integers 1.3-1.6x
    faster, reading a quarter or half the bytes; ``unit`` brings them to [0, 1]),
    corrected for the micro images' vignetting where the plan has a profile. Each slot's
    samples are read at positions rounded to 1/32 px (OpenCV's fixed-point maps; the
    module docstring). The weights and maps are made, and the samples blended, by
    compiled passes (:mod:`plenocal.convert.renderkernels`: the same bits as
    :func:`view_weights`, :func:`slot_samples` and ``cv2.accumulateProduct``). A
    four-channel source is no faster than three here: the samples' reads from the frame,
    not the interpolation, bound the remap (measured on Boxer: 3.09 against 3.10 s).
    ``support``: an (h, W) float32 array that receives each pixel's support
    (:func:`pixel_support`; :func:`plenocal.convert.holes.fill_unsupported` mends the
    pixels that have too little)."""
    from plenocal.convert.renderkernels import (  # noqa: PLC0415 (numba: 0.3 s to import)
        accumulate_slots,
        slot_weights_and_maps,
    )

    if source.dtype not in (np.uint8, np.uint16, np.float32):
        raise ValueError(f"views sample uint8, uint16 or float32 frames, not {source.dtype}")
    o = plan.layout.offset_image(r, c)
    K, H, W = plan.lens.shape
    ch = 1 if source.ndim == 2 else source.shape[2]
    f = np.float32
    w = np.empty((K, H, W), f)
    xy = np.empty((K, H, W, 2), np.int16)
    frac = np.empty((K, H, W), np.uint16)
    sup = np.empty((H, W), f) if support is None else support
    slot_weights_and_maps(plan.lens, plan.tile_weight, plan.floor_weight,
                          plan.rows.indices(plan.layout.height)[0], *_per_lens(plan),
                          plan.weight_table, plan.gain_table, f(plan.radial_scale),
                          f(o[0]), f(o[1]), f(unit), w, xy, frac, sup)
    samples = np.empty((K, H, W, ch), source.dtype)
    for k in range(K):
        cv2.remap(source, xy[k], frac[k], cv2.INTER_LINEAR, dst=samples[k].reshape(
            (H, W) if ch == 1 else (H, W, ch)), borderMode=cv2.BORDER_REPLICATE)
    out = np.zeros((H, W, ch), dtype=f)
    accumulate_slots(samples, w, out)
    return out


def _per_lens(plan: RenderPlan) -> tuple[np.ndarray, ...]:
    """(lens_scale, tcx, tcy, lcx, lcy, lens_row): the plan's per-lens values, float32
    (the row int64), for :func:`plenocal.convert.renderkernels.slot_weights_and_maps`."""
    return (plan.lens_scale, *plan.centres, plan.lens_row)


def pixel_support(plan: RenderPlan, total: np.ndarray, rows: slice = slice(None),
                  out: np.ndarray | None = None) -> np.ndarray:
    """Each output pixel's support: the blend's weight from samples inside the micro
    images' rims, ``sum_k tile_k x radial_k`` (the floor taken out of ``total``, the
    pixel's whole weight ``sum_k tile_k x (radial_k + floor)``, :func:`view_weights`).

    It is 0 where every lens that covers the pixel samples past its rim, its neighbours'
    light: along a view's edge, where the lens that would see the point nearer its centre
    lies off the sensor, the floor then keeps rim samples that show as notches
    (:func:`plenocal.convert.holes.fill_unsupported` mends them)."""
    return np.subtract(total, plan.floor_weight[rows], out=out)


def reliability_map(layout: ViewLayout, guessed: np.ndarray) -> np.ndarray:
    """(H, W) float32 in [0, 1]: 0 where the lens under an output pixel has a guessed
    patch size (``guessed`` (m,) bool per used lens:
    :func:`plenocal.convert.patchsize.out_of_range`), else 1, smoothed over half a tile
    so that the change is gradual."""
    idx, _ = nearest_lenses(layout, k=1)
    idx = idx[..., 0]
    bad = np.asarray(guessed, dtype=bool)[np.maximum(idx, 0)] & (idx >= 0)
    return cv2.GaussianBlur((~bad).astype(np.float32), (0, 0), 0.5 * layout.tile)


def _lowpass(img: np.ndarray, sigma_px: float) -> np.ndarray:
    """``img`` (h, w[, C]) blurred by a Gaussian of ``sigma_px``: on the image shrunk by
    ``f = floor(sigma / 2)`` (area averages), where the Gaussian's sigma is 2-4 px, and
    brought back (bilinear); a low-pass either way, to the eye the same. A Boys2-sized view
    (sigma 6.5 px, a quarter tile): 19 ms at full scale, 7 ms shrunk by 3. Views whose
    sigma is under 4 px (the simulator's tiles of 7-8 px) are blurred at full scale. The
    shape of ``img``."""
    h, w = img.shape[:2]
    f = max(1, int(sigma_px // 2))
    small = (img if f == 1 else
             cv2.resize(img, (max(1, w // f), max(1, h // f)), interpolation=cv2.INTER_AREA))
    small = cv2.GaussianBlur(small, (0, 0), sigma_px / f)
    if f > 1:
        small = cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR)
    return small.reshape(img.shape)


#: rows of a view blended with its blur at a time (:func:`soften_unreliable`; a multiple of 64)
SOFTEN_ROWS = 256


def soften_unreliable(view: np.ndarray, rmap: np.ndarray, sigma_px: float) -> np.ndarray:
    """``view`` (H, W, C; uint8, uint16 or float32) blended with its Gaussian blur
    (``sigma_px``) where ``rmap`` (:func:`reliability_map`) is below 1:
    ``r view + (1 - r) blur``, rounded for integers; in place (pixels where ``rmap`` is 1
    are not touched), and returned. Only the box around the pixels to soften is blurred,
    with a margin of the kernel's reach (four sigmas): a view whose guessed lenses lie in
    one part of it blurs that part (on the real frames they are scattered, and the box is
    most of the view)."""
    box = box_of(rmap < 1.0 - 1e-6) if sigma_px > 0 else None
    if box is None:
        return view
    h, w = view.shape[:2]
    m = int(math.ceil(4.0 * sigma_px)) + 2
    ys, xs = box
    py = slice(max(0, ys.start - m), min(h, ys.stop + m))  # the box and the kernel's reach
    px = slice(max(0, xs.start - m), min(w, xs.stop + m))
    blurred = _lowpass(np.ascontiguousarray(view[py, px]), sigma_px)[
        ys.start - py.start:ys.stop - py.start, xs.start - px.start:xs.stop - px.start]
    # in strips of SOFTEN_ROWS rows (a whole blend's weights and result are 44 MB on a
    # 31-MP frame's filled view); a multiple of 64 rows starts every strip on a multiple
    # of OpenCV's vector width, so the strips give the whole blend's bits
    for r0 in range(ys.start, ys.stop, SOFTEN_ROWS):
        rows = slice(r0, min(r0 + SOFTEN_ROWS, ys.stop))
        part = np.ascontiguousarray(view[rows, xs])
        r = np.ascontiguousarray(rmap[rows, xs], dtype=np.float32)
        soft = np.ascontiguousarray(blurred[r0 - ys.start:rows.stop - ys.start])
        if view.dtype == np.uint16:  # cv2.blendLinear takes 8-bit and float images: float32
            # (a 1574 x 1190 view: 44 ms, against 60-90 ms for the products channel by channel)
            mixed = cv2.blendLinear(part.astype(np.float32), soft.astype(np.float32), r, 1.0 - r)
            np.rint(mixed, out=mixed)
            view[rows, xs] = mixed.astype(np.uint16).reshape(part.shape)
        else:
            view[rows, xs] = cv2.blendLinear(part, soft, r, 1.0 - r).reshape(part.shape)
    return view


def blend_disagreement(plan: RenderPlan, source: np.ndarray, r: int, c: int) -> float:
    """Mosaic / doubled-edge measure of view (r, c): how much the lenses blended into each
    output pixel disagree.

    Where patch sizes are right, every lens that covers an output pixel sees the same
    scene point there and the blend only averages noise; where they are wrong, the tiles
    show differently scaled content (a mosaic of blocks) and the blend doubles edges.
    Returns the weighted mean absolute deviation of the lenses' grey samples from the
    blended grey value, over pixels blended from at least two lenses (second weight >=
    0.2), divided by the mean absolute fine detail of the view (grey minus its Gaussian
    blur, sigma 1 tile): ~0.1-0.3 for clean views, about 1 for a mosaic."""
    grey = source if source.ndim == 2 else cv2.cvtColor(source, cv2.COLOR_RGB2GRAY)
    o = plan.layout.offset_image(r, c)
    w = view_weights(plan, r, c)
    wg = view_weights(plan, r, c, with_gain=True)
    samples = np.stack([cv2.remap(grey, plan.map_x[k] + np.float32(o[0]),
                                  plan.map_y[k] + np.float32(o[1]), cv2.INTER_LINEAR,
                                  borderMode=cv2.BORDER_REPLICATE) for k in range(w.shape[0])])
    samples = samples * (wg / np.maximum(w, 1e-12))  # vignetting-corrected
    blended = (samples * w).sum(axis=0)
    dev = (np.abs(samples - blended[None]) * w).sum(axis=0)
    two = np.sort(w, axis=0)[-2] >= 0.2 if w.shape[0] > 1 else np.zeros(blended.shape, bool)
    T = plan.layout.tile
    b = max(int(T), 1)
    inner = np.zeros(blended.shape, bool)
    inner[b:-b, b:-b] = True
    detail = np.abs(blended - cv2.GaussianBlur(blended, (0, 0), float(T)))[inner].mean()
    sel = two & inner
    if not sel.any() or detail <= 0:
        return 0.0
    return float(dev[sel].mean() / detail)
