"""Compiled ray tracing of the plenoptic camera (Fig. 2) and of ideal pinholes.

One sensor pixel is the mean of ``samples`` rays. Each ray starts at a jittered
point of the pixel (pixel-area integration) and leaves through a point of its own
microlens's circular aperture (defocus blur). The thin microlens (focal f) sends
every ray from sensor point x through the conjugate point
``P = c + (c - x) t / s`` at ``t = s f / (s - f)`` in front of the MLA; the ray
then reaches the main-lens plane at ``h`` and is black if ``|h| > A / 2``
(vignetting: the dark borders between micro images). The ideal thin main lens
turns tangent slopes as ``u' = u - h / F``. An optional front stop (a lens barrel
``stop_z`` in front of the main lens) clips oblique bundles: the mechanical
vignetting towards the sensor's edges. Light reaching a pixel through a
*neighbouring* microlens (cross-talk at the micro-image border) is not modelled.

Multi-focus MLAs: every pixel carries its lens's type, and ``t`` is that type's
(signed: negative for a Galilean MLA, whose conjugate point lies behind it) sharp
distance, so each type blurs a given depth differently.

A lenslet pixel's rays test only the quads that its microlens's bundle of rays can
reach (:func:`_bundle_candidates`, recomputed where the lens changes along a row): on the
default scene a ray tests 1-3 of 17 quads instead of the background, the slanted plane,
three bounding boxes and the faces of the boxes it enters - a lenslet image's tracing
2.83 -> 2.05 s, the same bits as with every quad tested (issue 15).

Numba compiles the per-pixel loops (the default dataset traces about 40 million
rays per shot); the arithmetic is IEEE double (the lenslet kernel's fast-math flags move
some 1e-16 of a value), so results are deterministic. The per-ray helpers are inlined
into the loops at Numba's level (``inline="always"``): called, each ray paid for passing
a dozen arrays and their reference counts - half of a lenslet image's time went to the
calls, not the rays (issue 15: 4.8-5.0 -> 3.5-3.6 CPU s per lenslet image, the same
bits). The lenslet kernel takes a pixel's rays lane by lane: all of them generated, then
each candidate quad tested against all of them (:func:`_hit`, branch-free), then their
colours summed in order - loops that vectorise, a third less time than tracing ray after
ray, the same bits (issue 15); the pinhole renderer takes a pixel's rays so too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from plenocal.simulate.scene import SceneArrays

BACKGROUND = 0.5


@njit(cache=True, inline="always")
def _texel(atlas, toff, th, tw, k, s, t, out):
    """Bilinear lookup with mirrored repetition into ``out`` (3,); s, t in texels, texture
    ``k`` the rows ``toff[k]`` on of the packed ``atlas`` (:func:`plenocal.simulate.scene.
    pack_textures`)."""
    h = th[k]
    w = tw[k]
    period = 2.0 * (w - 1)
    if not 0.0 <= s < period:  # (s % period is s itself there: skip the division)
        s = s % period
    if s > w - 1:
        s = period - s
    period = 2.0 * (h - 1)
    if not 0.0 <= t < period:
        t = t % period
    if t > h - 1:
        t = period - t
    i0 = int(math.floor(t))
    j0 = int(math.floor(s))
    i1 = min(i0 + 1, h - 1)
    j1 = min(j0 + 1, w - 1)
    fy = t - i0
    fx = s - j0
    r00 = toff[k] + i0 * w + j0
    r01 = toff[k] + i0 * w + j1
    r10 = toff[k] + i1 * w + j0
    r11 = toff[k] + i1 * w + j1
    for c in range(3):
        a = atlas[r00, c] * (1 - fx) + atlas[r01, c] * fx
        b = atlas[r10, c] * (1 - fx) + atlas[r11, c] * fx
        out[c] = a * (1 - fy) + b * fy
    return out


def quad_table(scene: SceneArrays) -> np.ndarray:
    """(n, 16) per-quad constants of :func:`_hit`, one contiguous row per quad: P0,
    normal, U, V, |U|^2, |V|^2, |U|, |V| (computed as the per-ray expressions were, so
    the traced values are the same bits)."""
    n = len(scene.p0)
    out = np.empty((n, 16))
    out[:, 0:3] = scene.p0
    out[:, 3:6] = scene.normal
    out[:, 6:9] = scene.u
    out[:, 9:12] = scene.v
    for q in range(n):
        u, v = scene.u[q], scene.v[q]
        out[q, 12] = u[0] * u[0] + u[1] * u[1] + u[2] * u[2]
        out[q, 13] = v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
        out[q, 14] = math.sqrt(out[q, 12])
        out[q, 15] = math.sqrt(out[q, 13])
    return out


@njit(cache=True, inline="always")
def _slab(o, inv_d, lo, hi, t0, t1):
    """The ray's parameter interval [t0, t1] clipped to the slab lo <= o + t d <= hi
    (``inv_d`` = 1 / d, computed once per ray; d = 0: inf)."""
    if math.isinf(inv_d):
        if o < lo or o > hi:
            return 1.0, 0.0
        return t0, t1
    a = (lo - o) * inv_d
    b = (hi - o) * inv_d
    if a > b:
        a, b = b, a
    return max(t0, a), min(t1, b)


@njit(cache=True, inline="always")
def _quad_row(quads, q):
    """Quad ``q``'s row of :func:`quad_table` as a tuple of 16 numbers (loaded once, held
    in registers across a pixel's rays)."""
    r = quads[q]
    return (r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8], r[9], r[10], r[11], r[12],
            r[13], r[14], r[15])


@njit(cache=True, inline="always")
def _hit(row, ox, oy, oz, dx, dy, dz, best):
    """The ray's hit of one quad (``row``: :func:`_quad_row`) nearer than ``best``:
    (hit or not, distance along the ray, texel coordinates along U and V in metres).

    Branch-free: every value is computed whether the ray hits or not (a miss's values
    are meaningless: a ray parallel to the quad divides by zero) and the tests are
    combined at the end, so that a loop over a pixel's rays vectorises
    (:func:`_render_lenslet`); a hit's values are those of the tests made one by one."""
    den = row[3] * dx + row[4] * dy + row[5] * dz
    tt = (row[3] * (row[0] - ox) + row[4] * (row[1] - oy) + row[5] * (row[2] - oz)) / den
    rx = ox + tt * dx - row[0]
    ry = oy + tt * dy - row[1]
    rz = oz + tt * dz - row[2]
    a = (rx * row[6] + ry * row[7] + rz * row[8]) / row[12]
    b = (rx * row[9] + ry * row[10] + rz * row[11]) / row[13]
    h = ((abs(den) >= 1e-12) & (tt > 1e-9) & (tt < best) & (a >= 0.0) & (a <= 1.0)
         & (b >= 0.0) & (b <= 1.0))
    return h, tt, a * row[14], b * row[15]


@njit(cache=True, inline="always")
def _keep_nearer(k, h, tt, q, a, b, best, hit, ba, bb):
    """Lane ``k`` takes the hit (distance ``tt``, quad ``q``, texel coordinates ``a``,
    ``b``) where ``h``, else keeps its own: selects, no branch (the loops over a pixel's
    rays vectorise)."""
    best[k] = tt if h else best[k]
    hit[k] = q if h else hit[k]
    ba[k] = a if h else ba[k]
    bb[k] = b if h else bb[k]


@njit(cache=True, inline="always")
def _shade(hit, best, ba, bb, tex_id, texel, atlas, toff, th, tw, rgb):
    """The colour of the nearest hit (quad ``hit`` at texel coordinates ``ba``, ``bb``)
    into rgb, or the background where nothing was hit (``hit`` < 0); returns the hit's
    distance, -1 for none."""
    if hit < 0:
        rgb[0] = BACKGROUND
        rgb[1] = BACKGROUND
        rgb[2] = BACKGROUND
        return -1.0
    _texel(atlas, toff, th, tw, tex_id[hit], ba / texel[hit], bb / texel[hit], rgb)
    return best


def camera_boxes(quads: np.ndarray, cam_to_world: np.ndarray) -> np.ndarray:
    """(n, 6) bounding box of every quad (:func:`quad_table`) in the camera frame:
    [x min, x max, y min, y max, z min, z max] (metres)."""
    p0, u, v = quads[:, None, 0:3], quads[:, None, 6:9], quads[:, None, 9:12]
    corners = np.concatenate([p0, p0 + u, p0 + v, p0 + u + v], axis=1)  # (n, 4, 3)
    R = np.asarray(cam_to_world, dtype=np.float64)[:3, :3]
    C = np.asarray(cam_to_world, dtype=np.float64)[:3, 3]
    cam = (corners - C) @ R  # R^T (p - C)
    lo, hi = cam.min(axis=1), cam.max(axis=1)
    return np.ascontiguousarray(np.stack([lo[:, 0], hi[:, 0], lo[:, 1], hi[:, 1], lo[:, 2],
                                          hi[:, 2]], axis=1))


@njit(cache=True, inline="always")
def _bundle_candidates(lx, ly, L, kappa, half_ap, half_lens, boxes, cand):
    """The quads that a ray through the microlens centred at (lx, ly) can hit, into
    ``cand`` in increasing order; returns their count.

    Every ray of the lens leaves a point m of the microlens disc (radius ``half_lens``,
    plane z = -L) and crosses the main lens at h, |h| <= ``half_ap``; past the thin lens
    (``u' = (h - m) / L - h / F``) it is at camera depth z at
    ``h (1 + z kappa) - (z / L) m`` with ``kappa = 1 / L - 1 / F``: inside the disc of
    centre ``-(z / L) (lx, ly)`` and radius ``|1 + z kappa| half_ap + (z / L) half_lens``. Over a
    quad's depth range [z0, z1] the centre moves linearly and the radius is convex, so the
    discs lie inside the bounding box of the two end discs; a quad whose camera-frame box
    misses it cannot be hit by the lens's rays (the front stop only removes rays). The
    boxes are padded by a micrometre and 1e-6 of the distance, far above round-off."""
    n = 0
    for q in range(boxes.shape[0]):
        z1 = boxes[q, 5]
        if z1 <= 0.0:
            continue
        z0 = max(boxes[q, 4], 0.0)
        pad = 1e-6 * (1.0 + z1)
        ca = -z0 / L
        cb = -z1 / L
        ra = abs(1.0 + z0 * kappa) * half_ap + (z0 / L) * half_lens + pad
        rb = abs(1.0 + z1 * kappa) * half_ap + (z1 / L) * half_lens + pad
        if min(ca * lx - ra, cb * lx - rb) > boxes[q, 1]:
            continue
        if max(ca * lx + ra, cb * lx + rb) < boxes[q, 0]:
            continue
        if min(ca * ly - ra, cb * ly - rb) > boxes[q, 3]:
            continue
        if max(ca * ly + ra, cb * ly + rb) < boxes[q, 2]:
            continue
        cand[n] = q
        n += 1
    return n


def _groups(quads: np.ndarray, groups: np.ndarray | None) -> np.ndarray:
    return np.ascontiguousarray(quad_groups(quads) if groups is None else groups,
                                dtype=np.float64)


def single_quad_groups(n: int) -> np.ndarray:
    """One run per quad: every quad tested for every ray, no bounding boxes."""
    out = np.zeros((n, 8))
    out[:, 0] = np.arange(n)
    out[:, 1] = np.arange(n) + 1
    return out


def quad_groups(quads: np.ndarray) -> np.ndarray:
    """(g, 8) runs of consecutive quads whose bounding boxes touch (a box's faces), each
    with its bounding box padded by 1e-6 of the scene's size: [first, end, min xyz, max
    xyz]. On the default scenes: the background, the slanted plane, and each box's five
    faces - rays that miss a box skip its faces (9 % of a lenslet image's CPU time, the
    same image bit for bit)."""
    corners = []
    for row in quads:
        p0, u, v = row[0:3], row[6:9], row[9:12]
        pts = np.stack([p0, p0 + u, p0 + v, p0 + u + v])
        corners.append((pts.min(axis=0), pts.max(axis=0)))
    if not corners:
        return np.zeros((0, 8))
    span = max(float(np.max([hi for _, hi in corners]) - np.min([lo for lo, _ in corners])),
               1.0)
    pad = 1e-6 * span
    groups = []
    for q, (lo, hi) in enumerate(corners):
        if groups:
            g = groups[-1]
            if (lo <= g[5:8] + pad).all() and (hi >= g[2:5] - pad).all():
                g[1] = q + 1
                g[2:5] = np.minimum(g[2:5], lo)
                g[5:8] = np.maximum(g[5:8], hi)
                continue
        groups.append(np.array([q, q + 1, *lo, *hi], dtype=float))
    out = np.array(groups)
    out[:, 2:5] -= pad
    out[:, 5:8] += pad
    return out


#: LLVM's fast-math flags of the lenslet kernel: fused multiply-adds (``contract``),
#: reciprocals (``arcp``), reassociation, signless zeros and approximate functions, but
#: not ``nnan`` / ``ninf`` (the kernel's NaN sentinel and the infinite slopes of
#: :func:`_slab` must stay what they are). 1.27 -> 0.93 s a default shot on two threads,
#: the same float32 images on every shot tried (the round-off they move is some 1e-16 of
#: a pixel's value, far below its float32 step; issue 15).
LENSLET_FASTMATH = {"contract", "arcp", "reassoc", "nsz", "afn"}


# error_model numpy: a float divided by zero gives inf or nan (the branch-free :func:`_hit`
# divides before it tests) instead of raising, and no division carries a test that stops
# the loops from vectorising
@njit(cache=True, parallel=True, fastmath=LENSLET_FASTMATH, error_model="numpy")
def _render_lenslet(height, width, pix_size, L, s, t_types, lens_type, F, half_ap, stop_z,
                    stop_half, lens_x, lens_y, half_lens, jitter, disk, R, C, quads, boxes,
                    tex_id, texel, atlas, toff, th, tw, out):
    """Each pixel's ``ns`` rays lane by lane (arrays of ``ns``): their generation, then
    each candidate quad tested against all of them, then their colours summed in order.
    The first two loops have no branches and vectorise (one default shot 0.98 -> 0.58 s
    on two threads against a loop that traced ray by ray, the same bits; issue 15)."""
    ns = jitter.shape[0]
    cxs = (width - 1) / 2.0
    cys = (height - 1) / 2.0
    kappa = 1.0 / L - 1.0 / F
    for row in prange(height):  # rows on numba's threads: every pixel on its own
        rgb = np.empty(3)
        cand = np.empty(quads.shape[0], dtype=np.int64)
        jx = np.empty(ns)  # the pixel's jitter, its pattern turned by rot
        jy = np.empty(ns)
        seen = np.empty(ns, dtype=np.bool_)  # passed the main-lens aperture and front stop
        ox = np.empty(ns)  # ray origins (main-lens plane) and slopes, world frame
        oy = np.empty(ns)
        oz = np.empty(ns)
        dx = np.empty(ns)
        dy = np.empty(ns)
        dz = np.empty(ns)
        best = np.empty(ns)  # nearest hit: distance, quad (-1: none), texel coordinates
        hit = np.empty(ns, dtype=np.int64)
        ba = np.empty(ns)
        bb = np.empty(ns)
        ncand = 0
        plx = math.nan
        ply = math.nan
        for col in range(width):
            lx = lens_x[row, col]
            ly = lens_y[row, col]
            if lx != plx or ly != ply:  # a new lens: its bundle's candidate quads
                ncand = _bundle_candidates(lx, ly, L, kappa, half_ap, half_lens, boxes, cand)
                plx = lx
                ply = ly
            t = t_types[lens_type[row, col]]
            t_s = t / s
            rot = (row * 7919 + col * 104729) % ns  # decorrelate the sample pattern
            for k in range(ns):
                kk = k + rot  # (k + rot) % ns
                if kk >= ns:
                    kk -= ns
                jx[k] = jitter[kk, 0]
                jy[k] = jitter[kk, 1]
            for k in range(ns):
                # sensor point (metric, 180-degree readout flip)
                xs = -(col + jx[k] - cxs) * pix_size
                ys = -(row + jy[k] - cys) * pix_size
                # point on the microlens aperture
                mx = lx + half_lens * disk[k, 0]
                my = ly + half_lens * disk[k, 1]
                # conjugate point of the sensor point, t in front of the MLA
                px = lx + (lx - xs) * t_s
                py = ly + (ly - ys) * t_s
                sx = (px - mx) / t
                sy = (py - my) / t
                hx = mx + sx * L
                hy = my + sy * L
                ux = sx - hx / F
                uy = sy - hy / F
                bx = hx + ux * stop_z
                by = hy + uy * stop_z
                # vignetted by the main-lens aperture, clipped by the front stop
                # (mechanical vignetting): such a ray adds nothing to the pixel
                seen[k] = (hx * hx + hy * hy <= half_ap * half_ap) & (
                    (stop_half <= 0.0) | (bx * bx + by * by <= stop_half * stop_half))
                # to the world
                ox[k] = R[0, 0] * hx + R[0, 1] * hy + C[0]
                oy[k] = R[1, 0] * hx + R[1, 1] * hy + C[1]
                oz[k] = R[2, 0] * hx + R[2, 1] * hy + C[2]
                dx[k] = R[0, 0] * ux + R[0, 1] * uy + R[0, 2]
                dy[k] = R[1, 0] * ux + R[1, 1] * uy + R[1, 2]
                dz[k] = R[2, 0] * ux + R[2, 1] * uy + R[2, 2]
                best[k] = 1e30
                hit[k] = -1
                ba[k] = 0.0
                bb[k] = 0.0
            for i in range(ncand):  # in increasing order: the nearest hit, first of equals
                q = cand[i]
                row_q = _quad_row(quads, q)
                for k in range(ns):
                    h, tt, a, b = _hit(row_q, ox[k], oy[k], oz[k], dx[k], dy[k], dz[k],
                                       best[k])
                    _keep_nearer(k, h, tt, q, a, b, best, hit, ba, bb)
            acc0 = 0.0
            acc1 = 0.0
            acc2 = 0.0
            for k in range(ns):
                if not seen[k]:
                    continue
                _shade(hit[k], best[k], ba[k], bb[k], tex_id, texel, atlas, toff, th, tw, rgb)
                acc0 += rgb[0]
                acc1 += rgb[1]
                acc2 += rgb[2]
            out[row, col, 0] = acc0 / ns
            out[row, col, 1] = acc1 / ns
            out[row, col, 2] = acc2 / ns


@njit(cache=True, inline="always")
def _pixel_ray(Kinv, R, u, v):
    """World direction (dx, dy, dz) of pixel (u, v) of a pinhole camera, and the camera
    z of ``K^-1 (u, v, 1)`` (cz), by which a ray length becomes a z-depth."""
    cx = Kinv[0, 0] * u + Kinv[0, 1] * v + Kinv[0, 2]
    cy = Kinv[1, 0] * u + Kinv[1, 1] * v + Kinv[1, 2]
    cz = Kinv[2, 0] * u + Kinv[2, 1] * v + Kinv[2, 2]
    return (R[0, 0] * cx + R[0, 1] * cy + R[0, 2] * cz,
            R[1, 0] * cx + R[1, 1] * cy + R[1, 2] * cz,
            R[2, 0] * cx + R[2, 1] * cy + R[2, 2] * cz, cz)


@njit(cache=True, error_model="numpy")  # (see _render_lenslet)
def _render_pinhole(height, width, Kinv, R, C, ss, quads, groups, tex_id, texel, atlas, toff,
                    th, tw, out, depth):
    """Every pixel's ``ss`` x ``ss`` rays and its centre's (the depth) lane by lane, as
    :func:`_render_lenslet` takes them: each group of quads (:func:`quad_groups`) skipped
    where none of the rays meets its padded bounding box, else each of its quads tested
    against all rays (a ray that misses the box misses its quads: the same hits) - 25-30 %
    less time than ray after ray, the same bits (issue 15)."""
    n = ss * ss + 1  # the pixel's ss x ss colour rays, then its centre's ray (the depth)
    rgb = np.empty(3)
    dx = np.empty(n)
    dy = np.empty(n)
    dz = np.empty(n)
    inv = np.empty((n, 3))  # 1 / direction per axis (inf where 0), for the boxes' slabs
    best = np.empty(n)
    hit = np.empty(n, dtype=np.int64)
    ba = np.empty(n)
    bb = np.empty(n)
    ox = C[0]
    oy = C[1]
    oz = C[2]
    for row in range(height):
        for col in range(width):
            for i in range(ss):
                for j in range(ss):
                    k = i * ss + j
                    dx[k], dy[k], dz[k], _ = _pixel_ray(Kinv, R, col - 0.5 + (j + 0.5) / ss,
                                                        row - 0.5 + (i + 0.5) / ss)
            # z-depth of the pixel centre's ray (direction has z_cam = 1 by K^-1)
            dx[n - 1], dy[n - 1], dz[n - 1], cz = _pixel_ray(Kinv, R, float(col), float(row))
            for k in range(n):
                inv[k, 0] = 1.0 / dx[k] if dx[k] != 0.0 else math.inf
                inv[k, 1] = 1.0 / dy[k] if dy[k] != 0.0 else math.inf
                inv[k, 2] = 1.0 / dz[k] if dz[k] != 0.0 else math.inf
                best[k] = 1e30
                hit[k] = -1
                ba[k] = 0.0
                bb[k] = 0.0
            for g in range(groups.shape[0]):
                grp = groups[g]
                q0 = int(grp[0])
                q1 = int(grp[1])
                if q1 - q0 > 1:
                    inside = False
                    for k in range(n):
                        t0, t1 = _slab(ox, inv[k, 0], grp[2], grp[5], -1e30, 1e30)
                        t0, t1 = _slab(oy, inv[k, 1], grp[3], grp[6], t0, t1)
                        t0, t1 = _slab(oz, inv[k, 2], grp[4], grp[7], t0, t1)
                        if not (t1 < t0 or t1 < 0.0):
                            inside = True
                            break
                    if not inside:
                        continue
                for q in range(q0, q1):
                    row_q = _quad_row(quads, q)
                    for k in range(n):
                        h, tt, a, b = _hit(row_q, ox, oy, oz, dx[k], dy[k], dz[k], best[k])
                        _keep_nearer(k, h, tt, q, a, b, best, hit, ba, bb)
            a0 = 0.0
            a1 = 0.0
            a2 = 0.0
            for k in range(n - 1):
                _shade(hit[k], best[k], ba[k], bb[k], tex_id, texel, atlas, toff, th, tw, rgb)
                a0 += rgb[0]
                a1 += rgb[1]
                a2 += rgb[2]
            m = ss * ss
            out[row, col, 0] = a0 / m
            out[row, col, 1] = a1 / m
            out[row, col, 2] = a2 / m
            tt = best[n - 1] if hit[n - 1] >= 0 else -1.0
            depth[row, col] = tt * cz if tt > 0 else 0.0


@njit(cache=True)
def _nearest_lens_map(height, width, origin, A, Ainv, out):
    """Per pixel, the nearest lattice point ``origin + A (i, j)``: one of the four
    corners of the lattice cell holding the pixel (the cell is two equilateral
    triangles, the Delaunay triangles of the hexagonal lattice)."""
    for row in range(height):
        for col in range(width):
            rx = col - origin[0]
            ry = row - origin[1]
            fi = math.floor(Ainv[0, 0] * rx + Ainv[0, 1] * ry)
            fj = math.floor(Ainv[1, 0] * rx + Ainv[1, 1] * ry)
            best = 1e300
            for di in range(2):
                for dj in range(2):
                    i = fi + di
                    j = fj + dj
                    cx = origin[0] + (A[0, 0] * i + A[0, 1] * j)
                    cy = origin[1] + (A[1, 0] * i + A[1, 1] * j)
                    d = (cx - col) * (cx - col) + (cy - row) * (cy - row)
                    if d < best:
                        best = d
                        out[row, col, 0] = cx
                        out[row, col, 1] = cy


def nearest_lens_centres(origin: np.ndarray, A: np.ndarray, width: int,
                         height: int) -> np.ndarray:
    """(H, W, 2) micro-image centre (pixels) of the lens nearest to every sensor pixel,
    for the lattice ``origin + A (i, j)`` (``A``: 2 x 2, columns are the lattice steps)."""
    out = np.zeros((height, width, 2))
    A = np.ascontiguousarray(A, dtype=np.float64)
    _nearest_lens_map(int(height), int(width), np.asarray(origin, dtype=np.float64), A,
                      np.ascontiguousarray(np.linalg.inv(A)), out)
    return out


def sample_pattern(samples: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Stratified pixel jitter in [-0.5, 0.5)^2 and points on the unit disc, uniform in
    area: each set point-symmetric about its centre (every sample paired with its mirror
    image; an odd count adds the centre), so that their means are zero. Every pixel
    traces the same set (paired differently, :func:`_render_lenslet`'s ``rot``), so a
    set whose mean is off the centre moved every pixel's integration and every
    microlens's ray bundle the same way: with 12 samples by up to 0.085 px in jitter and
    0.05 of the lens radius on the disc, a principal point 0.15-0.48 px and a view
    centre 0.05-0.09 mm from the ground-truth cameras' (a review's measurement, seeds
    0-5 of the default camera)."""
    rng = np.random.default_rng([seed, 11])
    half = samples // 2
    n = int(math.ceil(math.sqrt(samples)))
    cells = np.array([(i, j) for i in range(n) for j in range(n)], dtype=float)
    # cells in mirror pairs (c, n - 1 - c); an odd n's middle cell is its own mirror
    first = cells[(cells[:, 0] * n + cells[:, 1]) < (n * n - 1) / 2]
    picked = first[rng.permutation(len(first))[:half]]
    offset = rng.random((half, 2))
    jitter = (picked + offset) / n - 0.5
    # disc: stratified in area (radius sqrt), golden-angle spiral plus a turn
    k = np.arange(half) + 0.5
    r = np.sqrt(k / max(half, 1))
    phi = k * math.pi * (3 - math.sqrt(5)) + rng.uniform(0, 2 * math.pi)
    disk = np.stack([r * np.cos(phi), r * np.sin(phi)], axis=1)
    jitter, disk = np.concatenate([jitter, -jitter]), np.concatenate([disk, -disk])
    if samples % 2:
        jitter, disk = np.vstack([jitter, [[0.0, 0.0]]]), np.vstack([disk, [[0.0, 0.0]]])
    return jitter, disk


@dataclass(frozen=True)
class LensletSetup:
    """What every shot of one camera and scene traces with (:func:`prepare_lenslet`): the
    physical microlens centre and type of every pixel, the ray pattern and the quads.
    Made once per dataset: on the default camera 0.1 s a shot (its 3 million pixels'
    arrays), 2.8 s of a 28-shot simulation in which the tracer's threads waited
    (issue 15)."""
    height: int
    width: int
    pixel_size: float
    L: float
    s: float
    F: float
    half_aperture: float
    half_lens: float
    t_types: np.ndarray  # (types,) sharp distance of every lens type
    lens_types: np.ndarray  # (H, W) int64
    lens_x: np.ndarray  # (H, W) physical microlens centre (metres)
    lens_y: np.ndarray
    jitter: np.ndarray  # (samples, 2)
    disk: np.ndarray  # (samples, 2)
    quads: np.ndarray  # (n, 16), quad_table


def prepare_lenslet(scene: SceneArrays, optics, lens_centres_px: np.ndarray, samples: int,
                    seed: int, lens_types: np.ndarray | None = None) -> LensletSetup:
    """The shot-independent part of :func:`render_lenslet` (arguments as there)."""
    t_types = np.array([optics.type_t(i) for i in range(optics.lens_types)])
    if lens_types is None:
        lens_types = np.zeros(lens_centres_px.shape[:2], dtype=np.int64)
    lens_types = np.ascontiguousarray(lens_types, dtype=np.int64)
    if lens_types.min() < 0 or lens_types.max() >= len(t_types):
        raise ValueError(f"lens type map holds types outside 0..{len(t_types) - 1}")
    L, s = optics.L, optics.s
    mx, my = optics.sensor_to_metric(lens_centres_px[..., 0], lens_centres_px[..., 1])
    jitter, disk = sample_pattern(samples, seed)
    return LensletSetup(int(optics.height), int(optics.width), float(optics.pixel_size),
                        L, s, optics.focal_length, optics.aperture / 2, optics.mla_pitch / 2,
                        t_types, lens_types, np.ascontiguousarray(mx * L / (L + s)),
                        np.ascontiguousarray(my * L / (L + s)), jitter, disk,
                        quad_table(scene))


def trace_lenslet(setup: LensletSetup, scene: SceneArrays, cam_to_world: np.ndarray,
                  stop_distance: float = 0.0, stop_diameter: float = 0.0,
                  cull: bool = True) -> np.ndarray:
    """One shot's lenslet image (float32 RGB in [0, 1]) with a prepared ``setup`` of the
    same ``scene`` (:func:`render_lenslet` for the arguments)."""
    st = setup
    out = np.zeros((st.height, st.width, 3), dtype=np.float32)
    R = np.ascontiguousarray(cam_to_world[:3, :3], dtype=np.float64)
    C = np.ascontiguousarray(cam_to_world[:3, 3], dtype=np.float64)
    _render_lenslet(st.height, st.width, st.pixel_size, st.L, st.s, st.t_types, st.lens_types,
                    st.F, st.half_aperture, float(stop_distance), float(stop_diameter) / 2,
                    st.lens_x, st.lens_y, st.half_lens, st.jitter, st.disk, R, C, st.quads,
                    camera_boxes(st.quads, cam_to_world) if cull
                    else _unbounded(len(st.quads)),
                    scene.tex_id, scene.texel, scene.atlas, scene.tex_off, scene.tex_h,
                    scene.tex_w, out)
    return out


def render_lenslet(scene: SceneArrays, optics, lens_centres_px: np.ndarray,
                   cam_to_world: np.ndarray, samples: int, seed: int,
                   lens_types: np.ndarray | None = None, stop_distance: float = 0.0,
                   stop_diameter: float = 0.0, cull: bool = True) -> np.ndarray:
    """Render a lenslet image (float32 RGB in [0, 1]) of one shot.

    ``lens_centres_px`` (H, W, 2) gives, per sensor pixel, the micro-image centre of
    the microlens it lies under (pixels); ``lens_types`` (H, W) its lens type (None:
    every lens of type 0). ``stop_diameter`` > 0: a front stop of that diameter
    ``stop_distance`` in front of the main lens (metres). ``cull``: each ray tests only
    the quads its microlens's bundle can reach (:func:`_bundle_candidates`; the same
    image as ``cull=False``, which tests every quad for every ray). Several shots of one
    camera: :func:`prepare_lenslet` once, then :func:`trace_lenslet` per shot (the same
    images).
    """
    setup = prepare_lenslet(scene, optics, lens_centres_px, samples, seed, lens_types)
    return trace_lenslet(setup, scene, cam_to_world, stop_distance, stop_diameter, cull)


def _unbounded(n: int) -> np.ndarray:
    """(n, 6) camera boxes that every bundle reaches (no culling)."""
    return np.tile(np.array([-np.inf, np.inf, -np.inf, np.inf, 0.0, np.inf]), (n, 1))


def render_pinhole(scene: SceneArrays, K: np.ndarray, cam_to_world: np.ndarray, width: int,
                   height: int, supersample: int, groups: np.ndarray | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Ideal pinhole render (box-filtered over the pixel) and z-depth (metres);
    ``groups`` as :func:`render_lenslet`'s."""
    out = np.zeros((height, width, 3), dtype=np.float32)
    depth = np.zeros((height, width), dtype=np.float32)
    Kinv = np.ascontiguousarray(np.linalg.inv(K))
    R = np.ascontiguousarray(cam_to_world[:3, :3], dtype=np.float64)
    C = np.ascontiguousarray(cam_to_world[:3, 3], dtype=np.float64)
    quads = quad_table(scene)
    _render_pinhole(height, width, Kinv, R, C, int(supersample), quads,
                    _groups(quads, groups), scene.tex_id, scene.texel, scene.atlas,
                    scene.tex_off, scene.tex_h, scene.tex_w, out, depth)
    return out, depth
