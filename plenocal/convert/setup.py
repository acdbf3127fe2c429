"""What the converter decides once per camera, for every shot of a dataset.

A camera array is one camera model: its MLA kind, its microlens grid and the size of its
views are the same for every shot. Deciding them per shot would let two shots of one
array come out with different view sizes (registration A shares one pinhole camera
among all central views) or read the MLA kind differently. Rule ``convert_setup``
decides them on one shot (the central array shot) and writes ``convert_setup.json``;
rule ``convert`` applies it to every shot, and the ground truth of a synthetic dataset
reads the tile from it (the views' geometry must be known before any render).

Decided here, from ``convert`` settings that may say ``auto``:

* ``mla``: ``keplerian`` / ``galilean``, read from the image by matching both ways
  (:func:`plenocal.convert.patchsize.detect_mla_kind`) where the setting is ``auto``;
* ``tile``: output pixels per lens pitch, ``ceil(upsample x median patch size)`` where
  ``tile_size`` is ``auto`` (:func:`plenocal.convert.shot.resolve_tile`);
* ``safe_diameter_px`` (``D'``) and with it the view spacing ``q_px``: measured on the
  image where ``safe_diameter`` is ``auto`` (:mod:`plenocal.convert.safediameter`: where
  the micro images carry their own light, not their neighbours'); registration B and the
  ground truth read ``q`` from the shots' ``disparity.json`` and from here;
* the grid: the calib.xml grid checked against the micro images
  (:func:`plenocal.convert.gridcheck.check_grid`) and refined where ``convert.grid``
  says so (``refine``, or ``auto`` past the drift bar of :mod:`.gridcheck`);
* ``border_cut``: the border lens rows whose micro images the main lens cuts, left out
  of every shot's views where ``border_cut`` is ``auto``
  (:mod:`plenocal.convert.bordercut`);
* ``least_reach``: 2 where the shot's lenses' mean focus weight says a multi-focus MLA
  sees the scene sharp through one lens type only, and every view then takes the wider
  blend (:func:`plenocal.convert.render.focus_reach`); 0 otherwise. Per camera, because a
  hand-held shot nearer the scene reads other types' ranges.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from plenocal.artifacts.stage_warnings import WARNINGS_KEY, warning_list, warnings_of
from plenocal.config import stage_defaults
from plenocal.convert.bordercut import BorderCut
from plenocal.convert.centring import CentringFit, measure_centring, shifted_grid
from plenocal.convert.errors import ConvertError
from plenocal.convert.gridcheck import (
    GRID_MODES,
    UNVERIFIED_USE,
    GridCheck,
    grid_for_mode,
)
from plenocal.convert.levels import OVEREXPOSED_SHARE, clipped_share
from plenocal.convert.shot import ConvertSettings, ShotConversion, build_grid, mla_contradiction
from plenocal.grid import MicrolensGrid
from plenocal.io.files import read_json, write_json
from plenocal.io.raytrix import RayCalib
from plenocal.optics import view_spacing
from plenocal.rounding import round_floats
from plenocal.viewgeom import MLA_KINDS

# 2: safe_diameter_px, q_px and the safe-diameter measure; 3: pitch_px; 4: least_reach;
# 5: border_cut
FORMAT_VERSION = 5
LATTICE_DIGITS = 8
log = logging.getLogger("plenocal.convert")


@dataclass(frozen=True)
class ConverterSetup:
    """The per-camera decisions (see the module docstring); ``lattice`` is the grid's
    (origin (2,), A (2, 2) columns) where ``refined`` (the lattice fitted to the image, or
    the file's moved onto the centres the corner views agree on: ``grid_check`` says which,
    :func:`centring_for`), else None.
    ``safe_diameter_px`` / ``q_px``: ``D'`` and the view spacing every shot is cut with
    (None: per the settings, as without a set-up); ``safe_diameter_measure``: how ``D'`` was
    found (:meth:`plenocal.convert.safediameter.SafeDiameter.to_dict`)."""

    mla: str
    tile: int
    grid_mode: str
    refined: bool
    lattice: tuple[tuple[float, float], tuple[tuple[float, float], tuple[float, float]]] | None
    decided_on: str
    mla_source: str  # "image" or "setting"
    tile_source: str  # "auto" or "setting"
    mla_match_scores: dict[str, float] | None
    grid_check: dict
    warnings: tuple[str, ...] = ()
    safe_diameter_px: float | None = None
    q_px: float | None = None
    safe_diameter_measure: dict | None = None
    # the refined lattice's micro-image pitch (its grid's diameter; None: not refined)
    pitch_px: float | None = None
    # the least blend reach of every view (plenocal.convert.render.focus_reach: 2 where the
    # decided shot's sharp lenses are sparse, else 0)
    least_reach: int = 0
    # the border lenses the main lens cuts, left out of every shot's views
    # (plenocal.convert.bordercut; none where convert.border_cut is off)
    border_cut: BorderCut = dataclasses.field(default_factory=BorderCut)
    # the file it was read from, for messages (not written: :meth:`to_dict`)
    source: str = dataclasses.field(default="", compare=False, repr=False)

    def __post_init__(self) -> None:
        """ConvertError naming the set-up and the key where a decision is out of its
        range (a hand-edited file): a negative D' or spacing would give flat views."""
        where = self.source or "convert_setup.json"
        remedy = ("make the set-up again (rule convert_setup, or plenocal convert without "
                  "--setup), or edit the key back")
        bad = None
        if self.mla not in MLA_KINDS:
            bad = ("mla", self.mla, f"one of {', '.join(MLA_KINDS)}")
        elif self.tile < 2:
            bad = ("tile", self.tile, "a whole number >= 2")
        elif self.least_reach < 0:
            bad = ("least_reach", self.least_reach, ">= 0")
        else:
            for key in ("safe_diameter_px", "q_px", "pitch_px"):
                value = getattr(self, key)
                if value is not None and not (np.isfinite(value) and value > 0):
                    bad = (key, value, "a number > 0, or null")
                    break
        if bad is None and self.lattice is not None and not np.isfinite(
                np.array([self.lattice[0], *self.lattice[1]], dtype=float)).all():
            bad = ("lattice", self.lattice, "finite numbers")
        if bad is not None:
            key, value, want = bad
            raise ConvertError(f"{where}: {key} = {value!r}: {want}; {remedy}")

    def check_frame(self, width: int, height: int, frame: str, calib: RayCalib) -> None:
        """ConvertError where ``frame`` (``width`` x ``height``) is not of the size the
        set-up was decided on (``grid_check``'s ``width`` and ``height``): its grid, D' and
        tile belong to that sensor readout, and another size, a crop or another camera,
        converts into a mosaic of wrong lenses without a word. Nor may its D' exceed the
        micro-image diameter of ``calib``."""
        d = self.safe_diameter_px
        if d is not None and d > calib.diameter + 1e-6:
            raise ConvertError(
                f"{self.source or 'the set-up'}: safe_diameter_px = {d:g}, wider than the "
                f"micro images of {calib.source} (D = {calib.diameter:g} px); the set-up "
                "belongs to another camera, or was edited: make it again on this camera's "
                "frame (leave --setup out)")
        w, h = self.grid_check.get("width"), self.grid_check.get("height")
        if w is None or h is None or (int(w), int(h)) == (int(width), int(height)):
            return
        raise ConvertError(
            f"{self.source or 'the set-up'}: decided on a {w}x{h} frame (grid_check width "
            f"and height), but {frame} is {width}x{height}: the set-up's grid and patch "
            "settings belong to that readout. Give the set-up of this camera and frame size, "
            "or leave --setup out to decide it on this frame")

    def settings(self, base: ConvertSettings) -> ConvertSettings:
        """``base`` with the decided MLA kind and tile (nothing left ``auto``)."""
        return dataclasses.replace(base, mla=self.mla, tile_size=int(self.tile))

    def grid(self, calib: RayCalib, width: int, height: int) -> MicrolensGrid:
        """The grid every shot is converted with: the file's, or the refined lattice."""
        if not self.refined:
            return build_grid(calib, width, height)
        assert self.lattice is not None
        return lattice_grid(calib, width, height, self.lattice, self.pitch_px)

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        del d["source"]
        d["border_cut"] = self.border_cut.to_dict()
        d[WARNINGS_KEY] = warning_list(self.warnings)
        d["lattice"] = None if self.lattice is None else {
            "origin_px": list(self.lattice[0]), "A_columns_px": [list(r) for r in self.lattice[1]]}
        return {"format": "plenocal.convert_setup", "version": FORMAT_VERSION, **d}

    @classmethod
    def from_dict(cls, d: dict, source: str = "<memory>") -> ConverterSetup:
        if d.get("format") != "plenocal.convert_setup" or d.get("version") != FORMAT_VERSION:
            raise ConvertError(f"{source}: not a convert_setup.json of version "
                               f"{FORMAT_VERSION} (format {d.get('format')!r}, version "
                               f"{d.get('version')!r}); rerun rule convert_setup, or make a "
                               "recording's set-up again (plenocal convert RECORDING.yuv "
                               "writes one)")
        lat = d["lattice"]
        lattice = None if lat is None else (
            tuple(float(x) for x in lat["origin_px"]),
            tuple(tuple(float(x) for x in row) for row in lat["A_columns_px"]))
        return cls(mla=str(d["mla"]), tile=int(d["tile"]), grid_mode=str(d["grid_mode"]),
                   refined=bool(d["refined"]), lattice=lattice, decided_on=str(d["decided_on"]),
                   mla_source=str(d["mla_source"]), tile_source=str(d["tile_source"]),
                   mla_match_scores=d.get("mla_match_scores"), grid_check=dict(d["grid_check"]),
                   warnings=warnings_of(d, source, "rerun rule convert_setup"),
                   safe_diameter_px=_float_or_none(d["safe_diameter_px"]),
                   q_px=_float_or_none(d["q_px"]),
                   safe_diameter_measure=(None if d["safe_diameter_measure"] is None
                                          else dict(d["safe_diameter_measure"])),
                   pitch_px=_float_or_none(d["pitch_px"]),
                   least_reach=int(d["least_reach"]),
                   border_cut=BorderCut.from_dict(d["border_cut"]), source=source)


def _float_or_none(value) -> float | None:
    return None if value is None else float(value)


def lattice_grid(calib: RayCalib, width: int, height: int, lattice,
                 pitch_px: float | None = None) -> MicrolensGrid:
    """The grid of ``calib`` on a ``width`` x ``height`` image with the lattice
    ``(origin, A)`` (:attr:`ConverterSetup.lattice`) instead of the file's, and its
    micro-image pitch ``pitch_px`` as the grid's diameter (None: the file's), as
    :func:`plenocal.convert.gridcheck.refine_grid` makes it: the views' layout, the lens
    margins and the file's safe diameter follow the pitch on the sensor."""
    base = build_grid(calib, width, height).calib
    if pitch_px is not None:
        base = dataclasses.replace(base, diameter=float(pitch_px))
    origin, A = lattice
    return MicrolensGrid(base, width, height,
                         lattice=(np.array(origin, dtype=float), np.array(A, dtype=float)))


def check_and_grid(image: np.ndarray, calib: RayCalib, mode: str
                   ) -> tuple[MicrolensGrid, GridCheck]:
    """The file's grid checked on ``image``; the grid that ``convert.grid`` = ``mode``
    asks for, and the check."""
    if mode not in GRID_MODES:
        raise ConvertError(f"convert.grid: {mode!r} is not one of {', '.join(GRID_MODES)}")
    H, W = image.shape[:2]
    return grid_for_mode(image, build_grid(calib, W, H), mode)


def centring_for(check: GridCheck, mode: str, shot: ShotConversion, source: str
                 ) -> CentringFit | None:
    """Where ``convert.grid`` = ``mode`` is ``auto`` and the check could not confirm the
    file's grid (not verified, not foreign, not refined), the lattice shift that the corner
    views of ``shot`` (converted on the file's grid) agree on best
    (:func:`plenocal.convert.centring.measure_centring`), recorded in ``check.centring``;
    where it is applied, the check's warning says so instead of "the file's grid is used".
    None where no search is made (every frame whose grid the check confirms)."""
    if mode != "auto" or check.verified or check.foreign or check.refined:
        return None
    fit = measure_centring(shot)
    check.centring = fit.to_dict()
    dx, dy = fit.offset_px
    what = (f"the corner views agree best with the file's lattice moved by ({dx:+.2f}, "
            f"{dy:+.2f}) px (their blend disagreement {fit.disagreement_file:.3f} -> "
            f"{fit.disagreement_fit:.3f} grey levels, {100 * fit.gain:.0f} % less)")
    if fit.applied:
        use = f"{what}: the views use it (plenocal.convert.centring)"
        check.warnings = [w.replace(UNVERIFIED_USE, use) for w in check.warnings]
    log.info("%s: %s%s", source, what, "; applied" if fit.applied else
             "; not applied (too short, or too little gain)")
    return fit


def centred_lattice(grid: MicrolensGrid, fit: CentringFit):
    """The lattice (origin, A columns) of ``grid`` moved by ``fit``, rounded as a refined
    set-up's lattice is (:data:`LATTICE_DIGITS`)."""
    moved = shifted_grid(grid, fit.offset_px)
    return round_floats((tuple(float(x) for x in moved.origin),
                         tuple(tuple(float(x) for x in row) for row in moved.A)),
                        LATTICE_DIGITS)


def centring_shift(centring: dict | None) -> tuple[float, float] | None:
    """The shift (px) a grid check's ``centring`` record moved the file's lattice by, None
    where none was applied (or no search made)."""
    if not centring or not centring.get("applied"):
        return None
    dx, dy = centring["offset_px"]
    return float(dx), float(dy)


def grid_words(check: dict) -> str:
    """Which grid the views were cut on, from a shot's ``grid_check`` record."""
    if check.get("refined"):
        return "refined from the image"
    shift = centring_shift(check.get("centring"))
    if shift is not None:
        return (f"calib.xml's, moved by ({shift[0]:+.2f}, {shift[1]:+.2f}) px onto the "
                "micro-image centres the corner views agree on")
    return "calib.xml's"


def centred_where_unverified(image: np.ndarray, calib: RayCalib, n_views: int,
                             settings: ConvertSettings, source: str, grid: MicrolensGrid,
                             check: GridCheck, shot: ShotConversion, threads: int = 1):
    """``(grid, shot, lattice)``: where :func:`centring_for` moves the file's lattice, the
    moved grid, the frame ``image`` measured again on it and the lattice as a set-up
    writes it (rounded: :func:`centred_lattice`); elsewhere ``grid`` and ``shot`` as they
    are, and None. The shot measured on the file's grid is let go first (its prefiltered
    frame: 93 MB at 31 MP)."""
    fit = centring_for(check, settings.grid, shot, source)
    if fit is None or not fit.applied:
        return grid, shot, None
    lattice = centred_lattice(grid, fit)
    grid = lattice_grid(calib, grid.width, grid.height, lattice)
    del shot
    return grid, ShotConversion(image, calib, n_views, settings, source=source, grid=grid,
                                threads=threads), lattice


#: convert.grid_foreign: stop at a foreign grid, or convert on it with a warning
GRID_FOREIGN = ("error", "warn")
_CONVERT = stage_defaults("convert")  # the schema's defaults (grid_foreign: error)


def _check_policy(policy: str) -> None:
    """ConvertError unless ``policy`` is a ``convert.grid_foreign`` value."""
    if policy not in GRID_FOREIGN:
        raise ConvertError(f"convert.grid_foreign: {policy!r} is not one of "
                           f"{', '.join(GRID_FOREIGN)}")


def overexposure_hint(image: np.ndarray | None) -> str:
    """A sentence for the grid errors where a fifth or more of ``image`` is clipped
    (:data:`OVEREXPOSED_SHARE`), else "" (and where no image is given). Saturated micro
    images lose the edges and the falloff the grid check measures the lattice by: Boys2
    made 2x brighter (60 % of its pixels clipped) read its own calib.xml as foreign (a
    pitch 1.6 % off, 47 px of drift), where the frame as recorded (4 % clipped) measures
    42 % of its lit lenses and is refined onto the lattice they give; HandTools 4x
    brighter (59 % clipped) still measured 69 %."""
    share = 0.0 if image is None else clipped_share(image)
    if share < OVEREXPOSED_SHARE:
        return ""
    return (f". But {100 * share:.0f}% of the frame's pixels are clipped at full scale: "
            "an overexposed frame hides the micro images' edges from the check, and the "
            "file may not be at fault. Decide the set-up on a frame of this camera exposed "
            "without clipping (the workflow's central array shot; plenocal convert on a "
            "recording: --setup-frame K) and convert this one with it (plenocal convert: "
            "--setup convert_setup.json)")


def foreign_grid_error(check: GridCheck, calib_source: str, frame: str,
                       policy: str = _CONVERT["grid_foreign"], *,
                       image: np.ndarray | None = None) -> str | None:
    """The error that stops the run when the grid check found the calib.xml grid foreign
    (not on the micro images: another camera's file) and it is used as it is, or None
    (``policy`` ``warn``: the user goes on; ``convert.grid`` ``refine``: the views use the
    lattice fitted to the image). Converting on a foreign grid gives views that registration
    A cannot match, and its error then blames the texture and the overlap. ``image``: the
    frame, whose overexposure the message names (:func:`overexposure_hint`)."""
    _check_policy(policy)
    if not check.foreign or check.refined or policy == "warn":
        return None
    dx, dy = check.offset_px
    return (f"{calib_source}: the calib.xml grid is not on the micro images of {frame} "
            f"({100 * check.measured_share:.0f}% of {check.lenses} lenses measured: pitch "
            f"x{check.pitch_ratio:.4f} of the file's, lattice ({dx:+.1f}, {dy:+.1f}) px off at "
            f"the image centre, drift up to {check.drift_max_px:.1f} px of a "
            f"{check.diameter_px:.1f} px lens, residual {check.residual_rms_px:.2f} px): it "
            "looks like another camera's or another sensor crop's file. Put this camera's "
            "calib.xml there, or set convert.grid: refine to convert on the lattice fitted to "
            "the image, or convert.grid_foreign: warn to convert on this grid all the same "
            "(plenocal convert: --grid refine, or --set grid_foreign=warn)"
            + overexposure_hint(image))


#: the mean best ZNCC of neighbouring micro images (:func:`plenocal.convert.patchsize.
#: detect_mla_kind`, the better of the two MLA kinds) below which a frame whose grid the
#: check could not confirm is taken as one that calib.xml does not describe
#: (:func:`unmatched_frame_error`). Measured on full frames: each real frame of
#: shared/real with its own calib.xml 0.84-0.97 (R42_klein_crop, whose grid the check
#: cannot confirm, 0.96), the simulator 0.98; the real frames with another camera's file,
#: where the check could not confirm the grid either, 0.06-0.48, and 0.65 where the file's
#: pitch is twice the frame's (R42_klein_crop with Boys2's: every other lens matches)
UNMATCHED_ZNCC = 0.75


def unmatched_frame_error(check: GridCheck, scores: dict[str, float] | None,
                          calib_source: str, frame: str,
                          policy: str = _CONVERT["grid_foreign"], *,
                          image: np.ndarray | None = None) -> str | None:
    """The error that stops the run where the grid check could not confirm the calib.xml
    grid (``check.verified`` false: too few lit lenses measured) and the micro images
    match their neighbours as neither MLA kind (``scores``: each kind's mean best ZNCC,
    the better under :data:`UNMATCHED_ZNCC`), or None. Either the file is another
    camera's, whose grid lies between this frame's micro images so that the check finds
    nothing to measure, or the frame shows too little to convert; the views would be a
    mosaic of misplaced patches either way. ``policy`` ``warn`` (convert.grid_foreign)
    converts all the same. A frame without any texture is left to the warnings (its views
    are flat, not wrong; :func:`plenocal.convert.shot.mla_undecided` says that the kind
    was assumed): both scores 0 or not measured, which only a frame whose matched lenses
    hold one grey level each gives (the ZNCC of two constant blocks is taken as 0; sensor
    noise alone reads about 0.1). ``image``: as :func:`foreign_grid_error`'s."""
    _check_policy(policy)
    if policy == "warn" or check.verified or not scores:
        return None
    measured = {k: v for k, v in scores.items() if np.isfinite(v)}
    if not any(measured.values()):  # none measured, or nothing varied: no texture
        return None
    kind = max(measured, key=measured.get)
    if measured[kind] >= UNMATCHED_ZNCC:
        return None
    return (f"{calib_source}: its microlens grid is not found in {frame}: the grid check "
            f"measured only {100 * check.lit_share:.0f}% of the {check.lit} lenses it takes "
            f"as lit, and neighbouring micro images match at best {measured[kind]:.2f} "
            f"(mean best ZNCC, as {kind}), where a frame with its own calib.xml matches "
            f"{UNMATCHED_ZNCC:g} or more. Either calib.xml is another camera's or another "
            "sensor crop's (put this camera's there), or the frame is too dark, flat or "
            "out of focus to decide the conversion on (decide it on a frame with texture: "
            "the workflow's central array shot; plenocal convert on a recording: "
            "--setup-frame K). The views would be a mosaic of misplaced patches. To "
            "convert all the same: convert.grid_foreign: warn (plenocal convert: --set "
            "grid_foreign=warn)" + overexposure_hint(image))


def views_decided(setup: ConverterSetup) -> int | None:
    """The N of the N x N views ``setup`` was decided for, where its view spacing is the
    default ``q = D' sin(45 deg) / N`` (:func:`plenocal.optics.view_spacing`) to the
    written digits; None where ``convert.view_spacing_px`` set ``q`` (or the set-up holds
    no ``q``). The views of another N are other cameras than the calibration's."""
    if not setup.q_px or not setup.safe_diameter_px:
        return None
    n = view_spacing(setup.safe_diameter_px, 1) / setup.q_px
    k = round(n)
    return k if k >= 1 and abs(n - k) <= 1e-6 * k else None


def mla_setting_error(setup: ConverterSetup, shot: ShotConversion, source: str
                      ) -> str | None:
    """The workflow's stop for an MLA kind set in the config (``mla_source`` "setting")
    that the set-up frame ``source`` clearly contradicts
    (:func:`plenocal.convert.shot.mla_contradiction`: the other kind matches better by
    :data:`~plenocal.convert.shot.MLA_CONTRADICTION` or more), or None. Converted so,
    every view would be a mosaic of misplaced patches, and in a workflow the warning
    would reach a log only."""
    if setup.mla_source != "setting" or not shot.match_scores:
        return None
    note = mla_contradiction(setup.mla, shot.match_scores)
    return None if note is None else f"{source}: {note}"


def decide_setup(image: np.ndarray, calib: RayCalib, n_views: int, settings: ConvertSettings,
                 source: str, grid_foreign: str = _CONVERT["grid_foreign"], threads: int = 1
                 ) -> tuple[ConverterSetup, ShotConversion]:
    """Decide the per-camera set-up on one shot; returns it and that shot's conversion.
    A foreign grid stops here (:func:`foreign_grid_error`, ``grid_foreign``: the config's
    ``convert.grid_foreign``) before any view is made, and so does a grid the check could
    not confirm on a frame whose micro images match nothing (:func:`unmatched_frame_error`).
    ``threads``: the shot's measurements side by side
    (:class:`plenocal.convert.shot.ShotConversion`; the same numbers with any number)."""
    grid, check = check_and_grid(image, calib, settings.grid)
    log.info("%s: %s", source, check.summary())
    error = foreign_grid_error(check, calib.source, source, grid_foreign, image=image)
    if error is not None:
        raise ConvertError(error)
    lattice = pitch = None
    if check.refined:
        # to LATTICE_DIGITS significant digits (1e-4 px on a 4000-px sensor): the fit's
        # last digits move with the machine's floating-point paths, and every shot is
        # converted with the lattice as written - this one too, so that its measurements
        # are those of any later conversion of the same image with the set-up
        lattice = round_floats((tuple(float(x) for x in grid.origin),
                                tuple(tuple(float(x) for x in row) for row in grid.A)),
                               LATTICE_DIGITS)
        pitch = round_floats(float(grid.diameter), LATTICE_DIGITS)
        grid = lattice_grid(calib, grid.width, grid.height, lattice, pitch)
    shot = ShotConversion(image, calib, n_views, settings, source=source, grid=grid,
                          threads=threads)
    error = unmatched_frame_error(check, shot.match_scores, calib.source, source,
                                  grid_foreign, image=image)
    if error is not None:
        raise ConvertError(error)
    grid, shot, centred = centred_where_unverified(image, calib, n_views, settings, source,
                                                   grid, check, shot, threads)
    lattice = centred or lattice
    warnings = [f"{source}: {w}" for w in check.warnings] + shot.warnings
    if shot.border_cut.any:  # the views are smaller than the sensor's lenses allow: said
        warnings.append(f"{source}: {shot.border_cut.summary()} ({shot.layout.width}x"
                        f"{shot.layout.height} views; convert.border_cut: off keeps them)")
    setup = ConverterSetup(
        mla=shot.mla, tile=int(shot.layout.tile), grid_mode=settings.grid,
        refined=lattice is not None, lattice=lattice, decided_on=source,
        mla_source="image" if shot.mla_scores is not None else "setting",
        tile_source="auto" if settings.tile_size == "auto" else "setting",
        mla_match_scores=shot.mla_scores, grid_check=check.to_dict(),
        warnings=tuple(warnings),
        # rounded as the lattice is (the last digits move with floating-point paths)
        safe_diameter_px=round_floats(float(shot.safe.diameter_px), LATTICE_DIGITS),
        q_px=round_floats(float(shot.layout.q), LATTICE_DIGITS),
        safe_diameter_measure=round_floats(shot.safe.to_dict(), LATTICE_DIGITS),
        pitch_px=pitch, least_reach=int(shot.least_reach), border_cut=shot.border_cut)
    return setup, shot


def write_setup(path: str | Path, setup: ConverterSetup) -> None:
    write_json(path, setup.to_dict())


def read_setup(path: str | Path) -> ConverterSetup:
    """The set-up in ``path`` (a convert_setup.json); errors name the file, the key where
    one is missing or wrong, and the remedy."""
    remedy = ("pass the convert_setup.json that rule convert_setup or plenocal convert "
              "wrote, or leave --setup out to decide the set-up on the frame")
    try:
        doc = read_json(path)
    except FileNotFoundError:
        raise ConvertError(f"{path}: no convert_setup.json; run rule convert_setup") from None
    except ValueError as exc:  # not JSON, or not text (UnicodeDecodeError is a ValueError)
        raise ConvertError(f"{path}: not a convert_setup.json (not JSON: {exc}); {remedy}"
                           ) from None
    if not isinstance(doc, dict):
        raise ConvertError(f"{path}: not a convert_setup.json (a JSON "
                           f"{type(doc).__name__}, not an object); {remedy}")
    try:
        return ConverterSetup.from_dict(doc, source=str(path))
    except KeyError as exc:
        raise ConvertError(f"{path}: convert_setup.json without its key {exc.args[0]!r}; "
                           f"{remedy}") from None
    except (TypeError, ValueError, AttributeError) as exc:
        if str(path) in str(exc):  # its own checks (format, version, values) name the file
            raise
        raise ConvertError(f"{path}: a value in convert_setup.json is not of its kind ({exc}); "
                           f"{remedy}") from None
