"""The depth maps of the shots' central views in registrations A and B, the inputs of the
scale (Eq. 5; Fig. 4c): rule depth_a makes every shot's map in registration A (sources: the
central views of the nearest shots, SfM units), rule depth_b every shot's map in
registration B (sources: views of its own set, metres). :mod:`plenocal.depth.inputs`
chooses sources and bounds.

Registration A's left-right check compares each shot's map with the map of its nearest
source, which is itself one of the maps made here: the plane sweep makes every shot's map
once, unchecked, and then checks each against its neighbour's (:func:`depths_a`). Where
each map was made alone, the check swept the neighbour a second time from other sources
(82 labels beside the map's own 52 on the default data), and each shot paid a process
start-up; one job for all shots does neither. Registration B's check partner is another
view of the shot's own set, whose map nothing else needs: it is swept for the check, as
before.

Both registrations' maps are made at 1 / ``depth.registration_downsample`` of the views'
resolution (:func:`plenocal.depth.inputs.downsampled`; half by default): the views are
read reduced and the cameras reduced with them, so a map is ``W // f x H // f``."""

from __future__ import annotations

import logging
import multiprocessing as mp
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from plenocal.artifacts.reg_a import read_reg_a
from plenocal.artifacts.rig import read_rig
from plenocal.config import with_defaults
from plenocal.depth import (
    MvsProblem,
    colmap_depths_in_one_run,
    estimate_depth,
    planesweep_options,
    resolve_backend,
)
from plenocal.depth.inputs import DepthJob, depth_job_a, depth_job_b, downsampled, job_images
from plenocal.depth.planesweep import (
    PlaneSweepOptions,
    left_right_check,
    plane_sweep_unchecked,
)
from plenocal.io.files import read_image

log = logging.getLogger(__name__)

@dataclass(frozen=True)
class ShotDepth:
    """One registration's depth map of a shot's central view and what it was made from."""
    depth: np.ndarray  # (H, W) z-depth, 0 where invalid
    info: dict  # backend, bounds, units, sources, valid share, reference


class _Images:
    """The views read so far, by path (a shot's central view is the source of several
    maps)."""

    def __init__(self) -> None:
        self._images: dict[str, np.ndarray] = {}

    def __call__(self, path: str | Path) -> np.ndarray:
        key = str(path)
        if key not in self._images:
            self._images[key] = read_image(path)
        return self._images[key]


def _info(job: DepthJob, backend: str, cam: str, centre: str, depth: np.ndarray,
          **extra) -> dict:
    return {"backend": backend, "near": job.near, "far": job.far, "units": job.units,
            "sources": job.src_names, "valid_share": float((depth > 0).mean()),
            "reference": f"{cam}/{centre}", "downsample": job.downsample,
            "size": [int(depth.shape[1]), int(depth.shape[0])], **extra}


def _estimate_each(reg: str, jobs: dict[str, DepthJob], centre: str, cfg: dict, backend: str,
                   progress: Callable[[str], None]) -> dict[str, ShotDepth]:
    """Each job's map on its own (the backend checks it as it does); COLMAP's maps all in
    one run (:func:`plenocal.depth.colmap_depths_in_one_run`)."""
    image = _Images()
    out = {}
    if backend == "colmap":
        t0 = time.perf_counter()
        problems = []
        for job in jobs.values():
            ref_img, src_imgs = job_images(job, image)
            problems.append(MvsProblem(job.ref_cam, ref_img, job.src_cams, src_imgs,
                                       job.near, job.far))
        depths = colmap_depths_in_one_run(problems, cfg)
        for (cam, job), depth in zip(jobs.items(), depths, strict=True):
            out[cam] = ShotDepth(depth, _info(job, backend, cam, centre, depth))
            progress(f"{reg}/{cam}: {100 * out[cam].info['valid_share']:.1f} % valid")
        progress(f"{reg}: {len(jobs)} maps by COLMAP in one run, "
                 f"{time.perf_counter() - t0:.1f} s")
        return out
    for k, (cam, job) in enumerate(jobs.items()):
        t0 = time.perf_counter()
        ref_img, src_imgs = job_images(job, image)
        depth = estimate_depth(job.ref_cam, ref_img, job.src_cams, src_imgs, job.near,
                               job.far, cfg, backend=backend)
        out[cam] = ShotDepth(depth, _info(job, backend, cam, centre, depth))
        progress(f"{reg}/{cam}: {time.perf_counter() - t0:.1f} s, "
                 f"{100 * out[cam].info['valid_share']:.1f} % valid ({k + 1} of {len(jobs)})")
    return out


def _downsample(cfg: dict) -> int:
    """The registrations' depth maps' reduction (``depth.registration_downsample``; the
    schema's default where a partial block leaves it out)."""
    return int(with_defaults("depth", cfg)["registration_downsample"])


def _describe(reg: str, jobs: dict[str, DepthJob], backend: str,
              progress: Callable[[str], None]) -> None:
    for cam, job in jobs.items():
        progress(f"{reg}/{cam}: backend {backend}, bounds [{job.near:.6g}, {job.far:.6g}] "
                 f"{job.units}, sources {', '.join(job.src_names)}")


def _sweep_one(job: DepthJob, opt: PlaneSweepOptions,
               image: Callable[[str | Path], np.ndarray] = read_image
               ) -> tuple[np.ndarray, float]:
    """One unchecked plane-sweep map (the views read here, by ``image``: in a worker
    process too)."""
    t0 = time.perf_counter()
    ref_img, src_imgs = job_images(job, image)
    depth = plane_sweep_unchecked(job.ref_cam, ref_img, job.src_cams, src_imgs, job.near,
                                  job.far, opt)
    return depth, time.perf_counter() - t0


def _sweep_all(jobs: dict[str, DepthJob], opt: PlaneSweepOptions, processes: int
               ) -> Iterator[tuple[str, np.ndarray, float]]:
    """(shot, unchecked map, seconds) of every job, in order, swept in ``processes``
    worker processes (1: here). Each map is swept alone, so any number gives the same
    maps. Processes, not threads: the sweep's Python between OpenCV's and the compiled
    kernels' calls holds the GIL, and two threads swept registration A's 21 maps only
    1.3x as fast as one where two processes take half the time (issue 15)."""
    if processes <= 1 or len(jobs) <= 1:
        # each view read once: registration A's 21 maps read 147 views, 21 of them distinct
        image = _Images()
        for cam, job in jobs.items():
            yield (cam, *_sweep_one(job, opt, image))
        return
    ctx = mp.get_context("fork" if "fork" in mp.get_all_start_methods() else "spawn")
    with ProcessPoolExecutor(max_workers=min(processes, len(jobs)), mp_context=ctx) as pool:
        futures = {cam: pool.submit(_sweep_one, job, opt) for cam, job in jobs.items()}
        for cam, fut in futures.items():
            yield (cam, *fut.result())


def depths_a(cams: list[str], centre: str, reg_a_path: str | Path, views_dir: str | Path,
             model_dir: str | Path | None, cfg: dict,
             progress: Callable[[str], None] = log.info, threads: int = 1
             ) -> dict[str, ShotDepth]:
    """Registration A's depth map of the central view ``centre`` of every shot in ``cams``
    (``reg_a.json`` at ``reg_a_path``, its COLMAP model in ``model_dir`` for the bounds),
    from the views in ``views_dir``; ``cfg``: the depth stage's settings (backend,
    sources_a, bounds_margin and the backend's).

    With the plane sweep every map is swept once, then (``lr_check``) each keeps the
    pixels that its nearest source's map - one of these maps - sees at the same depth
    within ``lr_tolerance`` (:func:`plenocal.depth.planesweep.left_right_check`); a
    nearest source that is not among ``cams`` is swept for the check alone. The sweeps run
    in ``threads`` processes (each map alone: the same maps on any number)."""
    backend = resolve_backend(cfg["backend"])
    reg_a = read_reg_a(reg_a_path)
    factor = _downsample(cfg)

    def job_of(cam: str) -> DepthJob:
        return downsampled(depth_job_a(reg_a, reg_a_path, cam, centre, views_dir, model_dir,
                                       int(cfg["sources_a"]), float(cfg["bounds_margin"])),
                           factor)

    jobs = {cam: job_of(cam) for cam in cams}
    _describe("a", jobs, backend, progress)
    if backend != "planesweep":
        return _estimate_each("a", jobs, centre, cfg, backend, progress)
    opt = planesweep_options(cfg)
    partners = {job.src_names[0] for job in jobs.values()} - set(jobs) if opt.lr_check \
        else set()
    todo = dict(jobs) | {p: job_of(p) for p in sorted(partners)}
    raw: dict[str, np.ndarray] = {}
    for cam, depth, seconds in _sweep_all(todo, opt, threads):
        raw[cam] = depth
        progress(f"a/{cam}: swept in {seconds:.1f} s")
    out = {}
    for cam, job in jobs.items():
        depth = raw[cam]
        extra = {}
        if opt.lr_check:
            partner = job.src_names[0]  # the nearest source
            ok = left_right_check(job.ref_cam, depth, job.src_cams[0], raw[partner],
                                  opt.lr_tolerance)
            depth = np.where(ok, depth, 0.0).astype(np.float32)
            extra["lr_partner"] = partner
        out[cam] = ShotDepth(depth, _info(job, backend, cam, centre, depth, **extra))
        progress(f"a/{cam}: {100 * out[cam].info['valid_share']:.1f} % valid")
    return out


def depths_b(cams: list[str], centre: str, rig_path: str | Path, views_dir: str | Path,
             cfg: dict, progress: Callable[[str], None] = log.info) -> dict[str, ShotDepth]:
    """Registration B's depth map of the central view ``centre`` of every shot in ``cams``
    (``rig.json`` at ``rig_path``), from the other views of its own set in ``views_dir``;
    ``cfg``: the depth stage's settings (backend, sources_b, bounds_margin and the
    backend's)."""
    backend = resolve_backend(cfg["backend"])
    rig = read_rig(rig_path)
    factor = _downsample(cfg)
    jobs = {cam: downsampled(depth_job_b(rig, cam, centre, views_dir, cfg["sources_b"],
                                         float(cfg["bounds_margin"])), factor)
            for cam in cams}
    _describe("b", jobs, backend, progress)
    return _estimate_each("b", jobs, centre, cfg, backend, progress)
