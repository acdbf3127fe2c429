"""The OpenMP and BLAS pools pinned before the libraries load (plenocal.library_threads):
in a fresh process, as rule refine's script runs, whatever the job's threads."""

import os
import subprocess
import sys

import pytest

# pycolmap's own libgomp (its wheel bundles one): its pool's size as CHOLMOD will see it
_PROBE = """
import sys
if sys.argv[1] == "pin":
    from plenocal.library_threads import pin_library_threads
    pin_library_threads()
import cv2  # noqa: F401  (before pycolmap)
import ctypes
import pycolmap  # noqa: F401
libs = {line.split()[-1] for line in open("/proc/self/maps") if "libgomp" in line}
if not libs:
    print("no-libgomp")
else:
    print(*sorted({ctypes.CDLL(p).omp_get_max_threads() for p in libs}))
"""


def _pool_size(mode: str) -> str:
    env = {**os.environ, "OMP_NUM_THREADS": "2", "OPENBLAS_NUM_THREADS": "2"}
    out = subprocess.run([sys.executable, "-c", _PROBE, mode], env=env, check=True,
                         capture_output=True, text=True)
    return out.stdout.strip()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/self/maps")
def test_the_openmp_pool_is_one_thread_whatever_the_job_asked_for():
    unpinned = _pool_size("plain")
    if unpinned == "no-libgomp":
        pytest.skip("this pycolmap loads no libgomp")
    assert unpinned == "2"  # Snakemake's two threads reach CHOLMOD's OpenMP ...
    assert _pool_size("pin") == "1"  # ... unless pinned first


def test_a_pin_after_numpy_is_refused_and_a_bad_count_too():
    code = ("import numpy\nfrom plenocal.library_threads import pin_library_threads\n"
            "pin_library_threads()\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode != 0 and "after numpy was imported" in out.stderr
    code = "from plenocal.library_threads import pin_library_threads\npin_library_threads(0)\n"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode != 0 and "at least 1" in out.stderr
