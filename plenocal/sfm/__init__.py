"""Structure-from-motion with pycolmap: registration A (Section II-B of the paper), the
COLMAP boundary conversions, and a synthetic capture for the tests."""

from __future__ import annotations

import logging
import os
import sys


def log_to_file(path: str) -> None:
    """Send Python logging and everything written to stdout/stderr, COLMAP's own log
    included (it writes to file descriptor 2), to ``path`` (a Snakemake rule's log)."""
    fh = open(path, "a", buffering=1)  # noqa: SIM115  (kept open for the process)
    sys.stdout.flush()
    sys.stderr.flush()
    os.dup2(fh.fileno(), 1)
    os.dup2(fh.fileno(), 2)
    logging.basicConfig(level=logging.INFO, stream=sys.stderr, force=True,
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
