"""The thread pools that numerical libraries start when they load, pinned before they do.

Snakemake sets ``OMP_NUM_THREADS``, ``OPENBLAS_NUM_THREADS`` and their kin to a job's
threads. OpenMP (pycolmap's bundled libgomp, under CHOLMOD's sparse Cholesky) and BLAS
read them once, when the library loads, and a sum split over another number of threads
is added in another order. In rule ``refine`` that changed the cameras' last digits with
the job's thread count: wide-s1's refined focal length 2110.476832265343 px with one
OpenMP thread, 2110.4768325203077 px with two, each the same run after run
(BENCHMARKS.md, "The refine job's threads: the same bytes for any number"). Pinned to one
thread, the job's threads go to the work that splits without changing a bit (Ceres'
Jacobians, each residual block's into its own place; the observations' alignment, one
batch of images per thread), so ``refine.num_threads`` changes the time and nothing else.
"""

from __future__ import annotations

import os
import sys

#: the environment variables that size the pools of OpenMP, OpenBLAS, MKL and Accelerate
POOL_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS",
                  "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS")
#: the modules that load such a pool (numpy: BLAS; cv2: numpy; pycolmap: libgomp)
POOL_MODULES = ("numpy", "cv2", "pycolmap")


def pin_library_threads(threads: int = 1) -> None:
    """Size the OpenMP and BLAS pools of this process to ``threads``; call it before
    numpy, OpenCV or pycolmap is imported (they read the size once, when they load).
    Raises RuntimeError where one of them already is: the pin would not take."""
    loaded = [m for m in POOL_MODULES if m in sys.modules]
    if loaded:
        raise RuntimeError(f"pin_library_threads() after {', '.join(loaded)} was imported: "
                           "its thread pool is already sized; call it first in the script")
    if threads < 1:
        raise ValueError(f"pin_library_threads: threads must be at least 1, not {threads}")
    for name in POOL_VARIABLES:
        os.environ[name] = str(int(threads))
