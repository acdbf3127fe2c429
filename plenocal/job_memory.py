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


#: Rules reprojection_calib and reprojection_complete (Table I's triangulations): peak RSS
#: over the size of ``matches/database.db`` (the benchmark files of the kept captures):
#: small-s35 53 MB -> 270 MB, wide-s34 76 -> 415, default-s34 150 -> 692, tele-s34
#: 152 -> 678, raytrix-s34 163 -> 743, square-galilean-s34 173 -> 820, dense-s34
#: 207 -> 942: 4.5-5.5x the database's size.
REPROJECTION_FIXED_MB = 200
REPROJECTION_PER_DATABASE_MB = 6.0
REPROJECTION_FLOOR_MB = 1500


def _grown(name: str, database_bytes: int, fixed_mb: int, per_mb: float, floor_mb: int
           ) -> int:
    if database_bytes < 0:
        raise ValueError(f"{name}: a size of {database_bytes} bytes")
    return max(floor_mb, math.ceil(fixed_mb + per_mb * database_bytes / 1e6))


def refine_mem_mb(database_bytes: int) -> int:
    """The memory (MB) to ask for rule refine's job, given the size in bytes of the match
    databases it reads (:data:`REFINE_PER_DATABASE_MB` per MB of them over
    :data:`REFINE_FIXED_MB`, at least :data:`REFINE_FLOOR_MB`)."""
    return _grown("refine_mem_mb", database_bytes, REFINE_FIXED_MB, REFINE_PER_DATABASE_MB,
                  REFINE_FLOOR_MB)


def reprojection_mem_mb(database_bytes: int) -> int:
    """The memory (MB) to ask for a Table I triangulation (rules reprojection_calib and
    reprojection_complete), given the size in bytes of the view database it reads
    (:data:`REPROJECTION_PER_DATABASE_MB` per MB over :data:`REPROJECTION_FIXED_MB`, at
    least :data:`REPROJECTION_FLOOR_MB`)."""
    return _grown("reprojection_mem_mb", database_bytes, REPROJECTION_FIXED_MB,
                  REPROJECTION_PER_DATABASE_MB, REPROJECTION_FLOOR_MB)
