"""Figures of the report, drawn without matplotlib: embedded raster previews, SVG heat
maps (the PSNR grids of Figs. 7-9) and an SVG drawing of the camera array.

Every function returns text (a data URI or an SVG element) whose bytes depend only on
its inputs: coordinates are printed with fixed precision, colours come from a fixed
table, and images are re-encoded with fixed settings.
"""

from __future__ import annotations

import base64
import math
from collections.abc import Mapping, Sequence
from html import escape
from pathlib import Path

import numpy as np

from plenocal.names import key_shot, middle_view, split_key

# Viridis at 9 evenly spaced stops (sRGB): interpolated linearly in between.
_VIRIDIS = np.array([
    [68, 1, 84], [71, 44, 122], [59, 81, 139], [44, 113, 142], [33, 144, 141],
    [39, 173, 129], [92, 200, 99], [170, 220, 50], [253, 231, 37]], dtype=float)


def colour(t: float) -> tuple[int, int, int]:
    """Viridis colour of ``t`` in [0, 1] (clipped)."""
    t = min(max(float(t), 0.0), 1.0) * (len(_VIRIDIS) - 1)
    i = min(int(math.floor(t)), len(_VIRIDIS) - 2)
    c = _VIRIDIS[i] + (t - i) * (_VIRIDIS[i + 1] - _VIRIDIS[i])
    return int(round(c[0])), int(round(c[1])), int(round(c[2]))


def hex_colour(rgb: tuple[int, int, int]) -> str:
    return "#{:02x}{:02x}{:02x}".format(*rgb)


def text_colour(rgb: tuple[int, int, int]) -> str:
    """Black or white, whichever reads better on ``rgb``."""
    lum = 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]
    return "#000" if lum > 110 else "#fff"


def _f(x: float) -> str:
    """Fixed-precision SVG coordinate."""
    s = f"{x:.1f}"
    return "0.0" if s == "-0.0" else s


# ---------------------------------------------------------------------------
# Raster previews
# ---------------------------------------------------------------------------


def to_preview(img: np.ndarray, max_side: int = 360) -> np.ndarray:
    """8-bit BGR/gray preview: 16-bit and float images stretched between their 1st and
    99th percentiles (previews of depth and patch-size maps), big ones downscaled."""
    import cv2  # noqa: PLC0415

    if img.ndim == 3 and img.shape[2] == 4:
        img = img[:, :, :3]
    if img.dtype != np.uint8:
        f = img.astype(np.float64)
        ok = np.isfinite(f)
        if ok.any():
            lo, hi = np.percentile(f[ok], [1, 99])
        else:
            lo, hi = 0.0, 1.0
        f = np.where(ok, (f - lo) / (hi - lo if hi > lo else 1.0), 0.0)
        img = np.clip(np.rint(f * 255.0), 0, 255).astype(np.uint8)
    h, w = img.shape[:2]
    scale = max_side / max(h, w)
    if scale < 1.0:
        size = (max(1, int(round(w * scale))), max(1, int(round(h * scale))))
        img = cv2.resize(img, size, interpolation=cv2.INTER_AREA)
    return np.ascontiguousarray(img)


def image_data_uri(path: str | Path, max_side: int = 360, quality: int = 85,
                   crop: tuple[int, int, int, int] | None = None,
                   lossless: bool = False) -> tuple[str, int, int]:
    """A compact JPEG data URI of the image file (and the preview's width, height), or a
    PNG one where ``lossless`` (a crop to be looked at pixel by pixel: JPEG's 8 x 8 blocks
    and ringing would read as detail).

    ``crop`` = (x, y, w, h) in the file's pixels, applied before downscaling."""
    import cv2  # noqa: PLC0415

    path = Path(path)
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise OSError(f"{path}: not a readable image")
    if crop is not None:
        x, y, w, h = crop
        img = img[y:y + h, x:x + w]
    prev = to_preview(img, max_side)
    kind, ext, params = (("png", ".png", [cv2.IMWRITE_PNG_COMPRESSION, 9]) if lossless
                         else ("jpeg", ".jpg", [cv2.IMWRITE_JPEG_QUALITY, int(quality)]))
    ok, enc = cv2.imencode(ext, prev, params)
    if not ok:
        raise OSError(f"{path}: {kind.upper()} encoding of the preview failed")
    uri = f"data:image/{kind};base64," + base64.b64encode(enc.tobytes()).decode("ascii")
    return uri, int(prev.shape[1]), int(prev.shape[0])


def svg_data_uri(svg: str) -> str:
    return "data:image/svg+xml;base64," + base64.b64encode(svg.encode("utf-8")).decode("ascii")


# ---------------------------------------------------------------------------
# Heat maps
# ---------------------------------------------------------------------------


#: the fill of an empty cell that is not marked (a view no experiment targeted)
_BLANK = "#fafafa"


def heatmap_svg(values: np.ndarray, vmin: float, vmax: float, *,
                labels: np.ndarray | None = None, titles: np.ndarray | None = None,
                marks: np.ndarray | None = None, cell: tuple[int, int] = (58, 30),
                group: tuple[int, int] | None = None, annotate: bool = True,
                col_labels: Sequence[str] | None = None,
                row_labels: Sequence[str] | None = None, unit: str = "dB",
                hatch: str = "hatch") -> str:
    """An SVG heat map of a 2-D grid (row 0 on top), with a colour bar.

    ``values``: NaN cells are drawn empty: hatched grey where ``marks`` has a text, else
    blank; ``marks`` (same shape,
    strings) are written in them, e.g. "input". ``labels`` overrides the printed
    text of a cell; ``titles`` gives each cell's hover text. ``group`` = (rows, cols)
    draws thicker separators every so many cells (the N x N set of each shot). ``hatch``:
    the id of the hatch pattern, which must be unique on a page of several heat maps."""
    values = np.asarray(values, dtype=float)
    rows, cols = values.shape
    cw, ch = cell
    left = 34 if row_labels is not None else 4
    top = 18 if col_labels is not None else 4
    bar_w = 14
    width = left + cols * cw + 16 + bar_w + 58
    height = top + rows * ch + 6
    height = max(height, top + 110)
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
             f'viewBox="0 0 {width} {height}" font-family="sans-serif" font-size="12" '
             'role="img">',
             f'<defs><pattern id="{hatch}" width="6" height="6" patternUnits="userSpaceOnUse" '
             'patternTransform="rotate(45)"><rect width="6" height="6" fill="#e8e8e8"/>'
             '<line x1="0" y1="0" x2="0" y2="6" stroke="#c8c8c8" stroke-width="2"/>'
             '</pattern></defs>']
    span = vmax - vmin if vmax > vmin else 1.0
    for i in range(rows):
        for j in range(cols):
            x, y = left + j * cw, top + i * ch
            v = values[i, j]
            title = titles[i, j] if titles is not None else None
            if np.isfinite(v):
                rgb = colour((v - vmin) / span)
                fill, tc = hex_colour(rgb), text_colour(rgb)
                text = labels[i, j] if labels is not None else f"{v:.2f}"
            else:  # a marked cell (an input view) hatched; an unmarked one left blank
                text = marks[i, j] if marks is not None else ""
                fill, tc = (f"url(#{hatch})" if text else _BLANK), "#555"
            parts.append(f'<g><rect x="{x}" y="{y}" width="{cw}" height="{ch}" '
                         f'fill="{fill}" stroke="#fff" stroke-width="1"/>')
            if title:
                parts.append(f"<title>{escape(str(title))}</title>")
            if annotate and text:
                parts.append(f'<text x="{_f(x + cw / 2)}" y="{_f(y + ch / 2 + 4)}" '
                             f'text-anchor="middle" fill="{tc}">{escape(str(text))}</text>')
            parts.append("</g>")
    if group is not None:
        gr, gc = group
        for i in range(0, rows + 1, gr):
            parts.append(f'<line x1="{left}" y1="{top + i * ch}" x2="{left + cols * cw}" '
                         f'y2="{top + i * ch}" stroke="#222" stroke-width="1.5"/>')
        for j in range(0, cols + 1, gc):
            parts.append(f'<line x1="{left + j * cw}" y1="{top}" x2="{left + j * cw}" '
                         f'y2="{top + rows * ch}" stroke="#222" stroke-width="1.5"/>')
    if col_labels is not None:
        for j, lab in enumerate(col_labels):
            parts.append(f'<text x="{_f(left + (j + 0.5) * cw)}" y="{top - 5}" '
                         f'text-anchor="middle" fill="#444">{escape(str(lab))}</text>')
    if row_labels is not None:
        for i, lab in enumerate(row_labels):
            parts.append(f'<text x="{left - 5}" y="{_f(top + (i + 0.5) * ch + 4)}" '
                         f'text-anchor="end" fill="#444">{escape(str(lab))}</text>')
    parts.append(colour_bar_svg(left + cols * cw + 16, top, bar_w, 100, vmin, vmax, unit))
    parts.append("</svg>")
    return "".join(parts)


def colour_bar_svg(x: float, y: float, w: float, h: float, vmin: float, vmax: float,
                   unit: str) -> str:
    steps = 20
    out = ["<g>"]
    for k in range(steps):
        t = 1.0 - (k + 0.5) / steps
        out.append(f'<rect x="{_f(x)}" y="{_f(y + k * h / steps)}" width="{_f(w)}" '
                   f'height="{_f(h / steps + 0.5)}" fill="{hex_colour(colour(t))}"/>')
    out.append(f'<rect x="{_f(x)}" y="{_f(y)}" width="{_f(w)}" height="{_f(h)}" fill="none" '
               'stroke="#444" stroke-width="0.5"/>')
    out.append(f'<text x="{_f(x + w + 4)}" y="{_f(y + 10)}" fill="#444">'
               f'{vmax:.1f} {escape(unit)}</text>')
    out.append(f'<text x="{_f(x + w + 4)}" y="{_f(y + h)}" fill="#444">'
               f'{vmin:.1f} {escape(unit)}</text>')
    out.append("</g>")
    return "".join(out)


# ---------------------------------------------------------------------------
# Camera array
# ---------------------------------------------------------------------------


def _view_basis(rotations: Sequence[np.ndarray], yaw_deg: float, pitch_deg: float
                ) -> np.ndarray:
    """3x3 world-to-screen rotation: the cameras' mean frame (x right, y down, z
    forward), turned by ``yaw`` about its y axis and ``pitch`` about its x axis, so
    that the array is seen obliquely from behind and above."""
    M = np.mean(np.asarray(rotations), axis=0)
    U, _, Vt = np.linalg.svd(M)
    R_mean = U @ Vt
    if np.linalg.det(R_mean) < 0:
        R_mean = U @ np.diag([1.0, 1.0, -1.0]) @ Vt
    a, b = math.radians(yaw_deg), math.radians(pitch_deg)
    Ry = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
    Rx = np.array([[1, 0, 0], [0, math.cos(b), -math.sin(b)], [0, math.sin(b), math.cos(b)]])
    return Rx @ Ry @ R_mean.T


def camera_array_svg(cameras: Mapping[str, object], truth: Mapping[str, object] | None = None,
                     *, size: tuple[int, int] = (560, 380), yaw_deg: float = -35.0,
                     pitch_deg: float = -25.0, frustum_views: set[str] | None = None,
                     title: str = "") -> str:
    """An oblique orthographic drawing of the camera array: every view's centre as a
    dot, frusta for the views named in ``frustum_views`` (default: the central view
    of every shot), and the ground truth (already in the same frame) as red rings.

    ``cameras``/``truth``: ``"<cam>/<view>"`` -> objects with ``centre``, ``R``, ``K``,
    ``width``, ``height`` (:class:`plenocal.camera.PinholeCamera`)."""
    keys = sorted(cameras)
    if not keys:
        raise ValueError("no camera to draw")
    C = np.array([cameras[k].centre for k in keys])
    Rs = [cameras[k].R for k in keys]
    V = _view_basis(Rs, yaw_deg, pitch_deg)
    shots = sorted({key_shot(k) for k in keys})
    if frustum_views is None:
        by_shot: dict[str, list[str]] = {}
        for k in keys:
            by_shot.setdefault(key_shot(k), []).append(k)
        frustum_views = {f"{s}/{middle_view(split_key(k)[1] for k in by_shot[s])}"
                         for s in shots}
    centre_dist = np.linalg.norm(C - C.mean(axis=0), axis=1)
    extent = float(max(centre_dist.max(), 1e-9))
    flen = 0.18 * extent

    def frustum(cam) -> np.ndarray:
        K, W, H = np.asarray(cam.K), cam.width, cam.height
        corners = np.array([[0, 0], [W - 1, 0], [W - 1, H - 1], [0, H - 1]], dtype=float)
        d = np.c_[corners, np.ones(4)] @ np.linalg.inv(K).T
        pts = cam.centre + (d * flen) @ np.asarray(cam.R).T
        return np.vstack([cam.centre, pts])

    pts_all = [C]
    fr = {k: frustum(cameras[k]) for k in keys if k in frustum_views}
    pts_all.extend(fr.values())
    tkeys = sorted(truth) if truth else []
    if tkeys:
        pts_all.append(np.array([truth[k].centre for k in tkeys]))
    P = np.vstack(pts_all) @ V.T
    lo, hi = P[:, :2].min(axis=0), P[:, :2].max(axis=0)
    W, H = size
    pad, top, bottom = 24, 60, 44  # room for the title and axes above, legend below
    s = min((W - 2 * pad) / max(hi[0] - lo[0], 1e-12),
            (H - top - bottom) / max(hi[1] - lo[1], 1e-12))
    off = np.array([W / 2, top + (H - top - bottom) / 2]) - s * (lo + hi) / 2

    def scr(X: np.ndarray) -> np.ndarray:
        return (np.atleast_2d(X) @ V.T)[:, :2] * s + off

    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" '
           f'viewBox="0 0 {W} {H}" font-family="sans-serif" font-size="12" role="img">',
           f'<rect width="{W}" height="{H}" fill="#fbfbfb" stroke="#ddd"/>']
    if title:
        out.append(f'<text x="8" y="16" fill="#333">{escape(title)}</text>')
    # frusta, far ones first
    depth = {k: float((cameras[k].centre @ V.T)[2]) for k in fr}
    for k in sorted(fr, key=lambda k: (-depth[k], k)):
        p = scr(fr[k])
        o = p[0]
        lines = "".join(f'<line x1="{_f(o[0])}" y1="{_f(o[1])}" x2="{_f(q[0])}" '
                        f'y2="{_f(q[1])}"/>' for q in p[1:])
        poly = " ".join(f"{_f(q[0])},{_f(q[1])}" for q in p[1:])
        out.append(f'<g stroke="#1f4e9a" stroke-width="0.8" fill="none"><title>'
                   f'{escape(k)}</title>{lines}<polygon points="{poly}" '
                   'fill="#1f4e9a" fill-opacity="0.08"/>'
                   f'<line x1="{_f(p[1][0])}" y1="{_f(p[1][1])}" x2="{_f(p[2][0])}" '
                   f'y2="{_f(p[2][1])}" stroke-width="2"/></g>')
    r_dot = 1.6 if len(keys) > 60 else 2.5
    dots = scr(C)
    out.append('<g fill="#1f4e9a">')
    for k, q in zip(keys, dots, strict=True):
        out.append(f'<circle cx="{_f(q[0])}" cy="{_f(q[1])}" r="{r_dot}"><title>{escape(k)}'
                   "</title></circle>")
    out.append("</g>")
    if tkeys:
        tq = scr(np.array([truth[k].centre for k in tkeys]))
        a = r_dot + 2.0
        out.append('<g fill="none" stroke="#d62728" stroke-width="0.8">')
        for k, q in zip(tkeys, tq, strict=True):
            out.append(f'<path d="M{_f(q[0] - a)} {_f(q[1])}h{_f(2 * a)}M{_f(q[0])} '
                       f'{_f(q[1] - a)}v{_f(2 * a)}"><title>truth {escape(k)}</title></path>')
        out.append("</g>")
    # scale bar: a round length near a fifth of the drawing's width
    target = (W - 2 * pad) / 5 / s
    mag = 10 ** math.floor(math.log10(target))
    length = max(m * mag for m in (1, 2, 5) if m * mag <= target)
    bx, by = W - pad - length * s, H - 14
    label = f"{length * 1000:g} mm" if length < 1 else f"{length:g} m"
    out.append(f'<line x1="{_f(bx)}" y1="{_f(by)}" x2="{_f(bx + length * s)}" '
               f'y2="{_f(by)}" stroke="#333" stroke-width="1.5"/><text x="{_f(bx)}" '
               f'y="{_f(by - 4)}" fill="#333">{label}</text>')
    # legend and axes of the mean camera frame
    ly = H - 10
    out.append(f'<circle cx="14" cy="{ly - 4}" r="3" fill="#1f4e9a"/>'
               f'<text x="22" y="{ly}" fill="#333">calibrated view centre'
               + ("; frusta: central views (thick edge = top of the image)" if fr else "")
               + "</text>")
    if tkeys:
        out.append(f'<path d="M9 {ly - 20}h10M14 {ly - 25}v10" stroke="#d62728"/>'
                   f'<text x="22" y="{ly - 16}" fill="#333">ground truth (aligned)</text>')
    ax0 = np.array([W - 40.0, 26.0])
    names = ("x", "y", "z")
    for i, col in enumerate(("#c0392b", "#27ae60", "#2c3e50")):
        R_mean_axis = np.mean([r[:, i] for r in Rs], axis=0)
        d = (V @ R_mean_axis)[:2]
        n = float(np.linalg.norm(d))
        d = d / n * 14 if n > 1e-9 else d
        out.append(f'<line x1="{_f(ax0[0])}" y1="{_f(ax0[1])}" x2="{_f(ax0[0] + d[0])}" '
                   f'y2="{_f(ax0[1] + d[1])}" stroke="{col}" stroke-width="1.5"/>'
                   f'<text x="{_f(ax0[0] + d[0] * 1.25)}" y="{_f(ax0[1] + d[1] * 1.25 + 4)}" '
                   f'fill="{col}" text-anchor="middle">{names[i]}</text>')
    out.append("</svg>")
    return "".join(out)


def align_truth(cameras: Mapping[str, object], truth: Mapping[str, object]) -> dict:
    """The truth moved into the calibration's frame by a similarity fitted on the
    shared view centres (for drawing only); ``{}`` when fewer than 3 are shared."""
    from plenocal.camera import PinholeCamera, pose, umeyama  # noqa: PLC0415

    keys = sorted(set(cameras) & set(truth))
    if len(keys) < 3:
        return {}
    src = np.array([truth[k].centre for k in keys])
    dst = np.array([cameras[k].centre for k in keys])
    s, R, t = umeyama(src, dst)
    out = {}
    for k in keys:
        g = truth[k]
        out[k] = PinholeCamera(np.asarray(g.K), pose(R @ g.R, s * R @ g.centre + t),
                               g.width, g.height)
    return out
