"""One thread for every library a benchmark script loads (OpenMP, BLAS, numba).

Call :func:`pin` at the top of a benchmark that is run as a script, before numpy, OpenCV
or numba are imported, and only under ``if __name__ == "__main__"``: imported (as
``tests/test_bench_real.py`` imports ``bench_real``), the settings would reach the
importing process, whose numba, having started its threads, then refuses to compile
another kernel ("Cannot set NUMBA_NUM_THREADS to a different value").
"""

from __future__ import annotations

import os

#: the environment variables that bound each library's threads
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                    "NUMBA_NUM_THREADS")


def pin() -> None:
    """Set every library's thread count to one in this process's environment."""
    for name in THREAD_VARIABLES:
        os.environ[name] = "1"
