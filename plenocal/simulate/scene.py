"""The synthetic scene: textured planes and boxes between the near and far planes.

World frame = the array frame: shot ``x00_y00``'s main-lens centre at the origin,
OpenCV axes (x right, y down, z forward), metres. Every surface is a textured
quadrilateral ``P0 + a U + b V`` (a, b in [0, 1]); a box is its faces. Textures
are photographs that ship with scikit-image (nothing is downloaded), slightly
pre-blurred so that no detail is far finer than a subaperture-view pixel, and
repeated with mirroring across large surfaces.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from importlib import resources

import numpy as np

TEXTURES = ("immunohistochemistry", "astronaut", "coffee", "chelsea", "rocket",
            "hubble_deep_field", "colorwheel", "retina")


@dataclass
class SceneArrays:
    """Flat arrays of the quads, as the ray tracer consumes them."""

    p0: np.ndarray  # (n, 3)
    u: np.ndarray  # (n, 3) edge vectors
    v: np.ndarray
    normal: np.ndarray  # (n, 3) unit
    tex_id: np.ndarray  # (n,) int64
    texel: np.ndarray  # (n,) metres per texel
    atlas: np.ndarray  # (sum of H W, 3) float32 in [0, 1]: the textures' rows, packed
    tex_h: np.ndarray  # (n_tex,) int64
    tex_w: np.ndarray
    tex_off: np.ndarray  # (n_tex,) int64: texture k's first texel in ``atlas``


def pack_textures(textures: list[np.ndarray]) -> dict[str, np.ndarray]:
    """The (H, W, 3) float32 textures as :class:`SceneArrays` holds them: every texel
    in one (sum of H W, 3) array, texture k from row ``tex_off[k]`` on, row-major. (A
    (n, H max, W max, 3) block padded to the largest texture held 191 MB for the default
    scene's 50 MB and cost each simulate job 0.15 s to fill.)"""
    tex_h = np.array([t.shape[0] for t in textures], dtype=np.int64)
    tex_w = np.array([t.shape[1] for t in textures], dtype=np.int64)
    sizes = tex_h * tex_w
    tex_off = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
    atlas = np.empty((int(sizes.sum()), 3), dtype=np.float32)
    for t, o, n in zip(textures, tex_off, sizes, strict=True):
        atlas[o:o + n] = np.asarray(t, dtype=np.float32).reshape(-1, 3)
    return {"atlas": atlas, "tex_h": tex_h, "tex_w": tex_w, "tex_off": tex_off}


#: the photographs the scenes use: scikit-image's bundled files (``skimage/data/``)
TEXTURE_FILES = {
    "astronaut": "astronaut.png", "chelsea": "chelsea.png", "coffee": "coffee.png",
    "colorwheel": "color.png", "hubble_deep_field": "hubble_deep_field.jpg",
    "immunohistochemistry": "ihc.png", "retina": "retina.jpg", "rocket": "rocket.jpg",
}


def texture_pixels(name: str) -> np.ndarray:
    """RGB uint8 pixels of scikit-image's bundled photograph ``name``: those of
    ``skimage.data.<name>()``, read from its file with OpenCV - without importing
    ``skimage.io``, which cost each simulate job 0.4 s (tests/test_simulate.py checks that
    the pixels are the same)."""
    import cv2  # noqa: PLC0415

    if name not in TEXTURE_FILES:
        import skimage.data  # noqa: PLC0415

        return getattr(skimage.data, name)()
    path = resources.files("skimage") / "data" / TEXTURE_FILES[name]
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise FileNotFoundError(f"{path}: scikit-image's texture {name!r} is missing; "
                                "reinstall scikit-image (pyproject.toml pins it)")
    return img if img.ndim == 2 else np.ascontiguousarray(img[:, :, 2::-1])


def load_texture(name: str, blur: float = 1.0) -> np.ndarray:
    """An RGB float32 texture from scikit-image's bundled data, Gaussian pre-blurred
    (:func:`gaussian_blur`)."""
    img = texture_pixels(name)
    if img.ndim == 2:
        img = np.repeat(img[:, :, None], 3, axis=2)
    img = img[:, :, :3].astype(np.float32) / 255.0
    if blur > 0:
        img = gaussian_blur(img, blur)
    return np.ascontiguousarray(img)


def gaussian_blur(img: np.ndarray, sigma: float) -> np.ndarray:
    """``img`` (H, W[, C] float32) convolved with a normalised Gaussian of ``sigma`` px, row
    and column passes of radius ``ceil(4 sigma)`` (OpenCV's size for float images), the
    edges mirrored without repeating the edge pixel (OpenCV's default border).

    In numpy's float32 operations, one by one in a fixed order: the same bits on every
    CPU. OpenCV's blur picks its code by the CPU it runs on (vector width, FMA, IPP): its
    optimised and baseline paths gave 35 % of the textures' texels different values, by
    1-2 float32 steps, so the simulated images could differ between machines. 0.3 s for
    the eight textures against OpenCV's 0.02 s."""
    r = max(1, math.ceil(4.0 * sigma))
    t = np.arange(-r, r + 1, dtype=np.float64)
    k = np.exp(-t * t / (2.0 * sigma * sigma))
    k = (k / k.sum()).astype(np.float32)
    out = np.asarray(img, dtype=np.float32)
    for axis in (0, 1):
        x = np.moveaxis(out, axis, 0)  # this pass's axis first
        n = x.shape[0]
        if n < r + 1:
            raise ValueError(f"a {out.shape} image is too small for a blur of sigma {sigma}")
        padded = np.pad(x, [(r, r)] + [(0, 0)] * (x.ndim - 1), mode="reflect")
        acc = padded[r:r + n] * k[r]
        for i in range(1, r + 1):
            pair = padded[r - i:r - i + n] + padded[r + i:r + i + n]
            pair *= k[r + i]
            acc += pair
        out = np.moveaxis(acc, 0, axis)
    return np.ascontiguousarray(out)


def _rot_y(deg: float) -> np.ndarray:
    a = math.radians(deg)
    return np.array([[math.cos(a), 0.0, math.sin(a)], [0.0, 1.0, 0.0],
                     [-math.sin(a), 0.0, math.cos(a)]])


def _quad(p0, u, v, texture: str, texel: float) -> dict:
    return {"p0": [float(x) for x in p0], "u": [float(x) for x in u],
            "v": [float(x) for x in v], "texture": texture, "texel_m": float(texel)}


def _box(centre, size, yaw_deg: float, textures: list[str], texel: float) -> list[dict]:
    """The five faces of a box seen from the cameras (no back face), yawed about y."""
    R = _rot_y(yaw_deg)
    c = np.asarray(centre, dtype=float)
    sx, sy, sz = (s / 2 for s in size)
    ex, ey, ez = R[:, 0], R[:, 1], R[:, 2]
    faces = [
        (c - sx * ex - sy * ey - sz * ez, 2 * sx * ex, 2 * sy * ey),  # front (z-)
        (c - sx * ex - sy * ey - sz * ez, 2 * sz * ez, 2 * sy * ey),  # left
        (c + sx * ex - sy * ey - sz * ez, 2 * sz * ez, 2 * sy * ey),  # right
        (c - sx * ex - sy * ey - sz * ez, 2 * sx * ex, 2 * sz * ez),  # top (y-)
        (c - sx * ex + sy * ey - sz * ez, 2 * sx * ex, 2 * sz * ez),  # bottom
    ]
    return [_quad(p, u, v, textures[i % len(textures)], texel) for i, (p, u, v) in
            enumerate(faces)]


def make_scene(centre_xy: tuple[float, float], near: float, far: float, seed: int) -> dict:
    """A seeded scene of a background plane at ``far``, a slanted plane and three
    boxes whose front faces span ``near`` .. the middle of the depth range."""
    rng = np.random.default_rng([seed, 7])
    cx, cy = centre_xy
    span = far - near
    quads: list[dict] = []
    # background: a wide fronto-parallel plane at the far distance
    w, h = 0.9, 0.7
    quads.append(_quad((cx - w / 2, cy - h / 2, far), (w, 0, 0), (0, h, 0),
                       "immunohistochemistry", 0.0005))
    # a slanted plane, turned 35 degrees about y, in the back half
    R = _rot_y(35.0 + rng.uniform(-5, 5))
    pw, ph = 0.12, 0.16
    pc = np.array([cx - 0.06, cy - 0.02, near + 0.75 * span])
    quads.append(_quad(pc - R @ np.array([pw / 2, ph / 2, 0]), R @ np.array([pw, 0, 0]),
                       R @ np.array([0, ph, 0]), "rocket", 0.0003))
    # three boxes; the nearest one's front face is fronto-parallel at ``near``
    boxes = [
        ((cx + 0.035, cy + 0.01), (0.045, 0.05, 0.04), near, 0.0, ["astronaut", "coffee"]),
        ((cx - 0.03, cy + 0.035), (0.06, 0.045, 0.05), near + 0.3 * span, 20.0,
         ["chelsea", "colorwheel"]),
        ((cx + 0.05, cy - 0.05), (0.05, 0.04, 0.05), near + 0.45 * span, -15.0,
         ["hubble_deep_field", "retina"]),
    ]
    for (bx, by), size, front, yaw, tex in boxes:
        jx, jy = rng.uniform(-0.005, 0.005, size=2)
        # place the box so that the nearest point of its front face is at ``front``
        a = math.radians(yaw)
        zc = front + size[2] / 2 * math.cos(a) + size[0] / 2 * abs(math.sin(a))
        quads.extend(_box((bx + jx, by + jy, zc), size, yaw, tex, 0.00025))
    return {"quads": quads, "centre": [cx, cy, near + 0.5 * span], "near_m": near,
            "far_m": far}


def scene_arrays(scene: dict) -> SceneArrays:
    quads = scene["quads"]
    names = sorted({q["texture"] for q in quads})
    p0 = np.array([q["p0"] for q in quads], dtype=np.float64)
    u = np.array([q["u"] for q in quads], dtype=np.float64)
    v = np.array([q["v"] for q in quads], dtype=np.float64)
    n = np.cross(u, v)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return SceneArrays(
        p0=p0, u=u, v=v, normal=n,
        tex_id=np.array([names.index(q["texture"]) for q in quads], dtype=np.int64),
        texel=np.array([q["texel_m"] for q in quads], dtype=np.float64),
        **pack_textures([load_texture(n) for n in names]),
    )
