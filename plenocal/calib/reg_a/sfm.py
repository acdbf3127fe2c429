"""Registration A (Section II-B of the paper): structure-from-motion of the central
subaperture view of every array shot plus every hand-held shot.

- one shared SIMPLE_PINHOLE camera (all shots come from the same camera), principal
  point fixed at the image centre and no distortion: the views are recombined from
  micro images, so the paper assumes both;
- exhaustive SIFT matching with geometric verification;
- incremental mapping (or COLMAP's global mapper, option ``mapper: global``) with a
  fixed seed, refining the focal length only.

The hand-held shots are required: a parallel array alone leaves the focal length
undetermined (it trades off against depth at a tiny reprojection error, [27] of the
paper). A view that does not register, or a scene split into several models, stops
the stage with an error naming the views.

Output: :class:`plenocal.artifacts.reg_a.RegistrationA`, written as ``reg_a.json`` (SfM
units, internal convention)::

    {"format": "plenocal.reg_a", "version": 1, "units": "sfm", "focal_px": f, "width": W,
     "height": H, "mapper": ..., "cameras": {"<cam>": {"K": 3x3, "cam_to_world": 4x4}},
     "mean_reprojection_error_px": ..., "num_points3D": ..., ...}
"""

from __future__ import annotations

import logging
import shutil
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from plenocal.artifacts.reg_a import RegistrationA
from plenocal.artifacts.stage_warnings import WARNINGS_KEY, warning_list
from plenocal.calib.reg_a import colmap as cm
from plenocal.calib.reg_a.uncertainty import reconstruction_focal_std_px
from plenocal.io.files import atomic_write_dir, make_temp_dir
from plenocal.io.lenslet import HANDHELD_WHY
from plenocal.names import is_handheld_shot

log = logging.getLogger(__name__)


class RegistrationError(RuntimeError):
    """Registration A could not register every view."""


def check_shots(cams: list[str]) -> None:
    """Registration A needs hand-held shots besides the array (Section II-B)."""
    hand = [c for c in cams if is_handheld_shot(c)]
    array = [c for c in cams if not is_handheld_shot(c)]
    if not hand:
        raise RegistrationError(
            "registration A needs hand-held shots (hand00.png, ...): with the parallel "
            f"array alone ({len(array)} shots) {HANDHELD_WHY}.")
    if len(cams) < 3:
        raise RegistrationError(f"registration A needs at least 3 shots, got {cams}")


#: fewer SIFT keypoints than this in a central view: a warning (it may not register)
MIN_KEYPOINTS = 100


def features_a(views: Mapping[str, str | Path], image_dir: str | Path,
               database: str | Path, *,
               max_num_features: int = cm.DEFAULT_MAX_FEATURES, seed: int = cm.DEFAULT_SEED,
               num_threads: int = cm.DEFAULT_THREADS, first_octave: int = cm.DEFAULT_FIRST_OCTAVE,
               extractor: str = cm.DEFAULT_EXTRACTOR, use_gpu: bool = False,
               contrast: float = cm.DEFAULT_CONTRAST) -> dict:
    """Stage the central views (``views``: cam -> png) as ``<cam>.png`` in ``image_dir``
    and extract SIFT into a new ``database`` with one SIMPLE_PINHOLE camera for all
    (``first_octave``: the same SIFT setting as the view database's, so the naive
    baseline and the proposed calibration start from the same kind of features;
    ``contrast``: SIFT's DoG peak threshold, :data:`plenocal.calib.reg_a.colmap.
    DEFAULT_CONTRAST`)."""
    check_shots(sorted(views))
    sizes = {cam: cm.image_size(p) for cam, p in sorted(views.items())}
    if len(set(sizes.values())) != 1:
        detail = ", ".join(f"{c}: {w}x{h}" for c, (w, h) in sizes.items())
        raise RegistrationError(f"the central views differ in size ({detail}); one shared "
                                "camera needs one size: reconvert every shot alike")
    image_dir = Path(image_dir)
    if image_dir.exists():
        shutil.rmtree(image_dir)
    names = cm.stage_images(views, image_dir)
    cm.extract_features(database, image_dir, [(names, None)], model="SIMPLE_PINHOLE",
                        max_num_features=max_num_features, num_threads=num_threads, seed=seed,
                        first_octave=first_octave, extractor=extractor, use_gpu=use_gpu,
                        contrast=contrast)
    import pycolmap  # noqa: PLC0415

    with pycolmap.Database.open(str(database)) as db:
        kp = {im.name: db.num_keypoints_for_image(im.image_id) for im in db.read_all_images()}
        ncam = db.num_cameras()
    if ncam != 1:
        raise RegistrationError(f"expected one shared camera in {database}, found {ncam}")
    poor = sorted(n for n, k in kp.items() if k < MIN_KEYPOINTS)
    for n in sorted(kp):
        log.info("features_a: %s %d keypoints", n, kp[n])
    warnings = []
    if poor:
        warnings.append(
            f"few features (< {MIN_KEYPOINTS} SIFT keypoints) in the central views of "
            + ", ".join(f"{n[:-4]} ({kp[n]})" for n in poor)
            + ": texture-poor views may not register (more texture, light or focus)")
        log.warning("%s", warnings[-1])
    # read by the report's Warnings box (plenocal.report.sources)
    return {"num_images": len(kp), "keypoints": kp, "sift": extractor,
            "device": cm.sift_device(extractor, use_gpu),
            WARNINGS_KEY: warning_list(warnings)}


def match_a(database: str | Path, *, seed: int = cm.DEFAULT_SEED,
            num_threads: int = cm.DEFAULT_THREADS, use_gpu: bool = False,
            name: str | Path | None = None) -> dict:
    """Exhaustive matching (on the GPU with ``use_gpu``) with geometric verification.
    ``name``: the database its errors name (rule match_a matches in a copy of its input,
    removed on failure)."""
    n = cm.match(database, None, seed=seed, num_threads=num_threads, use_gpu=use_gpu)
    if n == 0:
        raise RegistrationError(f"{name or database}: no image pair passed geometric "
                                "verification; the views need more texture or overlap")
    return {"num_verified_pairs": n, "device": "cuda" if use_gpu else "cpu"}


def incremental_options(seed: int, num_threads: int):
    import pycolmap  # noqa: PLC0415

    o = pycolmap.IncrementalPipelineOptions()
    o.random_seed = seed
    o.mapper.random_seed = seed
    o.triangulation.random_seed = seed
    o.num_threads = num_threads
    o.mapper.num_threads = num_threads
    o.ba_refine_focal_length = True
    o.ba_refine_principal_point = False
    o.ba_refine_extra_params = False
    o.mapper.abs_pose_refine_focal_length = True
    o.mapper.abs_pose_refine_extra_params = False
    o.multiple_models = True
    o.min_model_size = 2
    return o


def global_options(seed: int, num_threads: int):
    import pycolmap  # noqa: PLC0415

    o = pycolmap.GlobalPipelineOptions()
    o.random_seed = seed
    o.num_threads = num_threads
    o.multiple_models = True
    o.min_model_size = 2
    m = o.mapper
    m.random_seed = seed
    m.num_threads = num_threads
    m.rotation_averaging.random_seed = seed
    m.global_positioning.random_seed = seed
    m.global_positioning.use_gpu = False
    ba = m.bundle_adjustment
    ba.refine_focal_length = True
    ba.refine_principal_point = False
    ba.refine_extra_params = False
    ba.ceres.use_gpu = False
    m.retriangulation.random_seed = seed
    return o


def run_mapper(database: str | Path, image_dir: str | Path, *,
               mapper: str = cm.SFM_DEFAULTS["mapper"], seed: int = cm.DEFAULT_SEED,
               num_threads: int = cm.DEFAULT_THREADS) -> dict:
    """Run the mapper; returns {model index: Reconstruction}."""
    import pycolmap  # noqa: PLC0415

    pycolmap.set_random_seed(seed)
    out = make_temp_dir(Path(database).parent, ".mapper.")
    try:
        if mapper == "incremental":
            recs = pycolmap.incremental_mapping(str(database), str(image_dir), str(out),
                                                options=incremental_options(seed, num_threads))
        elif mapper == "global":
            recs = pycolmap.global_mapping(str(database), str(image_dir), str(out),
                                           options=global_options(seed, num_threads))
        else:
            raise ValueError(f"sfm.mapper must be incremental or global, not {mapper!r}")
    finally:
        shutil.rmtree(out, ignore_errors=True)
    return dict(recs)


def check_models(recs: dict, all_names: list[str], mapper: str) -> object:
    """The single model holding every view, or a RegistrationError naming the views."""
    hint = ("try: more texture or overlap between the shots, more hand-held shots, "
            "more features (sfm.max_num_features)"
            + (", or sfm.mapper: global" if mapper == "incremental" else
               ", or sfm.mapper: incremental"))
    if not recs:
        raise RegistrationError(f"registration A ({mapper}) built no model from "
                                f"{len(all_names)} views; {hint}")
    models = sorted(recs.values(), key=lambda r: -r.num_reg_images())
    parts = "; ".join(
        f"model {i}: " + ", ".join(sorted(r.image(j).name[:-4] for j in r.reg_image_ids()))
        for i, r in enumerate(models))
    if len(models) > 1 and models[0].num_reg_images() < len(all_names):
        anywhere = {r.image(j).name for r in models for j in r.reg_image_ids()}
        nowhere = sorted(n[:-4] for n in all_names if n not in anywhere)
        unplaced = f"; in none: {', '.join(nowhere)}" if nowhere else ""
        raise RegistrationError(f"registration A ({mapper}) split the scene into "
                                f"{len(models)} models ({parts}{unplaced}); {hint}")
    if len(models) > 1:
        # COLMAP may start a second model from views that are already in the first one
        # (leftover pairs); the first holds every view and is the registration
        log.warning("registration A (%s): %d models, the first holds every view and is "
                    "used (%s)", mapper, len(models), parts)
    rec = models[0]
    reg = {rec.image(j).name for j in rec.reg_image_ids()}
    missing = sorted(n[:-4] for n in all_names if n not in reg)
    if missing:
        raise RegistrationError(f"registration A ({mapper}) did not register "
                                f"{', '.join(missing)}; {hint}")
    if rec.num_cameras() != 1:
        raise RegistrationError(f"registration A expected one shared camera, the model has "
                                f"{rec.num_cameras()}")
    return rec


#: a shot held by fewer 3-D points than this share of the shots' median: its pose is
#: doubtful. Over 64 kept captures of the simulator, tele-s36's hand03 was held by 19
#: against a median of 1,221 (0.016) and was 8.5 mm and 0.33 deg off; every other
#: capture's weakest shot had at least 0.33 of its median
WEAK_SHOT_SHARE = 0.1


def weak_shots(points: Mapping[str, int], share: float = WEAK_SHOT_SHARE) -> list[str]:
    """Warnings for the shots whose central view registration A holds by fewer 3-D points
    than ``share`` of the shots' median (``points``: shot -> its points)."""
    if not points:
        return []
    median = float(np.median(list(points.values())))
    return [f"registration A holds shot {shot} by {n} points, against the shots' median of "
            f"{median:.0f}: its pose may be far off (on a simulated capture such a shot, "
            "held by 19 points, was 8.5 mm and 0.33 deg off). The joint refinement corrects "
            "it where the shot's views match the other shots' (refine.json: corrected_shots); "
            "with refine.enabled false, Eq. 6 keeps it: give the shot more overlap with the "
            "others, or leave it out"
            for shot, n in sorted(points.items()) if n < share * median]


def reg_a_dict(rec, mapper: str, notes: Sequence[str] = ()) -> RegistrationA:
    """Registration A of a single-camera reconstruction (``reg_a.json``, internal
    convention; :mod:`plenocal.artifacts.reg_a`); ``notes``: warnings before the weak
    shots' (the mapper that was used instead of the configured one)."""
    cams = {}
    points = {}
    camera = None
    for image_id in sorted(rec.reg_image_ids()):
        image = rec.image(image_id)
        camera = rec.camera(image.camera_id)
        pc = cm.pinhole_from_colmap(image, camera)
        cams[image.name[:-4]] = pc
        points[image.name[:-4]] = int(image.num_points3D)
    if camera is None:
        raise RegistrationError("registration A: the model has no registered image")
    errs = []
    for p in rec.points3D.values():
        for el in p.track.elements:
            image = rec.image(el.image_id)
            proj = image.project_point(p.xyz)
            if proj is not None:
                errs.append(np.linalg.norm(np.asarray(proj) - image.points2D[el.point2D_idx].xy))
    errs = np.asarray(errs)
    stats = {
        "camera_model": camera.model_name,
        "num_images": len(cams),
        "num_points3D": int(rec.num_points3D()),
        "num_observations": int(errs.size),
        "mean_track_length": float(rec.compute_mean_track_length()),
        "mean_reprojection_error_px": float(errs.mean()) if errs.size else None,
        "median_reprojection_error_px": float(np.median(errs)) if errs.size else None,
        "colmap_mean_reprojection_error_px": float(rec.compute_mean_reprojection_error()),
        # how firmly the data fix the focal length (the hand-held shots' turns; a parallel
        # array alone does not): the report shows it where no truth is known
        "focal_std_px": reconstruction_focal_std_px(rec),
        "points_per_shot": points,
    }
    weak = weak_shots(points)
    for msg in weak:
        log.warning(msg)
    # always written, empty where no shot is weak: the report refuses a record without the
    # key (plenocal.artifacts.stage_warnings), as it should a file of another version
    stats[WARNINGS_KEY] = warning_list([*notes, *weak])
    return RegistrationA(focal_px=float(camera.params[0]), width=int(camera.width),
                         height=int(camera.height), mapper=mapper, cameras=cams, stats=stats)


def write_model(rec, folder: str | Path) -> None:
    """Write a binary COLMAP model into ``folder`` atomically."""
    atomic_write_dir(folder, lambda tmp: rec.write_binary(str(tmp)))


def map_a(database: str | Path, image_dir: str | Path, model_dir: str | Path, *,
          mapper: str = cm.SFM_DEFAULTS["mapper"], seed: int = cm.DEFAULT_SEED,
          num_threads: int = cm.DEFAULT_THREADS) -> dict:
    """Map, check that every view registered into one model, write the model; returns
    registration A (what ``reg_a.json`` holds). Where ``mapper`` builds no such model, the
    other mapper is tried once and used if it does, with a warning in the record."""
    import pycolmap  # noqa: PLC0415

    t0 = time.perf_counter()
    # everything works on a copy: the database input of the rule stays untouched (pycolmap
    # writes to any database it opens, if only its change counter: a rule must not modify
    # its inputs), in a temporary folder that a killed job's successor removes (make_temp_dir)
    tmp = make_temp_dir(Path(model_dir).parent, ".map_a.")
    try:
        db_copy = tmp / "database.db"
        shutil.copyfile(database, db_copy)
        with pycolmap.Database.open(str(db_copy)) as db:
            names = sorted(im.name for im in db.read_all_images())
        check_shots([n[:-4] for n in names])
        rec, used, note = _map_either(database, db_copy, image_dir, names, mapper, seed,
                                      num_threads)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    seconds = time.perf_counter() - t0
    log.info("map_a (%s): %d images, %d points, %.1f s", used, rec.num_reg_images(),
             rec.num_points3D(), seconds)
    write_model(rec, model_dir)
    return reg_a_dict(rec, used, [note] if note else [])


def _map_either(database: str | Path, db_copy: Path, image_dir: str | Path,
                names: list[str], mapper: str, seed: int, num_threads: int
                ) -> tuple[object, str, str | None]:
    """The model of ``mapper`` holding every view of ``names`` or, where it builds none,
    the other mapper's, run once on a fresh copy of ``database``: (model, the mapper used, a
    warning when it is the other). COLMAP's global mapper built no model from the 21 views
    of a held-out capture (tele-s39: its bundle adjustment left no 3-D point) that the
    incremental one registers. Where both fail, the first error stands, with the second's."""
    recs = run_mapper(db_copy, image_dir, mapper=mapper, seed=seed, num_threads=num_threads)
    try:
        return check_models(recs, names, mapper), mapper, None
    except RegistrationError as first:
        other = "incremental" if mapper == "global" else "global"
        log.warning("%s; trying sfm.mapper %s", first, other)
        shutil.copyfile(database, db_copy)
        recs = run_mapper(db_copy, image_dir, mapper=other, seed=seed, num_threads=num_threads)
        try:
            rec = check_models(recs, names, other)
        except RegistrationError as second:
            raise RegistrationError(f"{first} (sfm.mapper {other}, tried next, failed too: "
                                    f"{second})") from None
        note = (f"registration A: the {mapper} mapper (sfm.mapper) failed ({first}); the "
                f"{other} mapper registered every view and is used")
        log.warning("%s", note)
        return rec, other, note
