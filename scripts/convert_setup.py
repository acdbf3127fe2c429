"""Rule convert_setup: the converter's per-camera decisions (MLA kind, tile size, grid),
made once on the central array shot and shared by every shot (plenocal.convert.setup)."""

import cv2

from plenocal.convert import ConvertSettings
from plenocal.convert.errors import ConvertError
from plenocal.convert.setup import decide_setup, grid_words, mla_setting_error, write_setup
from plenocal.convert.shot import load_calib, load_lenslet, read_sensor_size
from plenocal.convert.video import video_settings
from plenocal.rulelog import rule_logger

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "convert_setup")
cv2.setNumThreads(max(1, int(snakemake.threads)))

settings = ConvertSettings.from_config(snakemake.params.convert)
image = load_lenslet(snakemake.input.lenslet, read_sensor_size(snakemake.input.camera),
                     settings.bayer)
calib = load_calib(snakemake.input.calib)
if snakemake.params.convert.get("video_frames"):  # the shot is given as a video: its
    settings = video_settings(settings)  # frame by rule lenslet_frame: 16 (or 8) bits
setup, shot = decide_setup(image, calib, int(snakemake.params.views), settings,
                           source=str(snakemake.input.lenslet),
                           grid_foreign=snakemake.params.convert["grid_foreign"])
# an MLA kind set in the config that the image clearly contradicts stops here, before any
# view is made (the command line, which prints the warning, only warns)
error = mla_setting_error(setup, shot, str(snakemake.input.lenslet))
if error:
    raise ConvertError(error)
log.info("MLA %s (%s), tile %d px per lens pitch (%s), grid %s (convert.grid %s)",
         setup.mla, setup.mla_source, setup.tile, setup.tile_source,
         grid_words(setup.grid_check), setup.grid_mode)
log.info("%s", setup.border_cut.summary())
for note in setup.warnings:
    log.warning("%s", note)
write_setup(snakemake.output.setup, setup)
