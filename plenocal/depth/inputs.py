"""What a depth map of the workflow is computed from: the source views of each
registration, the scene bounds, and previews.

- Registration A: reference = the central view of shot ``cam``; sources = the central
  views of the ``k`` shots whose camera centres are nearest (SfM units). Bounds: the
  depths of the sparse SfM points the reference sees (``reg_a.json`` key
  ``depth_range`` per shot if present, else the COLMAP model), 2nd-98th percentile,
  widened.
- Registration B: reference = the central view; sources = the other views of its
  own N x N set (the ``k`` nearest, or all). Bounds: rig.json's X_n / X_f (mm),
  widened.

Both registrations' maps are made at 1 / ``registration_downsample`` of the views'
resolution (:func:`downsampled`): Eq. 5 needs one robust ratio per shot, not a detailed
map. At half resolution a map took about a seventh of the time, and Eq. 5's r moved by
+0.10 % on eighteen simulated captures, nearer the truth on fourteen (BENCHMARKS.md, "The
registrations' depth maps at half resolution").
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from plenocal.artifacts.reg_a import RegistrationA
from plenocal.artifacts.rig import RigB
from plenocal.camera import PinholeCamera, downsample_camera, transform


def widen(near: float, far: float, margin: float) -> tuple[float, float]:
    """Bounds widened by ``margin`` (relative) on both sides."""
    return near * (1.0 - margin), far * (1.0 + margin)


def nearest_sources(ref_key: str, cameras: dict[str, PinholeCamera], k: int | None,
                    candidates: list[str] | None = None) -> list[str]:
    """The ``k`` candidate cameras nearest to the reference by camera centre (sorted by
    distance, then name; all when k is None)."""
    cand = [c for c in (candidates if candidates is not None else sorted(cameras))
            if c != ref_key]
    c0 = cameras[ref_key].centre
    order = sorted(cand, key=lambda c: (round(float(np.linalg.norm(cameras[c].centre - c0)),
                                              12), c))
    return order if k is None else order[:k]


def rig_bounds(rig: RigB, margin: float) -> tuple[float, float]:
    """Scene bounds (metres) from rig.json's X_n / X_f (mm, Eq. 1 at the disparity
    range), widened."""
    return widen(float(rig.symbols["X_n"]) / 1000.0, float(rig.symbols["X_f"]) / 1000.0, margin)


def _model_points_depths(model_dir: Path, cam: str, cam_to_world: np.ndarray) -> np.ndarray:
    """Depths (> 0) in shot ``cam``'s camera frame of the sparse points its image (staged
    as ``<cam>.png`` by registration A) sees in the COLMAP model; every point of the model
    where the image is not in it."""
    from plenocal.calib.reg_a.colmap import model_points  # noqa: PLC0415

    pts = model_points(model_dir, f"{cam}.png")
    if len(pts) == 0:
        return np.zeros(0)
    Xc = transform(np.linalg.inv(cam_to_world), pts)
    return Xc[:, 2][Xc[:, 2] > 0]


def reg_a_bounds(reg_a: RegistrationA, cam: str, model_dir: str | Path | None,
                 margin: float) -> tuple[float, float]:
    """Scene bounds of shot ``cam`` in SfM units (the 2nd-98th percentile depth of the
    sparse points it sees in registration A's COLMAP model), widened."""
    if model_dir is None or not Path(model_dir).is_dir():
        raise FileNotFoundError(f"depth bounds of {cam} in registration A: the COLMAP model "
                                f"{model_dir} is missing; rerun rule map_a")
    z = _model_points_depths(Path(model_dir), cam, reg_a.cameras[cam].cam_to_world)
    if len(z) < 10:
        raise ValueError(f"depth bounds of {cam} in registration A: only {len(z)} sparse "
                         f"points in front of it in {model_dir}")
    near, far = np.percentile(z, [2.0, 98.0])
    return widen(float(near), float(far), margin)


def preview(depth: np.ndarray) -> np.ndarray:
    """Colour-mapped inverse depth (RGB uint8, invalid black), scaled to the valid
    1st-99th percentile."""
    import cv2  # noqa: PLC0415

    v = depth > 0
    out = np.zeros(depth.shape + (3,), np.uint8)
    if not v.any():
        return out
    inv = np.zeros_like(depth, dtype=np.float64)
    inv[v] = 1.0 / depth[v]
    lo, hi = np.percentile(inv[v], [1.0, 99.0])
    g = np.clip((inv - lo) / max(hi - lo, 1e-12), 0, 1)
    col = cv2.applyColorMap(np.rint(g * 255).astype(np.uint8), cv2.COLORMAP_TURBO)[..., ::-1]
    out[v] = col[v]
    return out



@dataclass(frozen=True)
class DepthJob:
    """One depth map of the workflow: the reference camera and image, the sources, the
    bounds and their units (``sfm`` in registration A, ``m`` in B)."""

    ref_cam: PinholeCamera
    ref_path: Path
    src_names: list[str]
    src_cams: list[PinholeCamera]
    src_paths: list[Path]
    near: float
    far: float
    units: str
    downsample: int = 1  # the views are read reduced by this factor (:func:`job_images`)


def depth_job_a(reg_a: RegistrationA, reg_a_path: str | Path, cam: str, centre: str,
                views_dir: str | Path, model_dir: str | Path | None, k: int,
                margin: float) -> DepthJob:
    """Registration A's map of shot ``cam`` (see the module docstring); a shot that SfM did
    not register is refused with the file and where to look."""
    cameras = reg_a.cameras
    if cam not in cameras:
        raise ValueError(f"depth: shot {cam} is not registered in {reg_a_path}; look at the "
                         "registration A log for why")
    near, far = reg_a_bounds(reg_a, cam, model_dir, margin)
    srcs = nearest_sources(cam, cameras, k)
    views = Path(views_dir)
    return DepthJob(cameras[cam], views / cam / f"{centre}.png", srcs,
                    [cameras[s] for s in srcs], [views / s / f"{centre}.png" for s in srcs],
                    near, far, "sfm")


def depth_job_b(rig: RigB, cam: str, centre: str, views_dir: str | Path, k: int | None,
                margin: float) -> DepthJob:
    """Registration B's map of shot ``cam``: its central view from the other views of its
    own set (see the module docstring)."""
    cameras = rig.cameras()
    near, far = rig_bounds(rig, margin)
    srcs = nearest_sources(centre, cameras, k)
    views = Path(views_dir) / cam
    return DepthJob(cameras[centre], views / f"{centre}.png", srcs,
                    [cameras[s] for s in srcs], [views / f"{s}.png" for s in srcs],
                    near, far, "m")


def downsample_image(img: np.ndarray, factor: int) -> np.ndarray:
    """``img`` (H, W[, C]) reduced ``factor`` times: the mean of each ``factor x factor``
    block (the last ``W mod factor`` columns and ``H mod factor`` rows left out), in the
    image's dtype (OpenCV's area resize at an integer factor)."""
    if factor == 1:
        return img
    import cv2  # noqa: PLC0415

    h, w = img.shape[0] // factor, img.shape[1] // factor
    if h < 1 or w < 1:
        raise ValueError(f"a {img.shape[1]}x{img.shape[0]} image cannot be reduced "
                         f"{factor} times")
    crop = np.ascontiguousarray(img[:h * factor, :w * factor])
    return cv2.resize(crop, (w, h), interpolation=cv2.INTER_AREA)


def downsampled(job: DepthJob, factor: int) -> DepthJob:
    """``job`` at 1 / ``factor`` of the views' resolution: its cameras reduced
    (:func:`downsample_camera`), its views read reduced (:func:`job_images`)."""
    if int(factor) < 1:
        raise ValueError(f"depth.registration_downsample must be >= 1 (got {factor})")
    factor = int(factor)
    return replace(job, ref_cam=downsample_camera(job.ref_cam, factor),
                   src_cams=[downsample_camera(c, factor) for c in job.src_cams],
                   downsample=job.downsample * factor)


def job_images(job: DepthJob, image: Callable[[str | Path], np.ndarray]
               ) -> tuple[np.ndarray, list[np.ndarray]]:
    """The reference and source views of ``job`` as ``image(path)`` reads them, reduced
    by the job's ``downsample`` factor."""
    f = job.downsample
    return (downsample_image(image(job.ref_path), f),
            [downsample_image(image(p), f) for p in job.src_paths])
