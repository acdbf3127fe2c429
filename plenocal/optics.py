"""Optics of a focused plenoptic (plenoptic 2.0) camera, Keplerian or Galilean.

Two families of functions live here:

* the paper's formulas of Section II-C (one function per formula, named after the
  symbol it returns), used by registration B; lengths in millimetres unless a
  name says otherwise, disparities in multiview pixels;
* :class:`PlenopticOptics`, the exact thin-lens model of Fig. 2 that the simulator
  renders with and from which the ground truth and the ``exact`` view model follow.

Geometry of Fig. 2 (exact model). The main lens (focal ``F``) sits at z = 0 with
the optical axis along +z towards the scene (OpenCV camera axes: x right, y down,
z forward). Focused at ``X_o`` it forms the image of that plane at ``F + e``
behind it, ``e = F^2 / (X_o - F)``. The MLA (microlens pitch ``D``, focal
``f = F_n D``) is ``t`` behind that image, so at ``L = F + e + t``; the sensor is
``s`` behind the MLA with ``1/s + 1/t = 1/f`` (sharp), ``s = k f / (k - 1)`` and
``t = k f``. A point whose main-lens image lies ``a`` in front of the MLA has
virtual depth ``v = a / s`` and appears in neighbouring micro images shifted by
``D s (1/a - 1/L)`` (metres on the sensor; for ``a << L`` this is ``D / v``).

Galilean set-up: the MLA stands in front of the main-lens image, which the microlenses
see as a virtual object ``|t| = k f`` behind them (``1/s = 1/f + 1/(k f)``, so
``s = k f / (k + 1) < f``); lengths ``t``, ``a`` and the virtual depth ``v`` are then
negative and the micro images upright. Multi-focus MLAs (Raytrix): every lens type
has its own focal length ``f_i``, all share ``s``; a type images sharply the virtual
depth ``v_i = 1 / kappa_i`` with ``kappa_i = s / f_i - 1``, and a point at virtual
depth ``v`` is blurred on the sensor into a disc of ``D |kappa_i - 1/v|`` (metres).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

SIN45 = math.sin(math.radians(45.0))


# ---------------------------------------------------------------------------
# The paper's formulas (Section II-C), one per symbol.
# ---------------------------------------------------------------------------


def multiview_pixel_size(p: float, w: float, W: float) -> float:
    """P = p * w / W: pixel size of a multiview image (same unit as ``p``)."""
    return p * w / W


def main_lens_focal(F_m: float, P: float) -> float:
    """F = F_m * P: main-lens focal length from the multiview focal length in pixels."""
    return F_m * P


def microlens_focal(F_n: float, D: float) -> float:
    """f = F_n * D: focal length of a microlens of diameter ``D`` and F-number ``F_n``."""
    return F_n * D


def middle_f_number(f_numbers: list[float] | tuple[float, ...] | float) -> float:
    """The paper's rule for multi-focus MLAs: use the middle of the F-numbers."""
    if isinstance(f_numbers, int | float):
        return float(f_numbers)
    values = sorted(float(x) for x in f_numbers)
    if not values:
        raise ValueError("no microlens F-number given")
    return values[len(values) // 2]


def mla_sensor_distance(k: float, f: float) -> float:
    """s = k f / (k - 1): MLA-to-sensor distance from the paper's ``k``."""
    if k <= 1:
        raise ValueError(f"k must be > 1 (got {k})")
    return k * f / (k - 1.0)


def sharp_image_distance(s: float, f: float) -> float:
    """t = s f / (s - f): distance in front of the MLA imaged sharply on the sensor."""
    if s <= f:
        raise ValueError(f"s ({s}) must exceed the microlens focal length f ({f})")
    return s * f / (s - f)


def focus_shift(F: float, X_o: float) -> float:
    """e = F^2 / (X_o - F): image of the focus plane lies at F + e behind the main lens."""
    if X_o <= F:
        raise ValueError(f"focus distance X_o ({X_o}) must exceed the focal length F ({F})")
    return F * F / (X_o - F)


def safe_diameter(D: float, lens_border: float = 1.0) -> float:
    """D' = D - 2 * lens_border (the paper: D' = D - 2 px)."""
    return D - 2.0 * lens_border


def view_spacing(D_safe: float, N: int) -> float:
    """q = D' sin(45 deg) / N: distance between neighbouring view points in a micro image."""
    return D_safe * SIN45 / N


def ray_angle(q: float, s: float) -> float:
    """beta = arctan(q / s) (``q`` and ``s`` in the same unit)."""
    return math.atan2(q, s)


def baseline(F: float, beta: float) -> float:
    """B = F tan(beta): baseline between neighbouring subaperture views."""
    return F * math.tan(beta)


def convergence_offset(e: float, t: float, beta: float) -> float:
    """C = (e + t) tan(beta)."""
    return (e + t) * math.tan(beta)


def rotation_angle(C: float, F: float) -> float:
    """alpha = arctan(C / F): rotation between neighbouring views (paper model)."""
    return math.atan2(C, F)


def convergence_distance(B: float, alpha: float) -> float:
    """X_c = B / tan(alpha): distance of the plane where the views converge."""
    return B / math.tan(alpha)


def object_distance(B: float, F: float, C: float, disparity: float, P: float) -> float:
    """Eq. 1: X = B F / (C + disparity * P) (X_n for D_max, X_f for D_min)."""
    return B * F / (C + disparity * P)


def baseline_from_range(P: float, D_max: float, D_min: float, F: float, X_n: float,
                        X_f: float) -> float:
    """Eq. 2: B = P (D_max - D_min) / (F (1/X_n - 1/X_f))."""
    return P * (D_max - D_min) / (F * (1.0 / X_n - 1.0 / X_f))


def alpha_from_range(B: float, F: float, X_n: float, D_max: float, P: float) -> float:
    """Eq. 3: alpha = arctan((B F / X_n - D_max P) / F)."""
    return math.atan((B * F / X_n - D_max * P) / F)


def rotation_matrix(alpha_h: float, alpha_v: float) -> np.ndarray:
    """R(alpha_h, alpha_v) of Eq. 4 in OpenCV camera axes (x right, y down, z forward).

    A view right of the centre (h > 0) turns towards the centre: a rotation of
    ``-alpha_h`` about the y axis; a view below (v > 0) turns up: ``+alpha_v``
    about the x axis. Returned as the camera-to-reference rotation.
    """
    cy, sy = math.cos(-alpha_h), math.sin(-alpha_h)
    cx, sx = math.cos(alpha_v), math.sin(alpha_v)
    Ry = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, cx, -sx], [0.0, sx, cx]])
    return Ry @ Rx


def view_extrinsic(h: float, v: float, B: float, alpha: float) -> np.ndarray:
    """Eq. 4: M_j^B = [R(h alpha, v alpha) | (h B, v B, 0)], camera-to-central-view, 4x4."""
    M = np.eye(4)
    M[:3, :3] = rotation_matrix(h * alpha, v * alpha)
    M[:3, 3] = (h * B, v * B, 0.0)
    return M


# ---------------------------------------------------------------------------
# The exact thin-lens model.
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class PlenopticOptics:
    """Exact thin-lens model of one focused plenoptic camera (lengths in metres).

    ``mla_pitch`` is the physical microlens pitch; the micro *images* on the sensor
    are larger by ``(L + s) / L`` because they are central projections of the
    lenses from the main-lens centre (what a Raytrix ``calib.xml`` records).
    """

    focal_length: float  # F
    focus_distance: float  # X_o, from the main lens
    mla_pitch: float  # D (physical)
    mla_f_number: float  # F_n
    k: float  # s = k f / (k - 1)
    pixel_size: float  # p
    width: int  # sensor pixels
    height: int
    aperture_scale: float = 1.0  # main-lens aperture relative to the F-number match
    kind: str = "keplerian"  # or "galilean"
    # focal length of each lens type relative to f (type ids 0, 1, ...); (1,) single-focus
    type_focal_ratios: tuple[float, ...] = (1.0,)

    def __post_init__(self) -> None:
        if self.kind not in ("keplerian", "galilean"):
            raise ValueError(f"kind must be 'keplerian' or 'galilean' (got {self.kind!r})")
        if not self.type_focal_ratios or min(self.type_focal_ratios) <= 0:
            raise ValueError(f"type_focal_ratios must be > 0 (got {self.type_focal_ratios})")
        object.__setattr__(self, "type_focal_ratios",
                           tuple(float(r) for r in self.type_focal_ratios))

    # -- derived lengths (paper symbols) --------------------------------------
    @property
    def f(self) -> float:
        return microlens_focal(self.mla_f_number, self.mla_pitch)

    @property
    def galilean(self) -> bool:
        return self.kind == "galilean"

    @property
    def s(self) -> float:
        """MLA-to-sensor distance: k f / (k - 1) (Keplerian), k f / (k + 1) (Galilean)."""
        if self.galilean:
            if self.k <= 0:
                raise ValueError(f"k must be > 0 (got {self.k})")
            return self.k * self.f / (self.k + 1.0)
        return mla_sensor_distance(self.k, self.f)

    @property
    def t(self) -> float:
        """Signed distance in front of the MLA imaged sharply by the reference lens type:
        k f (Keplerian), -k f (Galilean: a virtual object behind the MLA)."""
        return self.type_t(None)

    # -- lens types (multi-focus MLA) ---------------------------------------------
    @property
    def lens_types(self) -> int:
        return len(self.type_focal_ratios)

    def type_f(self, lens_type: int | None) -> float:
        """Focal length of a lens type (``None``: the reference type, f)."""
        return self.f if lens_type is None else self.f * self.type_focal_ratios[lens_type]

    def type_t(self, lens_type: int | None) -> float:
        """Signed sharp object distance s f_i / (s - f_i) of a lens type (thin lens)."""
        s, fi = self.s, self.type_f(lens_type)
        if s == fi:
            raise ValueError("a lens type with f = s images infinity: no sharp plane")
        return s * fi / (s - fi)

    def type_kappa(self, lens_type: int | None) -> float:
        """kappa_i = s / f_i - 1 = 1 / v_i: inverse sharp virtual depth of a lens type."""
        return self.s / self.type_f(lens_type) - 1.0

    def blur_px(self, v: np.ndarray | float, lens_type: int | None) -> np.ndarray | float:
        """Defocus disc diameter (pixels) of a point at (signed) virtual depth ``v`` seen
        through a lens of the given type: D |kappa_i - 1/v| / p."""
        v = np.asarray(v, dtype=np.float64)
        out = self.mla_pitch * np.abs(self.type_kappa(lens_type) - 1.0 / v) / self.pixel_size
        return out if out.ndim else float(out)

    def depth_of_field(self, lens_type: int | None, blur_px: float) -> tuple[float, float]:
        """|virtual depth| range in which the type's blur disc stays within ``blur_px``
        pixels: 1/|v| in [|kappa_i| - w, |kappa_i| + w], w = blur_px p / D (inf: far end
        open)."""
        w = blur_px * self.pixel_size / self.mla_pitch
        kap = abs(self.type_kappa(lens_type))
        lo = 1.0 / (kap + w)
        hi = 1.0 / (kap - w) if kap > w else math.inf
        return lo, hi

    @property
    def e(self) -> float:
        return focus_shift(self.focal_length, self.focus_distance)

    @property
    def L(self) -> float:
        """Main lens to MLA distance, F + e + t."""
        return self.focal_length + self.e + self.t

    @property
    def aperture(self) -> float:
        """Main-lens aperture diameter whose micro images just tile: A = D L / s."""
        return self.aperture_scale * self.mla_pitch * self.L / self.s

    @property
    def micro_image_pitch_px(self) -> float:
        """Pitch of the micro images on the sensor in pixels, D (L + s) / (L p)."""
        return self.mla_pitch * (self.L + self.s) / (self.L * self.pixel_size)

    @property
    def mla_conjugate_distance(self) -> float:
        """Z0 = F L / (L - F): object distance imaged onto the MLA (zero view disparity)."""
        F, L = self.focal_length, self.L
        return F * L / (L - F)

    # -- depth relations ---------------------------------------------------------
    def image_distance(self, Z: np.ndarray | float) -> np.ndarray | float:
        """Thin lens: distance behind the main lens of the image of depth ``Z``."""
        F = self.focal_length
        return F * Z / (Z - F)

    def virtual_depth(self, Z: np.ndarray | float) -> np.ndarray | float:
        """v = a / s with a = L - b(Z): > 0 Keplerian (image in front of the MLA), < 0
        Galilean (image behind it)."""
        return (self.L - self.image_distance(Z)) / self.s

    def depth_from_virtual_depth(self, v: np.ndarray | float) -> np.ndarray | float:
        b = self.L - np.asarray(v) * self.s
        F = self.focal_length
        return F * b / (b - F)

    def measured_virtual_depth(self, Z: np.ndarray | float) -> np.ndarray | float:
        """|v| as a RayCalibData file's readers take it: ``D / |P(Z)|``, the micro-image
        pitch over the exact micro-image disparity (:meth:`micro_image_disparity_px`), the
        relation ``P = D / v`` by which the converter turns a lens type's depth range into
        patch sizes (:func:`plenocal.convert.patchsize.type_ranges`). It is what matching
        measures; :meth:`virtual_depth`, the physical ``a / s``, leaves out the main lens's
        convergence and the micro images' wider pitch, and differs from it by
        ``(1 + s / L) / (1 - a / L)``: by 3-8 % on the accuracy bench's cameras, by 15-19 %
        on ``tspc-like``'s (a 25 mm main lens)."""
        return self.micro_image_pitch_px / np.abs(self.micro_image_disparity_px(Z))

    def micro_image_disparity_px(self, Z: np.ndarray | float) -> np.ndarray | float:
        """Shift of a point at depth Z between neighbouring micro images (pixels).

        Exact: ``D s (1/a - 1/L) / p``; this is the converter's patch size.
        """
        a = self.L - self.image_distance(Z)
        return self.mla_pitch * self.s * (1.0 / a - 1.0 / self.L) / self.pixel_size

    def to_dict(self) -> dict:
        d = asdict(self)
        d["type_focal_ratios"] = list(self.type_focal_ratios)
        d.update(
            f=self.f, s=self.s, t=self.t, e=self.e, L=self.L, aperture=self.aperture,
            micro_image_pitch_px=self.micro_image_pitch_px,
            mla_conjugate_distance=self.mla_conjugate_distance,
        )
        return d

    # -- ray geometry -------------------------------------------------------------
    def sensor_to_metric(self, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Sensor pixel (u right, v down; centres at integers) to metric (x, y) in the
        camera frame. The image on the sensor is inverted, so the readout turns it by
        180 degrees, as in any camera: pixel +u is metric -x."""
        cx = (self.width - 1) / 2.0
        cy = (self.height - 1) / 2.0
        return -(u - cx) * self.pixel_size, -(v - cy) * self.pixel_size

    def metric_to_sensor(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        cx = (self.width - 1) / 2.0
        cy = (self.height - 1) / 2.0
        return cx - x / self.pixel_size, cy - y / self.pixel_size

    def chief_rays(self, sensor_uv: np.ndarray, lens_uv: np.ndarray) -> tuple[np.ndarray,
                                                                                np.ndarray]:
        """Scene-side rays of sensor points seen through microlens centres.

        ``sensor_uv`` are sensor pixel positions, ``lens_uv`` the micro-image centres
        (pixels) of the lenses the rays pass through; the physical lens centre is the
        micro-image centre scaled by ``L / (L + s)`` towards the optical axis.
        Returns (origins on the main-lens plane z = 0, unit directions), camera frame.
        """
        sensor_uv = np.asarray(sensor_uv, dtype=np.float64)
        lens_uv = np.asarray(lens_uv, dtype=np.float64)
        L, s, F = self.L, self.s, self.focal_length
        xs, ys = self.sensor_to_metric(sensor_uv[..., 0], sensor_uv[..., 1])
        mx, my = self.sensor_to_metric(lens_uv[..., 0], lens_uv[..., 1])
        cx, cy = mx * L / (L + s), my * L / (L + s)
        # slope (per +z) from the sensor point through the lens centre
        sx, sy = (cx - xs) / s, (cy - ys) / s
        hx, hy = cx + L * sx, cy + L * sy  # where the ray meets the main lens
        # ideal thin lens, tangent slopes: u' = u - h / F
        ox, oy = sx - hx / F, sy - hy / F
        d = np.stack([ox, oy, np.ones_like(ox)], axis=-1)
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        o = np.stack([hx, hy, np.zeros_like(hx)], axis=-1)
        return o, d
