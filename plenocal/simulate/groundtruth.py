"""Ground truth of a synthetic dataset, computed by tracing, not by the paper's formulas.

For subaperture view (r, c), the converter's tile centres sample the sensor points
``m_i + R q_rc`` (plenocal.viewgeom). Their chief rays, traced through the
microlens centres and the ideal main lens (PlenopticOptics.chief_rays), define the
view's pinhole camera: its centre is the least-squares intersection of the rays,
and ``K`` and the rotation come from a linear fit of pixel <-> ray direction
(a DLT on directions, then an RQ decomposition). For this optics the fit is exact:
every view has the main lens's orientation, its centre lies on the main-lens plane
``L q p / s`` per view step from the axis, and its principal point is shifted by
``f B / Z0`` per step (Z0: the plane conjugate to the MLA).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

from plenocal.artifacts.cameras import read_cameras, write_cameras
from plenocal.camera import PinholeCamera, pose
from plenocal.grid import MicrolensGrid
from plenocal.io.files import read_json
from plenocal.io.raytrix import RayCalib, read_calib
from plenocal.optics import PlenopticOptics
from plenocal.simulate.dataset import optics_from_truth
from plenocal.viewgeom import ViewLayout, make_layout, parse_view, view_names

SKEW_ZERO = 1e-9  # relative skew below which the fitted K is taken as skew-free


def intersect_rays(origins: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Least-squares point closest to all rays (origins (n, 3), unit dirs (n, 3))."""
    P = np.eye(3) - dirs[:, :, None] * dirs[:, None, :]  # (n, 3, 3) projectors
    return np.linalg.solve(P.sum(axis=0), np.einsum("nij,nj->i", P, origins))


def rq(M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """RQ decomposition M = K R with K upper triangular (positive diagonal), R a rotation."""
    P = np.flipud(np.eye(3))
    Q, U = np.linalg.qr((P @ M).T)
    K = P @ U.T @ P
    R = P @ Q.T
    S = np.diag(np.sign(np.diag(K)))
    K, R = K @ S, S @ R
    if np.linalg.det(R) < 0:
        R = -R
        K = -K
    return K / K[2, 2], R


def fit_pinhole(pixels: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """K and the camera-to-frame rotation from pixel <-> direction pairs (DLT + RQ)."""
    mu = pixels.mean(axis=0)
    sc = np.sqrt(2) / np.linalg.norm(pixels - mu, axis=1).mean()
    T = np.array([[sc, 0, -sc * mu[0]], [0, sc, -sc * mu[1]], [0, 0, 1]])
    uv = (pixels - mu) * sc
    n = len(dirs)
    A = np.zeros((2 * n, 9))
    A[0::2, 0:3] = dirs
    A[0::2, 6:9] = -uv[:, :1] * dirs
    A[1::2, 3:6] = dirs
    A[1::2, 6:9] = -uv[:, 1:2] * dirs
    _, _, Vt = np.linalg.svd(A.T @ A)
    M = np.linalg.inv(T) @ Vt[-1].reshape(3, 3)
    if np.linalg.det(M) < 0:
        M = -M
    K, R = rq(M)
    if abs(K[0, 1]) < SKEW_ZERO * K[0, 0]:
        K[0, 1] = 0.0  # the optics give no skew: keep K clean of round-off
    # R maps frame directions to camera directions: camera-to-frame is its transpose
    return K, R.T


def view_camera(optics: PlenopticOptics, layout: ViewLayout, r: int, c: int,
                lens_uv: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """(K, cam_to_main 4x4, rms residual px) of view (r, c) in the main-lens frame.

    ``lens_uv`` (m, 2): the true micro-image centres of the layout's lenses, where they
    differ from those the views were laid out on (``layout.lens_centres``, the default):
    the tile centres sample the layout's sensor points, and the light there came through
    the physical lens (:func:`true_lens_centres`)."""
    sensor = layout.chief_sensor_points(r, c)
    origins, dirs = optics.chief_rays(sensor, layout.lens_centres if lens_uv is None
                                      else lens_uv)
    centre = intersect_rays(origins, dirs)
    K, R = fit_pinhole(layout.tile_centres, dirs)
    proj = (dirs @ R) @ K.T
    res = proj[:, :2] / proj[:, 2:] - layout.tile_centres
    return K, pose(R, centre), float(np.sqrt((res ** 2).sum(axis=1).mean()))


def shot_cameras(optics: PlenopticOptics, grid: MicrolensGrid, layout: ViewLayout,
                 cam_to_world: np.ndarray, lens_uv: np.ndarray | None = None
                 ) -> tuple[dict[str, PinholeCamera], float]:
    """Ground-truth cameras of every view of one shot, and the worst fit residual
    (``lens_uv``: :func:`view_camera`)."""
    out = {}
    worst = 0.0
    for name in view_names(layout.n_views):
        r, c = parse_view(name)
        K, M, rms = view_camera(optics, layout, r, c, lens_uv)
        worst = max(worst, rms)
        out[name] = PinholeCamera(K, cam_to_world @ M, layout.width, layout.height)
    return out, worst


def true_lens_centres(truth: MicrolensGrid, grid: MicrolensGrid, layout: ViewLayout
                      ) -> np.ndarray | None:
    """(m, 2) the micro-image centres of ``truth`` (the simulator's calib.xml, exact by
    construction) at the lattice coordinates of ``layout``'s lenses, which ``grid`` (the
    grid the views were laid out on) places; None where ``grid`` is ``truth``'s lattice.

    A grid the converter fitted to the micro images (``convert.grid``: auto or refine,
    :mod:`plenocal.convert.gridcheck`) or moved onto the corner views' agreement
    (:mod:`plenocal.convert.centring`) lays the views out on its own lattice, so the views
    are that size and their tile centres sample the sensor around its centres; the light
    at those points still came through the physical lenses, at the file's centres."""
    if np.array_equal(grid.origin, truth.origin) and np.array_equal(grid.A, truth.A):
        return None
    return truth.centres_at(grid.ij[layout.lens_index])


def ground_truth_cameras(data_dir: str | Path, shots: list[str], n_views: int, tile: int,
                         q: float | None, out_json: str | Path, log=print,
                         even: bool = True,
                         insets_px: Mapping[str, float] | None = None,
                         grid_of: Callable[[RayCalib, int, int], MicrolensGrid] | None = None
                         ) -> None:
    """Write the cameras of every view of every shot of ``shots`` (plain format; one job
    for all shots: each takes a fraction of a second, less than a job's start-up).
    ``even``: the converter's ``convert.even_size``; ``insets_px``: the border lenses the
    views leave out (the set-up's :class:`plenocal.convert.bordercut.BorderCut`);
    ``grid_of``: the grid the views were laid out on, from the calibration file and the
    sensor size (the set-up's :meth:`plenocal.convert.setup.ConverterSetup.grid`; None:
    the file's). The views' size must match; the rays go through the file's lenses
    (:func:`true_lens_centres`)."""
    data_dir = Path(data_dir)
    optics = optics_from_truth(data_dir / "truth" / "optics.json")
    calib = read_calib(data_dir / "calib.xml")
    truth = MicrolensGrid(calib, optics.width, optics.height)
    grid = truth if grid_of is None else grid_of(calib, optics.width, optics.height)
    layout = make_layout(grid, n_views, tile, q, even=even, insets_px=insets_px)
    lens_uv = true_lens_centres(truth, grid, layout)
    if lens_uv is not None:
        moved = np.linalg.norm(lens_uv - layout.lens_centres, axis=1)
        log(f"the views' grid lies up to {moved.max():.2f} px (rms "
            f"{np.sqrt(np.mean(moved ** 2)):.2f}) from the simulated lenses' centres")
    shots_truth = read_json(data_dir / "truth" / "shots.json")
    cameras, worst = {}, 0.0
    for cam in shots:
        if cam not in shots_truth:
            raise KeyError(f"{cam}: not a shot of {data_dir / 'truth' / 'shots.json'} "
                           f"({', '.join(sorted(shots_truth))}); rerun rule simulate_setup?")
        cams, shot_worst = shot_cameras(optics, grid, layout,
                                        np.asarray(shots_truth[cam]["cam_to_world"]), lens_uv)
        log(f"{cam}: {len(cams)} view cameras, worst chief-ray fit residual "
            f"{shot_worst:.2e} px")
        cameras.update({f"{cam}/{k}": v for k, v in cams.items()})
        worst = max(worst, shot_worst)
    write_cameras(out_json, cameras, extra={"fit_residual_px": worst})
    log(f"{len(cameras)} ground-truth cameras, worst fit residual {worst:.2e} px")


def render_views(scene_json: str | Path, cams_json: str | Path, keys: list[str],
                 supersample: int, images: list[str | Path], depths: list[str | Path],
                 log=print) -> None:
    """Ideal pinhole renders (box-filtered, ``supersample`` rays per pixel and axis) and
    z-depth maps of the views ``keys`` (``"<cam>/<view>"``), the scene's textures loaded
    once for all of them (rule ground_truth_render: one view; ground_truth_render_set: the
    rest of the full set; ground_truth_render_central: the central view of every shot)."""
    from plenocal.io.files import to_uint8, write_image, write_npy  # noqa: PLC0415
    from plenocal.simulate.raytrace import render_pinhole  # noqa: PLC0415
    from plenocal.simulate.scene import scene_arrays  # noqa: PLC0415

    if not len(keys) == len(images) == len(depths):
        raise ValueError(f"ground truth renders: {len(keys)} views, {len(images)} images, "
                         f"{len(depths)} depth maps")
    cams = read_cameras(cams_json)
    scene = scene_arrays(read_json(scene_json))
    for key, image, depth_path in zip(keys, images, depths, strict=True):
        if key not in cams:
            raise KeyError(f"{cams_json}: no camera {key}; rerun rule ground_truth")
        c = cams[key]
        img, depth = render_pinhole(scene, c.K, c.cam_to_world, c.width, c.height,
                                    int(supersample))
        write_image(image, to_uint8(img))
        write_npy(depth_path, depth)
        log(f"{key}: {c.width}x{c.height}, depth {float(depth[depth > 0].min()):.3f}-"
            f"{float(depth.max()):.3f} m")
