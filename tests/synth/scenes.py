"""A small synthetic capture for the structure-from-motion tests: pinhole renders of
textured planes (real photographs from scikit-image's data) with a z-buffer, seen by a
parallel array of cameras plus a few rotated "hand-held" ones, as in Section II-B of
the paper (the rotated shots fix the focal length that a parallel array leaves free).

A plane carries its texture through ``P(a, b) = O + a U + b V`` (texture pixel (a, b));
a camera with world-to-camera ``[R | t]`` sees it through the homography
``K [R U | R V | R O + t]``, so each plane is one ``cv2.warpPerspective``; the z-buffer
keeps the nearest plane per pixel. Rendering is supersampled (``ss`` x ``ss``) and
area-averaged, with the pixel-centre shift ``u_ss = ss u + (ss - 1) / 2`` so that the
result follows the internal convention exactly (pixel centres at integers).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from plenocal.camera import PinholeCamera, centred_intrinsics, pose


@dataclass(frozen=True)
class Plane:
    origin: np.ndarray  # world point of texture pixel (0, 0)
    u: np.ndarray  # world step of one texture pixel along a
    v: np.ndarray  # along b
    texture: np.ndarray  # (h, w, 3) float32 in [0, 1]


def _rot(axis: np.ndarray, deg: float) -> np.ndarray:
    axis = np.asarray(axis, dtype=float)
    rvec = axis / np.linalg.norm(axis) * np.radians(deg)
    return cv2.Rodrigues(rvec)[0]


def make_plane(centre, width_m: float, texture: np.ndarray, yaw_deg: float = 0.0) -> Plane:
    """A plane centred at ``centre`` facing the cameras (normal -z), turned about the
    vertical axis by ``yaw_deg``; ``width_m`` is its width."""
    h, w = texture.shape[:2]
    s = width_m / w
    R = _rot([0.0, 1.0, 0.0], yaw_deg)
    u = R @ np.array([s, 0.0, 0.0])
    v = R @ np.array([0.0, s, 0.0])
    origin = np.asarray(centre, dtype=float) - u * (w - 1) / 2 - v * (h - 1) / 2
    return Plane(origin, u, v, texture.astype(np.float32))


def default_scene(seed: int = 0) -> list[Plane]:
    """Three textured planes between 0.5 m and 0.75 m with occlusions."""
    from skimage import data  # noqa: PLC0415

    rng = np.random.default_rng(seed)

    def tex(img: np.ndarray, width: int, height: int) -> np.ndarray:
        img = img.astype(np.float32) / 255.0
        if img.ndim == 2:
            img = np.repeat(img[..., None], 3, axis=2)
        img = cv2.resize(img, (width, height), interpolation=cv2.INTER_AREA)
        return np.clip(img + rng.normal(0, 0.01, img.shape).astype(np.float32), 0, 1)

    back = np.concatenate([tex(data.astronaut(), 700, 700), tex(data.coffee(), 700, 700)], axis=1)
    return [
        make_plane([0.0, 0.0, 0.74], 1.4, back),
        make_plane([-0.09, 0.02, 0.62], 0.28, tex(data.chelsea(), 450, 300), yaw_deg=25.0),
        make_plane([0.12, -0.04, 0.52], 0.16, tex(data.rocket(), 300, 200), yaw_deg=-15.0),
    ]


def render(cam: PinholeCamera, planes: list[Plane], ss: int = 2) -> np.ndarray:
    """Render ``planes`` seen by ``cam``: uint8 RGB (H, W, 3)."""
    W, H = cam.width * ss, cam.height * ss
    K = cam.K.copy()
    K[:2] *= ss
    K[0, 2] += (ss - 1) / 2.0
    K[1, 2] += (ss - 1) / 2.0
    M = cam.world_to_cam
    R, t = M[:3, :3], M[:3, 3]
    Kinv = np.linalg.inv(K)
    ys, xs = np.mgrid[0:H, 0:W].astype(np.float64)
    d = np.stack([xs, ys, np.ones_like(xs)], axis=-1) @ Kinv.T  # camera rays, z = 1
    out = np.zeros((H, W, 3), np.float32)
    zbuf = np.full((H, W), np.inf)
    for p in planes:
        Hm = K @ np.column_stack([R @ p.u, R @ p.v, R @ p.origin + t])
        img = cv2.warpPerspective(p.texture, Hm, (W, H), flags=cv2.INTER_LINEAR,
                                  borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        # z-depth of the plane along each ray; inside the textured rectangle?
        n_c = R @ np.cross(p.u, p.v)
        o_c = R @ p.origin + t
        with np.errstate(divide="ignore", invalid="ignore"):
            z = (o_c @ n_c) / (d @ n_c)
        X = d * z[..., None] - o_c
        Ru, Rv = R @ p.u, R @ p.v
        a = X @ Ru / (Ru @ Ru)
        b = X @ Rv / (Rv @ Rv)
        h, w = p.texture.shape[:2]
        ok = (a >= 0) & (a <= w - 1) & (b >= 0) & (b <= h - 1) & (z > 0) & (z < zbuf)
        out[ok] = img[ok]
        zbuf[ok] = z[ok]
    out = cv2.resize(out, (cam.width, cam.height), interpolation=cv2.INTER_AREA)
    return np.clip(np.rint(out * 255.0), 0, 255).astype(np.uint8)


def rig_cameras(f: float = 400.0, width: int = 320, height: int = 240, cols: int = 3,
                rows: int = 2, step_m: float = 0.03, handheld: int = 3,
                seed: int = 0) -> dict[str, PinholeCamera]:
    """The array ``x{col:02d}_y{row:02d}`` (parallel, looking along +z) plus rotated
    hand-held shots ``hand{k:02d}`` looking at the scene centre."""
    K = centred_intrinsics(f, width, height)
    cams: dict[str, PinholeCamera] = {}
    for r in range(rows):
        for c in range(cols):
            centre = np.array([(c - (cols - 1) / 2) * step_m, (r - (rows - 1) / 2) * step_m, 0])
            cams[f"x{c:02d}_y{r:02d}"] = PinholeCamera(K, pose(np.eye(3), centre), width, height)
    rng = np.random.default_rng(seed)
    for k in range(handheld):
        ang = 2 * np.pi * k / max(handheld, 1) + rng.uniform(-0.3, 0.3)
        centre = np.array([0.08 * np.cos(ang), 0.06 * np.sin(ang), rng.uniform(-0.04, 0.04)])
        target = np.array([0.0, 0.0, 0.68])
        z = target - centre
        z /= np.linalg.norm(z)
        x = np.cross([0.0, 1.0, 0.0], z)
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        roll = _rot(z, rng.uniform(-8, 8))
        R = roll @ np.column_stack([x, y, z])
        cams[f"hand{k:02d}"] = PinholeCamera(K, pose(R, centre), width, height)
    return cams


def view_sets(shots: dict[str, PinholeCamera], n: int = 3,
              baseline_m: float = 0.002) -> dict[str, PinholeCamera]:
    """An n x n set of parallel views ``<cam>/<r>_<c>`` around every shot, ``baseline_m``
    apart along the shot's own x and y axes (a stand-in for a subaperture set)."""
    out = {}
    h = (n - 1) / 2
    for cam, pc in shots.items():
        for r in range(n):
            for c in range(n):
                M = pc.cam_to_world.copy()
                M[:3, 3] = pc.centre + pc.R @ np.array([(c - h) * baseline_m,
                                                        (r - h) * baseline_m, 0.0])
                out[f"{cam}/{r}_{c}"] = PinholeCamera(pc.K, M, pc.width, pc.height)
    return out


def render_view_sets(cams: dict[str, PinholeCamera], root, n: int = 3,
                     baseline_m: float = 0.003, shots=("x00_y00", "x02_y01", "hand00", "hand01")
                     ) -> tuple[dict[str, PinholeCamera], dict[str, PinholeCamera], dict]:
    """The ``n`` x ``n`` view sets of ``shots`` (:func:`view_sets`) rendered of the
    default scene into ``root`` as ``<shot>/<view>.png``: (the shots' cameras, the views'
    cameras, the views' paths)."""
    from pathlib import Path  # noqa: PLC0415

    from plenocal.io.files import write_image  # noqa: PLC0415

    sub = {k: cams[k] for k in shots}
    vs = view_sets(sub, n, baseline_m)
    scene = default_scene()
    paths = {}
    for name, cam in vs.items():
        paths[name] = Path(root) / f"{name}.png"
        write_image(paths[name], render(cam, scene))
    return sub, vs, paths
