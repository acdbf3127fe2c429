"""Rule lenslet_frame: the frame to calibrate on of a shot given as a raw YUV recording
(config datasets.<d>.video; plenocal.io.lenslet) -> the RGB lenslet image that the
conversion reads (8-bit for an 8-bit recording, else 16-bit), as `plenocal convert` makes
it of a frame (plenocal.convert.video.lenslet_frame)."""

import time

import cv2

from plenocal.io.files import write_image
from plenocal.io.lenslet import extract_frame, video_shot_from_params
from plenocal.rulelog import rule_logger

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "lenslet_frame")
cv2.setNumThreads(max(1, int(snakemake.threads)))

t0 = time.perf_counter()
shot = video_shot_from_params(snakemake.input.video, snakemake.params.video)
image = extract_frame(shot)
write_image(snakemake.output.lenslet, image)
log.info("%s: frame %d (%dx%d, %d bit, %s %s range) -> %s, %d-bit RGB, %.2f s",
         shot.path, shot.frame, shot.fmt.width, shot.fmt.height, shot.fmt.bits, shot.matrix,
         shot.range, snakemake.output.lenslet, 8 * image.itemsize, time.perf_counter() - t0)
