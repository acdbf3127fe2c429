"""The view-synthesis experiments of Section III (Figs. 6-9), as functions of a
calibration (cameras dict ``"<cam>/<view>" -> PinholeCamera``), the captured views
and the ``verify`` config, so that the same experiment runs on the complete
calibration and on the ground-truth cameras (the dB lost to calibration).

For each experiment: the depth of every input view is estimated by the plane sweep
with the calibration under test (sources: the same view of the nearest other array
shots and the nearest views of the input's own set), the targets are synthesized by
DIBR (:mod:`plenocal.dibr`) from the inputs, and each is scored by PSNR against the
captured (converted) view, excluding a border.

- Exp. 1 (Fig. 6a / 7): central view of every array shot from the central views of
  the four corner shots; grid = array rows x cols.
- Exp. 2 (Fig. 6b / 8): every view of an N x N set from the middle views of its four
  sides; one grid N x N per set.
- Exp. 3 (Fig. 6c, d / 9): every view of every array shot from the corner shots'
  central views (a) and from their lateral views (b), "lateral" being the view of
  each corner set nearest the array centre (the inner corner view, Fig. 6d); grid =
  (rows N) x (cols N), the views of shot (x, y) in block (y, x).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from plenocal.camera import PinholeCamera
from plenocal.depth import planesweep_options
from plenocal.depth.inputs import nearest_sources
from plenocal.depth.planesweep import plane_sweep_depth
from plenocal.dibr import DibrOptions, View, psnr, synthesize
from plenocal.io import read_image, to_float
from plenocal.viewgeom import central_view, parse_view, view_name

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ArrayLayout:
    cols: int
    rows: int
    n_views: int

    def cam(self, col: int, row: int) -> str:
        return f"x{col:02d}_y{row:02d}"

    @property
    def cams(self) -> list[str]:
        return [self.cam(c, r) for r in range(self.rows) for c in range(self.cols)]

    @property
    def corners(self) -> list[str]:
        cs = [(0, 0), (self.cols - 1, 0), (0, self.rows - 1), (self.cols - 1, self.rows - 1)]
        return sorted({self.cam(c, r) for c, r in cs})

    @property
    def centre_view(self) -> str:
        return central_view(self.n_views)

    @property
    def middle_cam(self) -> str:
        cams = self.cams
        return cams[len(cams) // 2]

    def side_views(self) -> list[str]:
        """Middle views of the four sides of the N x N set (Fig. 6b)."""
        n, h = self.n_views, (self.n_views - 1) // 2
        return [view_name(0, h), view_name(h, 0), view_name(h, n - 1), view_name(n - 1, h)]


def layout_from_cams(cams: list[str], n_views: int) -> ArrayLayout:
    arr = [c for c in cams if c.startswith("x")]
    if not arr:
        raise ValueError("synthesis: no array shot (x<col>_y<row>) among the cameras")
    cols = max(int(c[1:3]) for c in arr) + 1
    rows = max(int(c[5:7]) for c in arr) + 1
    return ArrayLayout(cols, rows, n_views)


@dataclass
class SynthesisContext:
    """What every experiment needs, for one calibration."""
    cameras: dict[str, PinholeCamera]
    image_path: Callable[[str, str], str]
    layout: ArrayLayout
    near: float
    far: float
    config: dict = field(default_factory=dict)
    _images: dict = field(default_factory=dict)
    _depths: dict = field(default_factory=dict)

    def camera(self, key: str) -> PinholeCamera:
        if key not in self.cameras:
            raise KeyError(f"synthesis: view {key} is not in the calibration; was it "
                           "registered? (check the calibration's cameras.json)")
        return self.cameras[key]

    def image(self, key: str) -> np.ndarray:
        if key not in self._images:
            cam, view = key.split("/")
            img = to_float(read_image(self.image_path(cam, view)))
            c = self.camera(key)
            if img.shape[:2] != (c.height, c.width):
                raise ValueError(f"synthesis: {self.image_path(cam, view)} is "
                                 f"{img.shape[1]}x{img.shape[0]}, its camera says "
                                 f"{c.width}x{c.height}")
            self._images[key] = img
        return self._images[key]

    def depth_sources(self, key: str) -> list[str]:
        cam, view = key.split("/")
        k_shots = int(self.config.get("depth_sources_shots", 4))
        k_set = int(self.config.get("depth_sources_set", 4))
        same_view = [f"{c}/{view}" for c in self.layout.cams if f"{c}/{view}" in self.cameras]
        own_set = [f"{cam}/{v}" for v in _all_views(self.layout.n_views)
                   if f"{cam}/{v}" in self.cameras]
        picked = nearest_sources(key, self.cameras, k_shots, same_view)
        picked += nearest_sources(key, self.cameras, k_set, own_set)
        if not picked:
            raise ValueError(f"synthesis: no source view to estimate the depth of {key}")
        return picked

    def depth(self, key: str) -> np.ndarray:
        if key not in self._depths:
            srcs = self.depth_sources(key)
            log.info("depth of %s from %s", key, ", ".join(srcs))
            self._depths[key] = plane_sweep_depth(
                self.camera(key), self.image(key), [self.camera(s) for s in srcs],
                [self.image(s) for s in srcs], self.near, self.far,
                planesweep_options(self.config.get("depth", {})))
        return self._depths[key]

    def synthesize(self, inputs: list[str], target: str) -> tuple[np.ndarray, np.ndarray]:
        views = [View(self.camera(k), self.image(k), self.depth(k)) for k in inputs]
        return synthesize(views, self.camera(target), dibr_options(self.config))

    def score(self, inputs: list[str], targets: list[str],
              keep: set[str] | None = None) -> tuple[dict[str, float], dict[str, np.ndarray]]:
        border = int(self.config.get("psnr_border_px", 8))
        scores, kept = {}, {}
        for t in targets:
            out, _ = self.synthesize(inputs, t)
            scores[t] = psnr(out, self.image(t), border)
            log.info("synthesized %s: %.2f dB", t, scores[t])
            if keep and t in keep:
                kept[t] = out
        return scores, kept


def lateral_view(ctx: SynthesisContext, cam: str) -> str:
    """The view of shot ``cam``'s set whose camera centre is nearest the centre of the
    array's central views (the inner corner view of Fig. 6d), by the calibration under
    test."""
    L = ctx.layout
    cv = L.centre_view
    centres = [ctx.camera(f"{c}/{cv}").centre for c in L.cams if f"{c}/{cv}" in ctx.cameras]
    mid = np.mean(centres, axis=0)
    views = [v for v in _all_views(L.n_views) if f"{cam}/{v}" in ctx.cameras]
    return min(views, key=lambda v: (float(np.linalg.norm(ctx.camera(f"{cam}/{v}").centre
                                                          - mid)), v))


def _all_views(n: int) -> list[str]:
    return [view_name(r, c) for r in range(n) for c in range(n)]


def dibr_options(cfg: dict) -> DibrOptions:
    d = cfg.get("dibr", {}) or {}
    return DibrOptions(**{k: v for k, v in d.items() if k in DibrOptions.__dataclass_fields__})


def _summary(scores: dict[str, float]) -> dict:
    vals = np.array(list(scores.values()), dtype=float)
    if len(vals) == 0:
        return {"mean_psnr": None, "min_psnr": None, "max_psnr": None, "count": 0}
    return {"mean_psnr": float(vals.mean()), "min_psnr": float(vals.min()),
            "max_psnr": float(vals.max()), "count": int(len(vals))}


def experiment1(ctx: SynthesisContext) -> tuple[dict, dict[str, np.ndarray]]:
    """Central views of every array shot from the corner shots' central views."""
    L = ctx.layout
    cv = L.centre_view
    inputs = [f"{c}/{cv}" for c in L.corners]
    targets = [f"{c}/{cv}" for c in L.cams if f"{c}/{cv}" not in inputs]
    keep = {f"{L.middle_cam}/{cv}"}
    scores, kept = ctx.score(inputs, targets, keep)
    grid = [[scores.get(f"{L.cam(c, r)}/{cv}") for c in range(L.cols)] for r in range(L.rows)]
    return {"inputs": inputs, "psnr": scores, "grid": grid, **_summary(scores)}, kept


def experiment2(ctx: SynthesisContext, cams: list[str]) -> tuple[dict, dict[str, np.ndarray]]:
    """Every view of the N x N sets of ``cams`` from the middle views of their sides."""
    L = ctx.layout
    n = L.n_views
    sets, all_scores, kept = {}, {}, {}
    for cam in cams:
        inputs = [f"{cam}/{v}" for v in L.side_views()]
        targets = [f"{cam}/{v}" for v in _all_views(n) if f"{cam}/{v}" not in inputs]
        scores, k = ctx.score(inputs, targets, {f"{cam}/{L.centre_view}"})
        kept.update(k)
        grid = [[scores.get(f"{cam}/{view_name(r, c)}") for c in range(n)] for r in range(n)]
        sets[cam] = {"inputs": inputs, "psnr": scores, "grid": grid, **_summary(scores)}
        all_scores.update(scores)
    return {"sets": sets, **_summary(all_scores)}, kept


def experiment3(ctx: SynthesisContext, stride: int = 1) -> tuple[dict, dict[str, np.ndarray]]:
    """Every view of every array shot (every ``stride``-th view row/column, the centre
    always included) from the corner shots' central (a) and lateral (b) views."""
    L = ctx.layout
    n = L.n_views
    h = (n - 1) // 2
    idx = sorted({i for i in range(n) if (i - h) % stride == 0})
    views = [view_name(r, c) for r in idx for c in idx]
    result, kept = {}, {}
    for variant, inputs in (("central", [f"{c}/{L.centre_view}" for c in L.corners]),
                            ("lateral", [f"{c}/{lateral_view(ctx, c)}" for c in L.corners])):
        targets = [f"{c}/{v}" for c in L.cams for v in views if f"{c}/{v}" not in inputs]
        keep = {f"{L.middle_cam}/{L.centre_view}"}
        scores, k = ctx.score(inputs, targets, keep)
        kept.update({f"{variant}:{key}": img for key, img in k.items()})
        grid = [[None] * (L.cols * n) for _ in range(L.rows * n)]
        for key, val in scores.items():
            cam, view = key.split("/")
            r, c = parse_view(view)
            grid[int(cam[5:7]) * n + r][int(cam[1:3]) * n + c] = val
        result[variant] = {"inputs": inputs, "psnr": scores, "grid": grid, **_summary(scores)}
    result["view_stride"] = stride
    return result, kept


def lost_db(ours: dict, truth: dict) -> float | None:
    """Mean PSNR with ground-truth cameras minus mean PSNR with the calibration."""
    if ours.get("mean_psnr") is None or truth.get("mean_psnr") is None:
        return None
    return float(truth["mean_psnr"] - ours["mean_psnr"])
