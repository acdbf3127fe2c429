"""Depth maps of the views that view synthesis reads (and, by ``depth.views: all``,
of every view): one z-depth map per view ``<cam>/<view>`` of the complete calibration,
computed once and shared by every camera set the experiments compare, so that the
dB lost to calibration compares the two camera sets with one and the same depth.

Sources of view ``<cam>/<view>`` (multi-view matching over the set and the
neighbouring shots): the same view of the ``k_shots`` nearest other array shots and
the ``k_set`` nearest views of its own N x N set. Method: ``sgm``
(:mod:`plenocal.depth.sgm`, dense, the default) or ``planesweep``
(:mod:`plenocal.depth.planesweep`, sparse: what registration B's scale uses).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from plenocal.camera import PinholeCamera
from plenocal.config import with_defaults
from plenocal.depth import planesweep_options
from plenocal.depth.inputs import nearest_sources
from plenocal.depth.planesweep import plane_sweep_depth
from plenocal.depth.sgm import sgm_depth, sgm_options
from plenocal.names import is_array_shot, key_shot, split_key, view_name

METHODS = ("sgm", "planesweep")


def view_depth_sources(key: str, cameras: dict[str, PinholeCamera], n_views: int,
                       k_shots: int, k_set: int) -> list[str]:
    """Source views of ``key``: the same view of the ``k_shots`` nearest array shots, then
    the ``k_set`` nearest views of its own set (each sorted by camera-centre distance,
    then name; the config's ``verify.depth_sources_shots`` and ``depth_sources_set``)."""
    cam, view = split_key(key)
    shots = sorted({key_shot(k) for k in cameras if is_array_shot(key_shot(k))})
    same_view = [f"{c}/{view}" for c in shots if f"{c}/{view}" in cameras]
    own_set = [f"{cam}/{view_name(r, c)}" for r in range(n_views) for c in range(n_views)
               if f"{cam}/{view_name(r, c)}" in cameras]
    picked = nearest_sources(key, cameras, k_shots, same_view)
    picked += nearest_sources(key, cameras, k_set, own_set)
    if not picked:
        raise ValueError(f"depth: no source view to estimate the depth of {key}")
    return picked


def estimate_view_depth(key: str, cameras: dict[str, PinholeCamera],
                        image: Callable[[str], np.ndarray], near: float, far: float,
                        n_views: int, depth_cfg: dict | None, k_shots: int,
                        k_set: int) -> tuple[np.ndarray, list[str]]:
    """(z-depth float32, sources) of view ``key`` by ``depth_cfg['synthesis_method']``
    (``sgm`` with the ``depth_cfg['sgm']`` settings, or ``planesweep`` with the
    plane-sweep settings of ``depth_cfg``; partial: the schema's defaults fill it)."""
    cfg = with_defaults("depth", depth_cfg)
    method = cfg["synthesis_method"]
    if method not in METHODS:
        raise ValueError(f"config: depth.synthesis_method = {method!r}: must be one of "
                         f"{', '.join(METHODS)}")
    if key not in cameras:
        raise KeyError(f"depth: view {key} is not in the calibration")
    srcs = view_depth_sources(key, cameras, n_views, k_shots, k_set)
    args = (cameras[key], image(key), [cameras[s] for s in srcs], [image(s) for s in srcs],
            near, far)
    if method == "sgm":
        return sgm_depth(*args, sgm_options(cfg["sgm"])), srcs
    return plane_sweep_depth(*args, planesweep_options(cfg)), srcs
