"""Memory requests of the jobs whose peak grows with the capture (Snakemake's ``mem_mb``,
which SLURM enforces: a job past its request is killed). A fixed request holds for the
arrays measured and fails on a larger one, so these grow with what the job reads."""

from __future__ import annotations

import math

#: Rule refine: its peak over the size of the match databases it reads
#: (``matches/central.db`` and ``matches/database.db``), with both track sets (peak RSS
#: from the rule's benchmark files, before the track sets were released early, so the
#: peaks are lower now): default-s34 167 MB -> 1,645 MB, tele-s34 165 -> 1,547, dense-s34
#: 234 -> 2,436 (1.9 GB since), wide-s34 83 -> 659, small-s35 58 -> 734. About 10x the
#: databases' size, and a fixed part: the views and the rig.
REFINE_FIXED_MB = 500
REFINE_PER_DATABASE_MB = 10.0
#: never less than the rule asked for before (every geometry measured fits under it)
REFINE_FLOOR_MB = 3000


def refine_mem_mb(database_bytes: int) -> int:
    """The memory (MB) to ask for rule refine's job, given the size in bytes of the match
    databases it reads (:data:`REFINE_PER_DATABASE_MB` per MB of them over
    :data:`REFINE_FIXED_MB`, at least :data:`REFINE_FLOOR_MB`)."""
    if database_bytes < 0:
        raise ValueError(f"refine_mem_mb: a size of {database_bytes} bytes")
    need = REFINE_FIXED_MB + REFINE_PER_DATABASE_MB * database_bytes / 1e6
    return max(REFINE_FLOOR_MB, math.ceil(need))
