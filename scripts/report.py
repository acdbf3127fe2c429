"""Rule report: results/<dataset>/report/index.html, a self-contained page (images
embedded, no server, no network) built from whatever evaluation files exist."""

from pathlib import Path

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)

from plenocal.report.html import build_report
from plenocal.rulelog import rule_logger

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "report")

out = Path(snakemake.output.html)
results = Path(snakemake.params.results)
# the exports this run made, as the page names them (under results/<dataset>/)
exports = [Path(p).relative_to(results).as_posix() for p in snakemake.input.get("exports", [])]
info = build_report(results, out, snakemake.wildcards.dataset,
                    cams=list(snakemake.params.cams), n_views=int(snakemake.params.views),
                    synthetic=bool(snakemake.params.synthetic), exports=exports,
                    log=log.info)
log.info("wrote %s: %d bytes, %d sections, %d source files linked", out, info["bytes"],
         len(info["sections"]), len(info["linked"]))
