"""Logging of a workflow rule's script: one set-up for every script in ``scripts/``.

A rule's log file (``log:`` in ``rules/*.smk``) receives Python's logging and
everything the process writes to its standard output and error, the C++ libraries'
own messages included (COLMAP and OpenCV write to file descriptor 2), so that a failed
job's log says what failed.

It is every script's first call, so it also sets what a job's process needs before its
work: numpy's arrays on ordinary pages (:func:`plenocal.malloc.no_huge_pages`).
"""

from __future__ import annotations

import logging
import os
import sys

FORMAT = "%(asctime)s %(name)s %(levelname)s %(message)s"


def log_to_file(path: str) -> None:
    """Send Python logging and everything written to stdout/stderr to ``path``; numpy's
    arrays on ordinary pages from here on (the module docstring)."""
    from plenocal.malloc import no_huge_pages  # noqa: PLC0415

    no_huge_pages()
    fh = open(path, "a", buffering=1)  # noqa: SIM115  (kept open for the process)
    sys.stdout.flush()
    sys.stderr.flush()
    os.dup2(fh.fileno(), 1)
    os.dup2(fh.fileno(), 2)
    logging.basicConfig(level=logging.INFO, stream=sys.stderr, force=True, format=FORMAT)


def rule_logger(snakemake, name: str) -> logging.Logger:
    """Log the rule's script into its first ``log:`` file; the logger ``name``."""
    log_to_file(str(snakemake.log[0]))
    return logging.getLogger(name)
