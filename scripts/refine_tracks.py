"""Rule refine_tracks: one track set of the joint refinement (its source, the wildcard:
central or views), triangulated with the Eq. 6 cameras and aligned by the views' patches
(plenocal.calib.track_sets.make_track_set), for rule refine."""

# first, before numpy, OpenCV and pycolmap size their thread pools (plenocal.library_threads)
from plenocal.library_threads import pin_library_threads

pin_library_threads()

import shutil  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402, F401  (before pycolmap: see DESIGN.md on cv2/pycolmap)

from plenocal.artifacts.cameras import read_cameras  # noqa: E402
from plenocal.artifacts.rig import read_rig  # noqa: E402
from plenocal.artifacts.tracks import write_tracks  # noqa: E402
from plenocal.calib.refine import RefineSettings  # noqa: E402
from plenocal.calib.track_sets import make_track_set  # noqa: E402
from plenocal.convert.viewset import view_set_files  # noqa: E402
from plenocal.io.files import make_temp_dir  # noqa: E402
from plenocal.rulelog import rule_logger  # noqa: E402

snakemake = globals()["snakemake"]
sm = snakemake
source = sm.wildcards.source
log = rule_logger(snakemake, f"refine_tracks ({source})")

settings = RefineSettings.from_config(sm.params.refine, seed=int(sm.params.sfm["seed"]),
                                      num_threads=int(sm.threads))
out = Path(sm.output.tracks)
out.parent.mkdir(parents=True, exist_ok=True)
# COLMAP's working files beside the output, removed at the end (and a killed job's by the
# next run: make_temp_dir)
work = make_temp_dir(out.parent, f".{source}.work.")
t0 = time.perf_counter()
try:
    tracks, alignment, _ = make_track_set(
        source, read_cameras(sm.input.eq6), read_rig(sm.input.rig), sm.input.database,
        settings, view_set_files(sm.input.view_sets) if "view_sets" in sm.input.keys()
        else None, align_threads=int(sm.threads),
        work_dir=work)
finally:
    shutil.rmtree(work, ignore_errors=True)
write_tracks(out, source, tracks, alignment)
log.info("wrote %s: %d points, %d images (%.1f s)", out, len(tracks.points),
         len(tracks.names), time.perf_counter() - t0)
