"""What the view-synthesis experiments of Section III (Fig. 6) read and render: the
array's layout, and each experiment's input and target views (:func:`experiment_plan`).
Needs no image, calibration or renderer, so the workflow plans the synthesis depth maps
with it while the Snakefile is read (rules/common.smk) without importing the renderers
(:mod:`plenocal.verify.synthesis` runs the experiments)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from plenocal.config import stage_defaults
from plenocal.names import array_position, array_shot, central_view, is_array_shot, view_name


@dataclass(frozen=True)
class ArrayLayout:
    cols: int
    rows: int
    n_views: int

    def cam(self, col: int, row: int) -> str:
        return array_shot(col, row)

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

    def exp2_cams(self, exp2_sets: str) -> list[str]:
        """The shots whose sets Exp. 2 runs on, by the config's ``verify.exp2_sets``:
        ``middle`` (the middle shot's set, Fig. 8) or ``all`` (every array shot's)."""
        return [self.middle_cam] if exp2_sets == "middle" else self.cams

    def side_views(self) -> list[str]:
        """Middle views of the four sides of the N x N set (Fig. 6b)."""
        n, h = self.n_views, (self.n_views - 1) // 2
        return [view_name(0, h), view_name(h, 0), view_name(h, n - 1), view_name(n - 1, h)]


def layout_from_cams(cams: list[str], n_views: int) -> ArrayLayout:
    pos = [array_position(c) for c in cams if is_array_shot(c)]
    if not pos:
        raise ValueError("synthesis: no array shot (x<col>_y<row>) among the cameras")
    cols = max(c for c, _ in pos) + 1
    rows = max(r for _, r in pos) + 1
    return ArrayLayout(cols, rows, n_views)


def all_views(n: int) -> list[str]:
    return [view_name(r, c) for r in range(n) for c in range(n)]


def experiment_plan(layout: ArrayLayout, exp: int, exp2_cams: list[str] | None = None,
                    stride: int = 1,
                    lateral: Callable[[str], str] | None = None) -> dict[str, tuple[list[str],
                                                                                   list[str]]]:
    """The (inputs, targets) of experiment ``exp`` by run name: ``exp1``;
    ``exp2_<cam>`` per set of ``exp2_cams`` (default the middle shot's; the config's
    choice: :meth:`ArrayLayout.exp2_cams`); ``exp3_central`` and ``exp3_lateral`` (every
    ``stride``-th view row/column, the centre always included; ``lateral`` maps a corner
    shot to its lateral view, default :func:`inner_corner_view`)."""
    L = layout
    n, cv = L.n_views, L.centre_view
    corners = [f"{c}/{cv}" for c in L.corners]
    if exp == 1:
        return {"exp1": (corners, [f"{c}/{cv}" for c in L.cams if f"{c}/{cv}" not in corners])}
    if exp == 2:
        out = {}
        for cam in exp2_cams or [L.middle_cam]:
            inputs = [f"{cam}/{v}" for v in L.side_views()]
            out[f"exp2_{cam}"] = (inputs, [f"{cam}/{v}" for v in all_views(n)
                                           if f"{cam}/{v}" not in inputs])
        return out
    if exp == 3:
        h = (n - 1) // 2
        idx = sorted({i for i in range(n) if (i - h) % stride == 0})
        views = [view_name(r, c) for r in idx for c in idx]
        lat = lateral or (lambda cam: inner_corner_view(L, cam))
        out = {}
        for variant, inputs in (("central", corners),
                                ("lateral", [f"{c}/{lat(c)}" for c in L.corners])):
            out[f"exp3_{variant}"] = (inputs, [f"{c}/{v}" for c in L.cams for v in views
                                               if f"{c}/{v}" not in inputs])
        return out
    raise ValueError(f"synthesis: no experiment {exp} (1, 2 or 3)")


def inner_corner_view(layout: ArrayLayout, cam: str) -> str:
    """The corner view of shot ``cam``'s set on the array's inner side by the view and
    shot numbering (view row/column grow with the shot row/column): what
    :func:`lateral_view` finds with a calibration, known before any calibration."""
    n = layout.n_views - 1
    col, row = array_position(cam)
    return view_name(n if 2 * row < layout.rows - 1 else 0, n if 2 * col < layout.cols - 1 else 0)


def experiment_input_views(layout: ArrayLayout, exp: int,
                           exp2_sets: str = stage_defaults("verify")["exp2_sets"]) -> list[str]:
    """The views whose depth maps experiment ``exp`` reads (Exp. 3's lateral views as
    :func:`inner_corner_view` predicts them)."""
    plan = experiment_plan(layout, exp, layout.exp2_cams(exp2_sets))
    return list(dict.fromkeys(k for inputs, _ in plan.values() for k in inputs))
