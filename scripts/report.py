"""Rule report: results/<dataset>/report/index.html, a self-contained page (images
embedded, no server, no network) built from whatever evaluation files exist."""

from pathlib import Path

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)

from plenocal.report.html import build_report
from plenocal.rulelog import rule_logger

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "report")

out = Path(snakemake.output.html)
info = build_report(Path(snakemake.params.results), out, snakemake.wildcards.dataset,
                    cams=list(snakemake.params.cams), n_views=int(snakemake.params.views),
                    synthetic=bool(snakemake.params.synthetic), log=log.info)
log.info("wrote %s: %d bytes, %d sections, %d source files linked", out, info["bytes"],
         len(info["sections"]), len(info["linked"]))
