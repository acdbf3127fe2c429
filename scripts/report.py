"""Rule report: results/<dataset>/report/index.html, a self-contained page (images
embedded, no server, no network) built from whatever evaluation files exist."""

import logging
from pathlib import Path

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)

from plenocal.report.html import build_report

snakemake = globals()["snakemake"]
logging.basicConfig(filename=snakemake.log[0], level=logging.INFO, force=True,
                    format="%(asctime)s %(levelname)s %(message)s")
log = logging.getLogger("report")

out = Path(snakemake.output.html)
info = build_report(Path(snakemake.params.results), out, snakemake.wildcards.dataset,
                    cams=list(snakemake.params.cams), n_views=int(snakemake.params.views),
                    synthetic=bool(snakemake.params.synthetic), log=log.info)
log.info("wrote %s: %d bytes, %d sections, %d source files linked", out, info["bytes"],
         len(info["sections"]), len(info["linked"]))
