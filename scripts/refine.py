"""Rule refine: the Eq. 6 calibration refined under the rig (plenocal.calib.refine), or,
with refine.enabled false, copied as it is; written in every export format."""

# first, before numpy, OpenCV and pycolmap size their thread pools: one thread each, so
# that refine.num_threads changes the time and not a bit (plenocal.library_threads)
from plenocal.library_threads import pin_library_threads

pin_library_threads()

import shutil  # noqa: E402
from functools import partial  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402, F401  (before pycolmap: see DESIGN.md on cv2/pycolmap)

from plenocal.artifacts.cameras import read_cameras, write_cameras  # noqa: E402
from plenocal.artifacts.rig import RigB, read_rig  # noqa: E402
from plenocal.artifacts.scale import read_scale  # noqa: E402
from plenocal.artifacts.tracks import read_tracks, track_source  # noqa: E402
from plenocal.calib.refine import RefineSettings, refine_calibration  # noqa: E402
from plenocal.calib.reg_b.rig import rig_at_focal  # noqa: E402
from plenocal.export.colmap_model import write_colmap  # noqa: E402
from plenocal.export.mpeg import write_mpeg  # noqa: E402
from plenocal.io.files import make_temp_dir, write_json  # noqa: E402
from plenocal.rulelog import rule_logger  # noqa: E402


def _tracks_of(folder: str) -> tuple:
    """The track set in ``folder`` and its alignment's statistics."""
    stored = read_tracks(folder)
    return stored.tracks, stored.alignment


snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "refine")
sm = snakemake

eq6 = read_cameras(sm.input.eq6)
rig = read_rig(sm.input.rig)
# every step on the job's threads (refine.num_threads: the same bytes for any number)
settings = RefineSettings.from_config(sm.params.refine, seed=int(sm.params.sfm["seed"]),
                                      num_threads=int(sm.threads))
if settings.enabled:
    # the stage's step where the merge took its scale from it (refine.scale: auto fits it
    # to the refined array shots)
    scale = read_scale(sm.input.scale)
    step_m = (float(scale.array_step["step_m"]) if scale.chosen == "array_step" else None)
    # the track sets of rule refine_tracks, one job per source (made side by side), read
    # where the rig reconstruction is built and released with its plain data, before the
    # adjustments
    sources = {track_source(folder): partial(_tracks_of, folder) for folder in sm.input.tracks}
    # COLMAP's working files beside the output, removed at the end (and a killed job's by
    # the next run: make_temp_dir)
    work = make_temp_dir(Path(sm.output.info).parent, ".refine.")
    try:
        result = refine_calibration(
            eq6, rig, None, settings, hold_shot=sm.params.hold_shot,
            rig_at_focal=lambda f: RigB(rig_at_focal(rig.doc, f)), work_dir=work,
            step_m=step_m, track_sets=sources)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    cams, info = result.cameras, {"enabled": True, **result.report}
    source = ("plenocal merge (Eq. 6: the refinement was not kept, see refine.json)"
              if info["rejected"] else "plenocal refine (all views under the rig)")
else:
    cams, info = eq6, {"enabled": False, "settings": dict(sm.params.refine)}
    source = "plenocal merge (Eq. 6)"
    log.info("refine.enabled is false: calibration/ holds the Eq. 6 result")
missing = sorted(set(eq6) - set(cams))
if missing:
    raise RuntimeError(f"the refinement lost {len(missing)} views ({', '.join(missing[:5])})")
extra = {"source": source, "rig_model": rig.model}
write_cameras(sm.output.plain, cams, extra=extra)
near, far = rig.depth_range_m
write_mpeg(sm.output.mpeg, cams, (near, far), content_name=sm.wildcards.dataset)
write_colmap(sm.output.colmap, cams)
write_json(sm.output.info, {"format": "plenocal.refine", "version": 1, **info})
log.info("wrote %s, %s, %s (%d cameras)", sm.output.plain, sm.output.mpeg, sm.output.colmap,
         len(cams))
