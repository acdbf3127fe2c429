"""Lenslet-to-multiview conversion (the paper's RLC, Fig. 1 (a)): patch sizes by block
matching and the MLA kind read from the image (:mod:`.patchsize`), view rendering
(:mod:`.render`), grey levels of 10-16-bit frames (:mod:`.levels`), micro-image
vignetting (:mod:`.vignetting`), the per-shot driver (:mod:`.shot`; it writes
``disparity.json``, :mod:`plenocal.artifacts.disparity`), quality against ideal renders
(:mod:`.quality`) and against another converter's views of a real frame
(:mod:`.compare`)."""

from plenocal.convert.errors import ConvertError
from plenocal.convert.patchsize import PatchSizeSettings, estimate_patch_size
from plenocal.convert.render import RenderSettings
from plenocal.convert.shot import (
    ConvertSettings,
    ShotConversion,
    convert_files,
    load_lenslet,
)

__all__ = [
    "ConvertError", "ConvertSettings", "PatchSizeSettings", "RenderSettings", "ShotConversion",
    "convert_files", "estimate_patch_size", "load_lenslet",
]
