"""Rule match_a: exhaustive matching and geometric verification of registration A."""
import shutil
from pathlib import Path

import cv2  # noqa: F401  (before pycolmap: DESIGN.md, Known traps)

from plenocal.calib.reg_a.colmap import check_database, resolve_sfm_device
from plenocal.calib.reg_a.sfm import RegistrationError, match_a
from plenocal.io.files import write_json
from plenocal.rulelog import log_to_file

log_to_file(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
cfg = sm.params.sfm
use_gpu, _ = resolve_sfm_device(cfg)  # sfm.device
images = check_database(sm.input.db, "delete it and run again: rule features_a makes it "
                        "anew")
if images < 2:
    raise RegistrationError(f"{sm.input.db}: {images} image(s), nothing to match; rule "
                            "features_a stages every shot's central view")
# matches go into a copy: the features database stays the input it was
tmp = Path(sm.output.db + ".part")
try:
    shutil.copyfile(sm.input.db, tmp)
    info = match_a(tmp, seed=cfg["seed"], num_threads=sm.threads, use_gpu=use_gpu,
                   name=sm.input.db)
    shutil.move(tmp, sm.output.db)
finally:  # a failed match leaves no copy beside the outputs
    tmp.unlink(missing_ok=True)
write_json(sm.output.info, info)
