"""Memory requests of the jobs whose peak grows with the capture (Snakemake's ``mem_mb``,
which SLURM enforces: a job past its request is killed). A fixed request holds for the
arrays measured and fails on a larger one, so these grow with what the job reads."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class GrowingRequest:
    """A job's memory request (MB): ``fixed_mb`` plus ``per_database_mb`` per MB of what it
    grows with (the match databases it reads; rule refine's, the track sets), never under
    ``floor_mb``. Called with their size in bytes."""

    name: str
    fixed_mb: int
    per_database_mb: float
    floor_mb: int

    def __call__(self, database_bytes: int) -> int:
        if database_bytes < 0:
            raise ValueError(f"{self.name}: a size of {database_bytes} bytes")
        return max(self.floor_mb,
                   math.ceil(self.fixed_mb + self.per_database_mb * database_bytes / 1e6))


#: Rule refine_tracks (one track set; rule refine made both in one process until
#: BENCHMARKS.md "The refine job's track sets as jobs of their own"): the one job's peak
#: over the size of the match databases it read (``matches/central.db`` and
#: ``matches/database.db``; peak RSS from the rule's benchmark files, before the track
#: sets were released early): default-s34 167 MB -> 1,645 MB, tele-s34 165 -> 1,547,
#: dense-s34 234 -> 2,436 (1.9 GB since), wide-s34 83 -> 659, small-s35 58 -> 734. About
#: 10x the databases' size, and a fixed part: the views and the rig. Each track set's job
#: reads one of the two databases and peaks lower (the default data: 772 MB for the
#: central views' set, 718 MB for every view's, against 1,330 MB for the one job); the
#: same request holds for it. Never less than the 3 GB the rule asked for before.
refine_tracks_mem_mb = GrowingRequest("refine_tracks_mem_mb", 500, 10.0, 3000)

#: Rule refine (the adjustments on the track sets): its peak over the size of the track
#: sets' folders it reads. The default data: 43 MB -> 1,212 MB (the rig reconstruction and
#: COLMAP's bundle adjustment of 1.23 million observations; the sets are read where the
#: reconstruction is built and released before the adjustments), 17x beyond the fixed
#: part; asked 30x, never less than the 3 GB the rule asked for before (dense-s34, the
#: largest capture measured, peaked at 1.9 GB with its databases' 234 MB).
refine_mem_mb = GrowingRequest("refine_mem_mb", 500, 30.0, 3000)

#: Rules reprojection_calib and reprojection_complete (Table I's triangulations): peak RSS
#: over the size of ``matches/database.db`` (the benchmark files of the kept captures):
#: small-s35 53 MB -> 270 MB, wide-s34 76 -> 415, default-s34 150 -> 692, tele-s34
#: 152 -> 678, raytrix-s34 163 -> 743, square-galilean-s34 173 -> 820, dense-s34
#: 207 -> 942: 4.5-5.5x the database's size. Never less than their former 1.5 GB.
reprojection_mem_mb = GrowingRequest("reprojection_mem_mb", 200, 6.0, 1500)
