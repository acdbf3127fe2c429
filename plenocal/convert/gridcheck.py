"""Check the calib.xml microlens grid against the micro images of the frame, and refine it.

Measurement. The micro images repeat on the MLA lattice, and so do their borders: the
discontinuities between neighbouring micro images (and the dark vignetted rims where there
are any) form a honeycomb centred on the lens centres. The frame is reduced by area
averaging to about 10 px per lens (the phase keeps sub-pixel accuracy), its gradient
magnitude taken (``FEATURE``; the borders are where the gradient is, wherever the scene
is), divided by its local mean (bright and dark parts of the scene weigh alike),
demodulated at the lattice's three shortest reciprocal vectors
``k_1, k_2, k_3 = -(k_1 + k_2)`` (cycles per pixel, ``k_i . a_j = delta_ij``) relative to
the file's grid, and low-passed over a few lenses (``BOX_LENSES``). For a pattern
``v(x - c_i)`` point-symmetric about ``c_i = c_i^file + delta``, the local coefficient is
``z_j = V(k_j) exp(-2 pi i k_j . delta)``: its phase gives the local shift ``delta`` of the
true lattice against the file's, modulo one lens. ``V`` is real, of one sign for the three
``k_j`` (hexagonal symmetry); the phase closure ``arg(z_1 z_2 z_3) = 3 arg V`` (the
``delta`` terms cancel, as ``k_1 + k_2 + k_3 = 0``) gives that sign, and lenses whose closure
is far from it (scene content at the lattice frequency, dark or flat regions) are not
measured. About 0.2-0.4 s per 4 MP frame on one core.

Why the gradient and not the grey level: the grey level's phase is biased by scene content
that repeats from lens to lens, worst where vignetting is weak (the TSPC frames, Galilean,
bright micro images with thin borders). Against the four corner centres that the TSPC
tools measured, the grey-level fit lands 16-18 px off on Boys2 (worse than the file's grid:
5-21 px) and 0.7-6 px off on HandTools (file: 12-14 px); the gradient fit lands 3.3-4.7 px
off on Boys2 and 1.5-2.3 px on HandTools, and its residual is lower on every frame
(6.1 / 6.6 px on the 70-px TSPC lenses, 0.7-1.4 px on the Raytrix ones; grey level
7.7 / 8.5 and 0.9-4.0 px). On synthetic lattices with known centres both are unbiased
to 0.04 px.

Fit. ``c_i^measured = o + M (i, j)`` by least squares with outlier trimming (3 robust
sigmas): an affine lattice (offset, pitch, rotation, and anisotropic scale / shear), and
the similarity part of it (offset, pitch, rotation: what a RayCalibData file can hold).
The drift, the decision and a refinement take the similarity (:func:`refine_grid`): an
MLA is a rigid lattice, and the anisotropy and shear the affine fit reads are the
measurement's. On the real frames they are 0.01-0.05 % (the two lattices within 0.5 px
of each other); on the simulator's exact file of ``tspc-like`` seed 96 (57-px micro images,
vignetted corners) 0.31 %, a drift of 2.97 px that the auto rule took (4.07 standard
errors). A lattice error does not stay a lattice error in the views: each lens is sampled
off its micro image's centre by it, so the views' rays through it leave the main lens off
its centre, and a field of such offsets that grows across the sensor bends the views'
ray directions in proportion: the views laid out on that sheared lattice were cameras
with a skew of 0.65 % and 1.85 % between fx and fy (the ground truth traced through the
simulated lenses, :func:`plenocal.simulate.groundtruth.true_lens_centres`). Its similarity
drifts 1.12 px, under 4 standard errors: the file's grid stays.
The shift modulo one lens is unwrapped from the centre outwards, so grids off by several
pixels at the edges (a pitch error) are followed: the file's lattice moved by the central
lenses' mean shift until a disc around the centre holds ``MIN_START`` (100) measured
lenses, then the affine fit of each widening disc. (An affine fit to the 30-odd lenses of a
frame with a dark or flat centre, HandTools_f150, was 0.9-2.7 px per lens off and sent the
unwrapping into the wrong cells: a 134 px drift, FOREIGN, after a yuv420p round trip.)
The drift of the file's grid is the distance from each lens's file centre to the fitted
lattice (max, rms, and per region: the four corners and the centre); the raw per-lens
measurements give the model-free medians per region.

Where is the RayCalibData offset measured from? On the three Raytrix frames whose files
fit their micro images (Fujita2, Origami, Boxer-IrishMan-Gladiator2), the fitted lattice
at the image centre lies at file + (-0.11, +0.24), (-0.19, -0.04) and (+0.35, -0.16) px
(mean (+0.02, +0.01)) when the offset is read from ``((W-1)/2, (H-1)/2)`` (this project's
convention, :mod:`plenocal.io.raytrix`). TLCT's ``(W/2, H/2)`` puts the grid half a pixel
further right and down: the micro images would then sit at (-0.5, -0.5) px from its grid,
on average. The measurement supports ``((W-1)/2, (H-1)/2)``, by 0.5 px against a frame-to-
frame spread of 0.2-0.35 px; on synthetic frames the check is unbiased to 0.04 px, so the
offsets are the files', not the method's. (The grey-level phase says the same in y,
(+0.31, -0.05), (+0.07, +0.03), (+0.42, +0.06); in x it is less clear.)

``convert.grid`` values:

- ``file``: the file's grid as it is; the check still runs and is reported.
- ``refine``: the fitted affine lattice (:func:`refine_grid`), unless the check found too
  few lenses to fit (then the file's grid, with a warning).
- ``auto`` (the rule of :func:`decide`): refine when the file's grid drifts from the fitted
  lattice by more than ``AUTO_DRIFT_PX`` = 1 px at its worst lens, and there by more than
  ``AUTO_DRIFT_SIGMAS`` = 4 standard errors of that lens's fitted drift, and the file is
  not foreign. Where fewer than ``PARTIAL_LIT`` (half) of the lenses are lit (a subject on
  black, below), the worst lit lens is judged instead: the worst lens lies in the black,
  where the views show nothing and the fit only extrapolates from the lit part. Its
  standard error there understates how wrong the extrapolation can be: on the Raytrix
  frames made black around a subject (Fujita2, Origami), whose files are right to a pixel,
  the worst lens read 2.6 +- 0.4 and 1.4 +- 0.3 px, the worst lit one 0.96 and 0.45 px. On
  Boys2 made black around one face the worst lit lens reads 7.7 +- 1.4 px (refined; the
  worst lens, in the black, 11.0 +- 4.1). HandTools made black around its centre keeps the
  file's grid: 4.6 +- 1.9 px at its worst lit lens, under 4 standard errors (its 9 % of
  lenses measured scatter 6 px about any lattice). Its file grid is 3-5 px off under the
  subject there (the whole frame's fit), and its corner views show no arc or honeycomb at
  100 % (BENCHMARKS.md, "HandTools on black, looked at"); Boys2's 11 px did.
  Why 1 px: a centre error of ``e`` px shifts that lens's tile in a view by ``e T / P``
  output pixels (seams at tile borders), so half a pixel would be the ideal bar, but it is
  below what the check can tell apart from its own systematic error: on the 28 shots of the
  simulator's default dataset (2048 x 1536, D = 23.9 px), whose calib.xml is exact by
  construction, it reads 0.37-0.54 px (max drift over the sensor; none refined), and the
  grey-level and gradient fits of the same Raytrix frame differ by up to 0.65 px (Origami),
  0.88 px (Boxer). Frames here: Fujita2 0.77 px (kept), Origami
  1.48 and Boxer 1.11 px (refined: a pitch x1.0009 / x1.0003 that both measures find),
  Boys2 18 px and HandTools 16 px (refined).
- A grid that is not on the micro images at all (a calib.xml from another camera or for
  another sensor crop) is recognised as foreign when the check measured enough lenses
  (``MIN_SHARE``): a fitted pitch more than ``FOREIGN_PITCH`` (2 %) from the file's, the
  lattice more than a quarter lens off at the image centre, or measurements more than a
  fifth of a lens (rms) from any lattice. It is reported with its measured drift
  (``GridCheck.foreign``, a warning in ``GridCheck.warnings``) and never refined
  automatically: a wrong file should be replaced, not patched (``refine`` still may).
- Fewer than ``MIN_SHARE`` of the lit lenses measured (or none fitted): the check cannot
  confirm the grid either way (``verified`` false, a warning); auto keeps the file's grid.
  A lens is lit where the mean of its micro image's central disc (a quarter of the pitch
  across) stands ``LIT_FRACTION`` (a tenth) of the way from the darkest lenses' level to the
  brightest ones' (:func:`lit_lenses`). A micro image of a black background holds no light
  to measure the lattice by, and counting it held a frame of a subject on black (the doll's
  face in the middle of a TSPC frame; made here from Boys2, every lens but 574 of its 2,762
  black: 15 % of its lenses measured, 61 % of its 550 lit ones) to the file's grid, 11 px
  off under the face there, and its corner views to arcs and a honeycomb on the hair. The
  lit lenses' share moves little with the fraction (a twentieth to a fifth): Boys2 on black
  0.61-0.62, R42_klein_crop 0.10-0.17, the other real frames 0.22 or more (Fujita2_f150
  0.22-0.23, whose share of all its lenses measured was 0.21).
  A far-off grid (another camera's pitch) ends here, and so does R42_klein_crop, whose file
  is nearly right: 16 % of its lenses measured, and the lattice it fits (18 px off the
  file's at the centre) is wrong - the views made on the file's grid are whole, those made
  with the fitted offset a mosaic. Its micro images (strongly textured, crossed by the
  sharp rim of a blue object, no vignetted rim) defeat the measurement; an unverified
  check is no verdict on the file. Its corner views are: they agree best with the file's
  lattice moved by (+3.25, +2.25) px, and ``auto`` then takes that
  (:mod:`plenocal.convert.centring`, :func:`plenocal.convert.setup.centring_for`).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace

import cv2
import numpy as np

from plenocal.convert.exact import magnitude, remap
from plenocal.grid import MicrolensGrid
from plenocal.io.raytrix import RayCalib
from plenocal.rounding import round_floats

AUTO_DRIFT_PX = 1.0  # refine (convert.grid: auto) past this drift of the file's grid
AUTO_DRIFT_SIGMAS = 4.0  # ... and when the drift is this many standard errors
MIN_SHARE = 0.2  # fewer lit lenses measured than this: the grid is not on the micro images
LIT_FRACTION = 0.1  # of the way from the dark lenses' level to the bright ones': lit
LIT_PERCENTILES = (1.0, 99.0)  # the dark and the bright lenses' levels
# fewer of the lenses lit than this: the drift is judged at the worst lit lens, not the
# worst lens on the sensor
PARTIAL_LIT = 0.5
FOREIGN_PITCH = 0.02  # fitted pitch this far from the file's: another camera's file
FOREIGN_OFFSET = 0.25  # lenses: fitted lattice this far from the file's at the image centre
FOREIGN_RESIDUAL = 0.2  # lenses: measurements this far from any lattice (rms)
WORK_PX_PER_LENS = 10.0  # the frame is reduced to about this many pixels per lens
CLOSURE_TOL = 0.6  # rad: phase closure of a measured lens
FEATURE = "gradient"  # intensity | gradient | both: the image the phase is measured on
BOX_LENSES = 3.0  # low-pass: two box filters this many lenses wide
MIN_LENSES = 30  # fewer measured lenses: no fit
# lenses the first (central) affine fit of the unwrapping needs: on 30 lenses bunched at
# the edge of the central disc, two of them a third of a lens off, the six parameters came
# out 2.7 px per lens off (HandTools_f150 after a yuv420p round trip) and led the unwrapping
# into the wrong cells: the whole lattice then fitted 134 px off, FOREIGN
MIN_START = 100
GRID_MODES = ("file", "refine", "auto")
REGIONS = ("top_left", "top_right", "centre", "bottom_left", "bottom_right")


# decimals of the grid check's figures in the JSON files: pixels to 1e-4 px (the check's
# standard error is about 0.1 px), the lattice's shape (affine, pitch ratio, vectors) to
# 1e-9; see GridCheck.to_dict
REPORT_DECIMALS = 4
SHAPE_DECIMALS = 9
SHAPE_FIELDS = ("affine", "A", "pitch_ratio", "rotation_deg")


@dataclass
class GridCheck:
    """The file's grid against the micro-image centres measured in the frame (pixels)."""

    width: int
    height: int
    diameter_px: float
    lenses: int
    measured: int
    measured_share: float  # of every lens
    lit: int  # lenses whose micro images hold light to measure (lit_lenses)
    lit_share: float  # of the lit lenses, those measured: verified from MIN_SHARE
    judged_drift_px: float  # the drift convert.grid auto judges (module docstring)
    judged_stderr_px: float  # ... and its standard error
    fitted: bool
    # file grid vs the fitted lattice's similarity (what a refinement takes), over every
    # lens on the sensor
    drift_max_px: float
    drift_rms_px: float
    drift_stderr_px: float  # standard error of the fitted drift at its worst lens
    regions: dict[str, dict[str, float]]  # per region: similarity (dx, dy), measured median
    offset_px: tuple[float, float]  # affine fit - file grid at the image centre
    pitch_ratio: float  # fitted pitch / file pitch (mean of the two lattice vectors)
    rotation_deg: float  # fitted lattice rotation - file rotation, image frame (y down)
    affine: list[list[float]]  # fitted A = affine @ A_file (reported; not taken)
    origin: tuple[float, float]  # affine fit: centre of lens (0, 0)
    A: list[list[float]]  # affine fit's lattice vectors as columns
    similarity_origin: tuple[float, float]  # centre of lens (0, 0) on the best similarity
    residual_rms_px: float  # measurements vs the affine fit
    similarity_residual_rms_px: float  # measurements vs the best similarity
    foreign: bool  # the file's grid is measurably not on the micro images
    refine_auto: bool
    verified: bool = True  # enough lit lenses measured for the figures to mean something
    warnings: list[str] = field(default_factory=list)
    seconds: float = 0.0
    mode: str = ""  # convert.grid, where grid_for_mode chose
    refined: bool = False  # the conversion used the refined grid
    # where the check could not confirm the grid: the file's lattice moved onto the centres
    # the corner views agree on (plenocal.convert.centring.CentringFit.to_dict), or None
    centring: dict | None = None

    def to_dict(self) -> dict:
        """For disparity.json (plain floats and lists; without the time it took, which would
        make the file differ from run to run). Floats to :data:`REPORT_DECIMALS` decimals,
        the lattice's shape to :data:`SHAPE_DECIMALS`: a cluster job's figures have differed
        from a local run's by up to 1e-8 px (cause not found: the same job repeated, pinned
        to either core or under any thread setting, gives identical bits here), and a
        fixed grid far coarser than that keeps the files identical in all but rare ties."""
        d = {k: round_floats(v, SHAPE_DECIMALS if k in SHAPE_FIELDS else REPORT_DECIMALS,
                             decimals=True)
             for k, v in asdict(self).items()}
        del d["seconds"]
        if d["centring"] is None:  # not searched: the record as before the search existed
            del d["centring"]
        d["rule"] = (f"convert.grid auto refines when the drift at the judged lens (the worst "
                     f"one; the worst lit one where fewer than {PARTIAL_LIT:g} of the lenses "
                     f"are lit) is > {AUTO_DRIFT_PX} px and > {AUTO_DRIFT_SIGMAS:g} x its "
                     f"standard error (judged_drift_px, judged_stderr_px), verified "
                     f"(lit_share >= {MIN_SHARE}) and not foreign")
        return d

    def summary(self) -> str:
        if not self.fitted:
            return (f"grid check: {self.measured} of {self.lenses} lenses measured, too few "
                    "to fit the lattice - UNVERIFIED")
        r = self.regions
        corners = ", ".join(f"{k} {r[k]['fit_drift_px']:.2f}" for k in REGIONS if k in r)
        return (f"grid check: {100 * self.measured_share:.0f}% of {self.lenses} lenses "
                f"measured ({100 * self.lit_share:.0f}% of the {self.lit} lit); file grid "
                f"drifts max {self.drift_max_px:.2f} px (rms "
                f"{self.drift_rms_px:.2f}, +-{self.drift_stderr_px:.2f}) [{corners}]; fitted "
                f"offset ({self.offset_px[0]:+.2f}, {self.offset_px[1]:+.2f}) px, pitch x"
                f"{self.pitch_ratio:.5f}, rotation {self.rotation_deg:+.4f} deg; residual "
                f"{self.residual_rms_px:.2f} px" + (" - FOREIGN GRID" if self.foreign else "")
                + ("" if self.verified else " - UNVERIFIED (too few lit lenses measured)"))


_DRIFT_HEAD = "grid check: the calib.xml grid drifts up to "
#: what an unverified check's warning says is used (plenocal.convert.setup.centring_for
#: replaces it where the file's lattice is moved onto the micro images)
UNVERIFIED_USE = "the file's grid is used"


def _drift_head(drift_px: float) -> str:
    """The start every drift warning shares (:func:`grid_for_mode` finds them by it)."""
    return f"{_DRIFT_HEAD}{drift_px:.2f} px from the micro-image centres"


def _drift_warning(drift_px: float, refined_by: str | None) -> str:
    """The warning of a calib.xml grid that drifts from the micro images, with what was
    done about it: nothing yet (``refined_by`` None: the check alone says how to correct
    it), or the views use the lattice fitted to the image (``convert.grid`` =
    ``refined_by``), so that a warning on the report's first screen does not ask for a
    correction that was made."""
    head = _drift_head(drift_px)
    if refined_by is None:
        return head + " (convert.grid: refine / auto corrects it)"
    return (head + "; corrected: the views use the lattice fitted to the image "
            f"(convert.grid: {refined_by})")


def _kept_warning(drift_px: float, judged_px: float, judged_se: float, partial: bool) -> str:
    """The warning of a drift past :data:`AUTO_DRIFT_PX` that ``auto`` does not correct:
    where the views have content (the worst lit lens of a frame lit in part) the drift is
    under the bar, or within :data:`AUTO_DRIFT_SIGMAS` standard errors of the fit. Said so,
    not "auto corrects it", which a frame of a right file on black read before."""
    where = "under the lit lenses" if partial else "at its worst lens"
    why = (f"under the {AUTO_DRIFT_PX:g} px bar" if judged_px <= AUTO_DRIFT_PX else
           f"within {AUTO_DRIFT_SIGMAS:g} standard errors of the fit")
    return (f"{_drift_head(drift_px)}{', in the dark part of the frame' if partial else ''}; "
            f"{where} "
            f"{judged_px:.2f} +- {judged_se:.2f} px, {why}: convert.grid auto keeps the "
            "file's grid (convert.grid: refine uses the lattice fitted to the image)")


def grid_for_mode(image: np.ndarray, grid: MicrolensGrid, mode: str
                  ) -> tuple[MicrolensGrid, GridCheck]:
    """Check ``grid`` (the file's) on ``image`` and return the grid ``convert.grid`` =
    ``mode`` asks for (the file's or the refined one) with the check (``mode``, ``refined``
    filled in; a drift warning says when the refined grid corrected it)."""
    check = check_grid(image, grid)
    check.mode = mode
    check.refined = decide(mode, check)
    if check.refined:  # the drift's warning says it was corrected
        check.warnings = [_drift_warning(check.drift_max_px, mode)
                          if w.startswith(_DRIFT_HEAD) else w for w in check.warnings]
    if mode == "refine" and not check.fitted:
        check.warnings.append("convert.grid refine: the lattice could not be fitted; the "
                              "file's grid is used")
    return (refine_grid(grid, check) if check.refined else grid), check


def decide(mode: str, check: GridCheck) -> bool:
    """Whether to use the refined grid for ``convert.grid`` = ``mode``."""
    if mode not in GRID_MODES:
        raise ValueError(f"convert.grid: {mode!r} is not one of {', '.join(GRID_MODES)}")
    if mode == "file":
        return False
    if mode == "refine":
        return check.fitted
    return check.refine_auto


# ---------------------------------------------------------------------------
# measurement
# ---------------------------------------------------------------------------


def _mul(X: np.ndarray, M: np.ndarray) -> np.ndarray:
    """``X @ M`` by einsum (no BLAS): OpenBLAS splits large products over its threads
    with results that differ in the last bits, so a check run on 2 cores and the same
    check in a one-core cluster job wrote different JSON (tests/test_slurm.py)."""
    return np.einsum("...j,jk->...k", X, M)


def _lstsq(X: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Least squares ``X P = y`` by the normal equations, summed without BLAS."""
    return np.linalg.solve(np.einsum("ni,nj->ij", X, X), np.einsum("ni,nk->ik", X, y))


def _grey(image: np.ndarray) -> np.ndarray:
    """One channel, in the image's own integer type where it has one (fast reductions)."""
    img = np.ascontiguousarray(image)
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    elif img.ndim == 3:
        if img.dtype not in (np.uint8, np.uint16, np.float32):
            img = img.astype(np.float32)
        img = cv2.cvtColor(np.ascontiguousarray(img[:, :, :3]), cv2.COLOR_RGB2GRAY)
    if img.dtype not in (np.uint8, np.uint16, np.float32):
        img = img.astype(np.float32)
    return img


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


def _measure(image: np.ndarray, origin: np.ndarray, A: np.ndarray, centres: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-lens shift of the true lattice against (origin, A) at ``centres`` (modulo one
    lens, in the cell nearest zero), a measured flag and a lit flag (:func:`lit_lenses`)."""
    D = float(np.sqrt(abs(np.linalg.det(A)) * 2 / math.sqrt(3)))
    s = max(1, int(D // WORK_PX_PER_LENS))
    g = _grey(image)
    H, W = g.shape
    Hs, Ws = H // s, W // s
    if s > 1:
        g = cv2.resize(np.ascontiguousarray(g[:Hs * s, :Ws * s]), (Ws, Hs),
                       interpolation=cv2.INTER_AREA)
    g = g.astype(np.float32)
    Ds = D / s
    # small pixel u covers big pixels s u .. s u + s - 1: its centre is at s u + (s - 1) / 2
    o_s = (origin - (s - 1) / 2) / s
    A_s = A / s
    K = np.linalg.inv(A_s)  # rows: reciprocal vectors k_1, k_2 (cycles per small pixel)
    ks = np.stack([K[0], K[1], -(K[0] + K[1])])
    box = max(3, int(round(BOX_LENSES * Ds)) | 1)
    pts = ((centres - (s - 1) / 2) / s).astype(np.float32)
    features = []
    if FEATURE in ("intensity", "both"):
        features.append(g)
    if FEATURE in ("gradient", "both"):
        features.append(magnitude(cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3),
                                  cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3)))
    z = sum(_coefficients(f, ks, o_s, Ds, box, pts) for f in features)
    phi = np.angle(z)
    closure = _wrap(phi.sum(axis=1))
    # delta from phases 1 and 2 (k_i . a_j = delta_ij), then least squares with all three
    d0 = -(phi[:, :1] * A_s[:, 0] + phi[:, 1:2] * A_s[:, 1]) / (2 * np.pi)
    e = _wrap(phi + 2 * np.pi * _mul(d0, ks.T))
    d = d0 - _mul(e, np.linalg.pinv(2 * np.pi * ks).T)
    d = _nearest_cell(d, A_s, np.zeros_like(d))
    amp = np.abs(z).min(axis=1) / len(features)
    margin = box // 2 + 1  # windows reaching well past the border are unreliable
    inside = ((pts[:, 0] >= margin) & (pts[:, 0] <= Ws - 1 - margin)
              & (pts[:, 1] >= margin) & (pts[:, 1] <= Hs - 1 - margin))
    ok = inside & (np.abs(closure) < CLOSURE_TOL) & (amp > 0.05)
    return d * s, ok, lit_lenses(g, pts, Ds)


def lit_lenses(g: np.ndarray, pts: np.ndarray, Ds: float) -> np.ndarray:
    """(n,) bool: the lenses at ``pts`` (pixels of ``g``, micro images ``Ds`` px across)
    whose central disc, a quarter of the pitch across (a box of that width), stands above
    the darkest lenses' level by at least :data:`LIT_FRACTION` of the way to the brightest
    lenses' (the :data:`LIT_PERCENTILES` of every lens's such mean: a black level, as a
    video's limited range has, counts as dark, and a subject on one lens in a hundred still
    sets the bright level)."""
    r = max(1, int(round(Ds / 8)))
    m = cv2.blur(g, (2 * r + 1, 2 * r + 1), borderType=cv2.BORDER_REPLICATE)
    H, W = g.shape
    x = np.clip(np.rint(pts[:, 0]).astype(np.intp), 0, W - 1)
    y = np.clip(np.rint(pts[:, 1]).astype(np.intp), 0, H - 1)
    mean = m[y, x].astype(np.float64)
    if len(mean) == 0:
        return np.zeros(0, bool)
    dark, bright = np.percentile(mean, LIT_PERCENTILES)
    return mean >= dark + LIT_FRACTION * (bright - dark)


def _coefficients(f: np.ndarray, ks: np.ndarray, o_s: np.ndarray, Ds: float, box: int,
                  pts: np.ndarray) -> np.ndarray:
    """(n, 3) local Fourier coefficients of the feature image ``f`` at the reciprocal
    vectors ``ks``, phase relative to the lattice origin ``o_s``, at the points ``pts``;
    relative to the local mean absolute contrast and with the sign making the phase
    closure positive (``V > 0``)."""
    Hs, Ws = f.shape
    wide = max(3, int(round(2 * Ds)) | 1)
    mean = cv2.blur(cv2.blur(f, (wide, wide)), (wide, wide))
    n = f / np.maximum(mean, np.float32(1e-3 * max(float(f.max()), 1e-6))) - np.float32(1.0)
    xs = np.arange(Ws, dtype=np.float64) - o_s[0]
    ys = np.arange(Hs, dtype=np.float64) - o_s[1]
    mx, my = pts[:, 0].reshape(-1, 1), pts[:, 1].reshape(-1, 1)
    z = np.empty((len(pts), 3), dtype=np.complex128)
    for j, k in enumerate(ks):
        ax, ay = 2 * np.pi * k[0] * xs, 2 * np.pi * k[1] * ys
        cx, sx = np.cos(ax).astype(np.float32), np.sin(ax).astype(np.float32)
        cy, sy = np.cos(ay).astype(np.float32), np.sin(ay).astype(np.float32)
        # n exp(-i (ax + ay)) = n (cos ax cos ay - sin ax sin ay) - i n (sin ax cos ay + ...)
        re = n * (np.outer(cy, cx) - np.outer(sy, sx))
        im = n * (np.outer(sy, cx) + np.outer(cy, sx))
        parts = []
        for comp in (re, -im):
            sm = cv2.blur(cv2.blur(comp, (box, box)), (box, box))
            parts.append(remap(sm, mx, my, cv2.INTER_LINEAR,
                                   borderMode=cv2.BORDER_REPLICATE)[:, 0])
        z[:, j] = parts[0] + 1j * parts[1]
    amp_ref = cv2.blur(cv2.blur(np.abs(n), (box, box)), (box, box))
    ref = remap(amp_ref, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)[:, 0]
    z /= np.maximum(ref, 1e-6)[:, None]
    triple = z[:, 0] * z[:, 1] * z[:, 2]
    return z if float(np.sum(triple).real) >= 0 else -z


def _nearest_cell(d: np.ndarray, A: np.ndarray, target: np.ndarray) -> np.ndarray:
    """``d`` moved by whole lattice vectors to the translate nearest ``target``."""
    Ainv = np.linalg.inv(A)
    base = np.round(_mul(target - d, Ainv.T))
    best = d + _mul(base, A.T)
    best_err = np.linalg.norm(best - target, axis=1)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di == dj == 0:
                continue
            cand = d + _mul(base + (di, dj), A.T)
            err = np.linalg.norm(cand - target, axis=1)
            better = err < best_err
            best[better], best_err[better] = cand[better], err[better]
    return best


def _fit_affine(ij: np.ndarray, y: np.ndarray, keep: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """y = P [1, i, j] for the kept rows, trimmed at 3 robust sigmas; (P (2, 3), keep,
    covariance of P's rows (3, 3) per unit variance)."""
    X = np.column_stack([np.ones(len(ij)), ij])
    keep = keep.copy()
    for _ in range(4):
        P = _lstsq(X[keep], y[keep])
        r = np.linalg.norm(_mul(X, P) - y, axis=1)
        sig = 1.4826 * float(np.median(r[keep])) + 1e-3
        new = keep & (r < max(3 * sig, 0.3))
        if new.sum() < MIN_LENSES or np.array_equal(new, keep):
            break
        keep = new
    P = _lstsq(X[keep], y[keep])
    cov = np.linalg.inv(np.einsum("ni,nj->ij", X[keep], X[keep]))
    return P.T, keep, cov


def _similarity(A_file: np.ndarray, A_fit: np.ndarray) -> tuple[float, float]:
    """(scale, angle) of the similarity closest to A_fit A_file^-1 (least squares)."""
    M = A_fit @ np.linalg.inv(A_file)
    a, b = (M[0, 0] + M[1, 1]) / 2, (M[1, 0] - M[0, 1]) / 2
    return math.hypot(a, b), math.atan2(b, a)


def check_grid(image: np.ndarray, grid: MicrolensGrid) -> GridCheck:
    """Measure ``grid`` (from calib.xml) against the micro images of ``image``."""
    import time  # noqa: PLC0415

    t0 = time.perf_counter()
    H, W = image.shape[:2]
    if (W, H) != (grid.width, grid.height):
        raise ValueError(f"grid is for {grid.width}x{grid.height}, image is {W}x{H}")
    D = grid.diameter
    c_file = grid.centres
    # OpenCV's box filters sum along stripes cut by its thread count: one thread keeps the
    # figures (written into convert_setup.json and disparity.json) the same bit for bit
    # whatever the job's cores (a SLURM job of 1 core against a workstation's 16)
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        d, ok, lit = _measure(image, grid.origin, grid.A, c_file)
    finally:
        cv2.setNumThreads(threads)
    ij = grid.ij.astype(float)
    centre = np.array([(W - 1) / 2, (H - 1) / 2])
    warnings: list[str] = []
    # unwrap from the centre outwards: fit near the centre, re-pick each lens's shift
    # nearest the fit's prediction, widen
    r_lens = np.linalg.norm(c_file - centre, axis=1)
    r_max = float(r_lens.max()) + 1
    radius = max(8 * D, 0.15 * r_max)
    central = ok & (r_lens <= radius)
    if central.sum() >= MIN_LENSES:
        # start from the mean shift of the central lenses on the torus (lattice cell):
        # a file half a lens off splits no cluster across the cell's edge
        kd = _mul(d[central], np.linalg.inv(grid.A).T)  # shift in lattice units, mod 1
        frac = np.angle(np.exp(2j * np.pi * kd).sum(axis=0)) / (2 * np.pi)
        d = _nearest_cell(d, grid.A, np.broadcast_to(grid.A @ frac, d.shape))
    P = None
    keep = ok
    cov = np.eye(3)
    while True:
        sel = ok & (r_lens <= radius)
        # the first fit waits for MIN_START lenses (the file's lattice moved by the torus
        # mean unwraps until then), the last one takes what there is
        if sel.sum() >= (MIN_START if P is None and radius < r_max else MIN_LENSES):
            P, keep, cov = _fit_affine(ij, c_file + d, sel)
        if P is not None and radius < r_max:
            pred = _mul(np.column_stack([np.ones(len(ij)), ij]), P.T) - c_file
            d = _nearest_cell(d, grid.A, pred)
        if radius >= r_max:
            break
        radius = min(radius * 1.6, r_max)
    n_lens = len(c_file)
    measured = int(ok.sum())
    share = measured / max(n_lens, 1)
    n_lit = int(lit.sum())
    lit_share = int((ok & lit).sum()) / max(n_lit, 1)
    if P is None:
        warnings.append(f"grid check: only {measured} of {n_lens} lenses measured: cannot fit "
                        "the lattice; either the calib.xml grid does not match the micro "
                        "images (another camera's or another sensor crop's file?) or the "
                        "check cannot see them in this frame (dark, flat)")
        nan2 = (math.nan, math.nan)
        return GridCheck(
            width=W, height=H, diameter_px=float(D), lenses=n_lens, measured=measured,
            measured_share=float(share), lit=n_lit, lit_share=float(lit_share),
            fitted=False, judged_drift_px=math.nan, judged_stderr_px=math.nan,
            drift_max_px=math.nan,
            drift_rms_px=math.nan, drift_stderr_px=math.nan, regions={}, offset_px=nan2,
            pitch_ratio=math.nan, rotation_deg=math.nan, affine=[], origin=nan2, A=[],
            similarity_origin=nan2, residual_rms_px=math.nan,
            similarity_residual_rms_px=math.nan, foreign=False, refine_auto=False,
            verified=False, warnings=warnings, seconds=time.perf_counter() - t0)
    X = np.column_stack([np.ones(len(ij)), ij])
    fit = _mul(X, P.T)
    origin_fit, A_fit = P[:, 0], P[:, 1:]
    scale, ang = _similarity(grid.A, A_fit)
    # the best similarity through the measurements: the lattice a refinement takes (an MLA
    # is a rigid lattice; the affine part's anisotropy and shear are the measurement's,
    # and a view's pixel <-> ray mapping magnifies them: module docstring, "Fit")
    A_sim = similarity_vectors(grid.A, scale, math.degrees(ang))
    o_sim = np.mean((c_file + d)[keep] - _mul(ij[keep], A_sim.T), axis=0)
    lattice = o_sim + _mul(ij, A_sim.T)
    drift = lattice - c_file
    dn = np.linalg.norm(drift, axis=1)
    resid = np.linalg.norm(fit - (c_file + d), axis=1)
    sigma = float(np.sqrt(np.mean(resid[keep] ** 2) / 2))  # per coordinate
    worst = int(np.argmax(dn))
    # neighbouring lenses share their low-pass window (two boxes BOX_LENSES wide): about
    # BOX_LENSES^2 / (sqrt(3)/2) lenses per independent measurement
    corr = math.sqrt(BOX_LENSES ** 2 / (math.sqrt(3) / 2))
    # a lens's standard error of its fitted drift (the fit's covariance at its lattice
    # coordinates): small where the measured lenses are, large where the fit extrapolates
    se = corr * sigma * np.sqrt(np.maximum(np.einsum("ni,ij,nj->n", X, cov, X), 0.0))
    stderr = float(se[worst])
    sim_res = np.linalg.norm(lattice - (c_file + d), axis=1)
    # at the image centre: fitted lattice point minus the file's, same lattice coordinates
    ij_c = (centre - grid.origin) @ np.linalg.inv(grid.A).T
    off = origin_fit + A_fit @ ij_c - centre
    regions = _regions(W, H, D, c_file, drift, d, keep)
    res_rms = float(np.sqrt(np.mean(resid[keep] ** 2)))
    verified = bool(lit_share >= MIN_SHARE)
    foreign = bool(verified and (abs(scale - 1) > FOREIGN_PITCH
                                 or float(np.linalg.norm(off)) > FOREIGN_OFFSET * D
                                 or res_rms > FOREIGN_RESIDUAL * D))
    # the lens whose drift decides: the worst one; on a frame lit on a part of the sensor
    # only (a subject on black) the worst lit one, where the views have content (the worst
    # lens lies in the black, where the fit extrapolates)
    partial = n_lit < PARTIAL_LIT * n_lens
    judged = int(np.flatnonzero(lit)[np.argmax(dn[lit])]) if partial and n_lit else worst
    refine_auto = bool(verified and not foreign and dn[judged] > AUTO_DRIFT_PX
                       and dn[judged] > AUTO_DRIFT_SIGMAS * se[judged])
    if not verified:
        warnings.append(
            f"grid check: only {100 * lit_share:.0f}% of the {n_lit} lit lenses measured: the "
            "check cannot confirm the calib.xml grid on this frame and its figures are "
            "unreliable (fitted "
            f"drift {dn.max():.1f} px); {UNVERIFIED_USE}. Either calib.xml is for "
            "another camera or sensor crop, or the frame's micro images are too dark, flat or "
            "repetitive for the check")
    elif foreign:
        warnings.append(
            f"grid check: the calib.xml grid does not fit the micro images of this frame "
            f"({100 * share:.0f}% of lenses measured, fitted pitch x{scale:.4f}, drift up to "
            f"{dn.max():.1f} px of a {D:.1f} px lens): is calib.xml for this camera and this "
            "sensor crop?")
    elif dn.max() > AUTO_DRIFT_PX:
        warnings.append(_drift_warning(float(dn.max()), None) if refine_auto else
                        _kept_warning(float(dn.max()), float(dn[judged]), float(se[judged]),
                                      partial))
    return GridCheck(
        width=W, height=H, diameter_px=float(D), lenses=n_lens, measured=measured,
        measured_share=float(share), lit=n_lit, lit_share=float(lit_share), fitted=True,
        judged_drift_px=float(dn[judged]), judged_stderr_px=float(se[judged]),
        drift_max_px=float(dn.max()),
        drift_rms_px=float(np.sqrt(np.mean(dn ** 2))), drift_stderr_px=stderr,
        regions=regions, offset_px=(float(off[0]), float(off[1])),
        pitch_ratio=float(scale), rotation_deg=float(math.degrees(ang)),
        affine=(A_fit @ np.linalg.inv(grid.A)).tolist(),
        origin=(float(origin_fit[0]), float(origin_fit[1])), A=A_fit.tolist(),
        residual_rms_px=res_rms, similarity_origin=(float(o_sim[0]), float(o_sim[1])),
        similarity_residual_rms_px=float(np.sqrt(np.mean(sim_res[keep] ** 2))),
        foreign=foreign, refine_auto=refine_auto, verified=verified, warnings=warnings,
        seconds=time.perf_counter() - t0)


def _regions(W: int, H: int, D: float, c: np.ndarray, drift: np.ndarray, d: np.ndarray,
             keep: np.ndarray) -> dict[str, dict[str, float]]:
    """Per region (a square of a fifth of the shorter side at each corner, and at the
    centre): the fitted drift at the lens nearest the region's corner (centre) and the
    median of the lenses measured there."""
    side = max(min(W, H) / 5, 3 * D)
    anchors = {"top_left": (0, 0), "top_right": (W - 1, 0), "centre": ((W - 1) / 2, (H - 1) / 2),
               "bottom_left": (0, H - 1), "bottom_right": (W - 1, H - 1)}
    out = {}
    for name, (ax, ay) in anchors.items():
        a = np.array([ax, ay], dtype=float)
        dist = np.abs(c - a).max(axis=1)
        near = int(np.argmin(np.linalg.norm(c - a, axis=1)))
        reach = side / 2 if name == "centre" else side
        inr = (dist <= reach) & keep
        med = np.median(d[inr], axis=0) if inr.any() else np.array([math.nan, math.nan])
        out[name] = {
            "x": float(c[near, 0]), "y": float(c[near, 1]),
            "fit_dx_px": float(drift[near, 0]), "fit_dy_px": float(drift[near, 1]),
            "fit_drift_px": float(np.linalg.norm(drift[near])),
            "measured_dx_px": float(med[0]), "measured_dy_px": float(med[1]),
            "measured_lenses": int(inr.sum()),
        }
    return out


# ---------------------------------------------------------------------------
# refinement
# ---------------------------------------------------------------------------


def refine_grid(grid: MicrolensGrid | RayCalib, check: GridCheck) -> MicrolensGrid:
    """The grid on the fitted lattice's similarity: the file's lattice scaled by the fitted
    pitch, turned by the fitted rotation and placed through the measurements (same lens
    indices and types as the file's grid; ``grid`` may be that grid or its RayCalib); its
    ``calib`` is :func:`refine_calib`'s, which holds the same similarity (diameter: the
    fitted mean pitch). Not the affine fit: module docstring, "Fit"."""
    if not check.fitted:
        raise ValueError("grid check found too few lenses to fit the lattice: cannot refine")
    if isinstance(grid, RayCalib):
        grid = MicrolensGrid(grid, check.width, check.height)
    calib = refine_calib(grid.calib, check)
    return MicrolensGrid(calib, grid.width, grid.height,
                         lattice=(np.array(check.similarity_origin), similarity_vectors(
                             grid.A, check.pitch_ratio, check.rotation_deg)))


def similarity_vectors(A_file: np.ndarray, pitch_ratio: float, rotation_deg: float
                       ) -> np.ndarray:
    """(2, 2) the file's lattice vectors (columns, image axes) scaled by ``pitch_ratio`` and
    turned by ``rotation_deg`` (image frame, y down): the refined lattice's."""
    a = math.radians(rotation_deg)
    S = pitch_ratio * np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    return S @ np.asarray(A_file, dtype=float)


def refine_calib(calib: RayCalib, check: GridCheck) -> RayCalib:
    """The RayCalibData closest to the fitted lattice: offset, diameter and rotation of its
    best similarity (a RayCalib cannot hold the affine part; see
    ``GridCheck.similarity_residual_rms_px`` for what it leaves)."""
    if not check.fitted:
        raise ValueError("grid check found too few lenses to fit the lattice: cannot refine")
    W, H = check.width, check.height
    ox = check.similarity_origin[0] - (W - 1) / 2
    oy = (H - 1) / 2 - check.similarity_origin[1]
    # image-frame rotation (y down) is the file's rotation (y up) negated
    return replace(calib, offset=(float(ox), float(oy)),
                   diameter=float(calib.diameter * check.pitch_ratio),
                   rotation=float(calib.rotation - math.radians(check.rotation_deg)))
