"""Depth maps of subaperture views: a reference camera + image, source cameras +
images and the scene bounds in, a float32 z-depth map of the reference out (0 =
invalid), by the CPU plane sweep (:mod:`plenocal.depth.planesweep`) or COLMAP's
patch-match stereo (:mod:`plenocal.depth.colmap_mvs`, GPU only)."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from plenocal.camera import PinholeCamera
from plenocal.config import settings_from, with_defaults
from plenocal.depth.colmap_mvs import (
    ColmapOptions,
    DepthBackendError,
    MvsProblem,
    colmap_depths,
)
from plenocal.depth.planesweep import PlaneSweepOptions, plane_sweep_depth
from plenocal.gpu import resolve_auto

__all__ = ["DepthBackendError", "MvsProblem", "colmap_depths_in_one_run", "estimate_depth",
           "planesweep_options", "resolve_backend"]


def planesweep_options(cfg: dict | None) -> PlaneSweepOptions:
    """PlaneSweepOptions from the config's ``depth`` block, partial or whole (missing keys:
    the schema's defaults; unknown keys ignored)."""
    return settings_from(PlaneSweepOptions, with_defaults("depth", cfg))


def colmap_options(cfg: dict | None) -> ColmapOptions:
    """ColmapOptions from the config's ``depth`` block (its ``colmap`` settings), partial or
    whole."""
    return settings_from(ColmapOptions, with_defaults("depth", cfg)["colmap"])


def resolve_backend(name: str) -> str:
    """Config ``depth.backend``: ``auto`` -> colmap where it can run (a CUDA pycolmap and a
    GPU, probed in a subprocess), else planesweep; ``colmap`` where it cannot ->
    DepthBackendError (:func:`plenocal.gpu.resolve_auto`)."""
    return resolve_auto(name, "depth.backend", "planesweep", "colmap", DepthBackendError)


def colmap_depths_in_one_run(problems: list[MvsProblem], cfg: dict | None = None,
                             workspace: str | Path | None = None) -> list[np.ndarray]:
    """Z-depth maps of several references by COLMAP's patch-match stereo in one run (one
    child process and CUDA context for all) in ``workspace`` (None: a temporary one);
    ``cfg``: the config's ``depth`` block, partial or whole."""
    if workspace is not None:
        return colmap_depths(problems, workspace, colmap_options(cfg))
    with tempfile.TemporaryDirectory(prefix="plenocal_mvs_") as tmp:
        return colmap_depths(problems, tmp, colmap_options(cfg))


def estimate_depth(ref: PinholeCamera, ref_img: np.ndarray, srcs: list[PinholeCamera],
                   src_imgs: list[np.ndarray], near: float, far: float,
                   cfg: dict | None = None, backend: str | None = None,
                   workspace: str | Path | None = None) -> np.ndarray:
    """Z-depth of the reference view (float32, cameras' units, 0 = invalid).

    ``cfg`` is the config's ``depth`` block (partial: the schema's defaults fill it);
    ``backend`` an already resolved backend (default: resolve ``cfg['backend']``)."""
    cfg = with_defaults("depth", cfg)
    backend = backend or resolve_backend(cfg["backend"])
    if len(srcs) != len(src_imgs):
        raise ValueError("depth: as many source images as source cameras are needed")
    if backend == "planesweep":
        return plane_sweep_depth(ref, ref_img, srcs, src_imgs, near, far,
                                 planesweep_options(cfg))
    return colmap_depths_in_one_run([MvsProblem(ref, ref_img, srcs, src_imgs, near, far)], cfg,
                                    workspace)[0]
