"""The two depth maps of a shot's central view (rule depth): in registration A (sources:
the central views of the nearest shots, SfM units) and in registration B (sources: views
of its own set, metres), the inputs of the scale (Eq. 5). One job computes both: they share
the process start-up and the reference view (on the default data 28 jobs instead of 56,
each about 1 s of start-up). :mod:`plenocal.depth.inputs` chooses sources and bounds."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from plenocal.artifacts.reg_a import read_reg_a
from plenocal.artifacts.rig import read_rig
from plenocal.depth import estimate_depth, resolve_backend
from plenocal.depth.inputs import depth_job_a, depth_job_b
from plenocal.io.files import read_image

log = logging.getLogger(__name__)

#: the registrations, in the order their maps are computed
REGISTRATIONS = ("a", "b")


@dataclass(frozen=True)
class ShotDepth:
    """One registration's depth map of a shot's central view and what it was made from."""
    depth: np.ndarray  # (H, W) z-depth, 0 where invalid
    info: dict  # backend, bounds, units, sources, valid share, reference


def shot_depths(cam: str, centre: str, reg_a_path: str | Path, rig_path: str | Path,
                views_dir: str | Path, model_dir: str | Path | None,
                cfg: dict) -> dict[str, ShotDepth]:
    """The depth maps of shot ``cam``'s central view ``centre`` in registrations A
    (``reg_a.json`` at ``reg_a_path``, its COLMAP model in ``model_dir`` for the bounds) and
    B (``rig.json`` at ``rig_path``), from the views in ``views_dir``; ``cfg``: the depth
    stage's settings (backend, sources_a, sources_b, bounds_margin and the backend's)."""
    margin = float(cfg["bounds_margin"])
    backend = resolve_backend(cfg["backend"])
    jobs = {
        "a": depth_job_a(read_reg_a(reg_a_path), reg_a_path, cam, centre, views_dir,
                         model_dir, int(cfg["sources_a"]), margin),
        "b": depth_job_b(read_rig(rig_path), cam, centre, views_dir, cfg["sources_b"],
                         margin),
    }
    images: dict[str, np.ndarray] = {}

    def image(path) -> np.ndarray:
        key = str(path)
        if key not in images:
            images[key] = read_image(path)
        return images[key]

    out = {}
    for reg in REGISTRATIONS:
        job = jobs[reg]
        log.info("%s/%s: backend %s, bounds [%.6g, %.6g] %s, sources %s", reg, cam, backend,
                 job.near, job.far, job.units, ", ".join(job.src_names))
        t0 = time.perf_counter()
        depth = estimate_depth(job.ref_cam, image(job.ref_path), job.src_cams,
                               [image(p) for p in job.src_paths], job.near, job.far, cfg,
                               backend=backend)
        valid = float((depth > 0).mean())
        log.info("%s/%s: %.1f s, %.1f %% valid", reg, cam, time.perf_counter() - t0,
                 100 * valid)
        out[reg] = ShotDepth(depth, {"backend": backend, "near": job.near, "far": job.far,
                                     "units": job.units, "sources": job.src_names,
                                     "valid_share": valid, "reference": f"{cam}/{centre}"})
    return out
