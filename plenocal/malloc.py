"""The C allocator's settings for jobs that allocate and free large buffers in a loop.

glibc's ``malloc`` serves a large request (over its mmap threshold, which it raises on
its own up to 32 MB as such blocks are freed) by mapping fresh pages, and gives the top of
its heap back to the system whenever more than its trim threshold (twice the mmap
threshold) lies free there. A job that runs OpenCV's SIFT on hundreds of views, each with
its own scale space (a 666 x 502 view upsampled 2x: tens of MB), then faults in fresh,
zeroed pages for every view: on the default data rule ``view_features`` spent 1.0-1.1 of its
3.3 s a shot (25 views) in the kernel. With the heap kept (:func:`keep_freed_memory`) it
is 0.1 s, and the jobs take 0.7 of their time (BENCHMARKS.md, "The allocator in the SIFT
jobs"). The numbers computed do not change: only where the buffers lie.

numpy asks the kernel for transparent huge pages (``madvise(MADV_HUGEPAGE)``) on every
array of 4 MB or more. Where the kernel serves such requests only (``madvise`` in
``/sys/kernel/mm/transparent_hugepage/enabled`` and ``defrag``: Ubuntu's defaults), each
first touch of a 2 MB page waits for the kernel to find, compact and zero one. The
converter's measurements make arrays of hundreds of MB and free them: on this project's
2-core VMs one call of the safe diameter's measure spent 1.8 s in the kernel for 0.1 s of
work, and ``plenocal convert`` on a 12-MP frame 2.3-3.7 s of 5.7-7.0 s
(:func:`no_huge_pages`; BENCHMARKS.md, "numpy's huge pages"). Ordinary 4 kB pages fault
in more often and cost a few microseconds each.
"""

from __future__ import annotations

import ctypes
import logging

log = logging.getLogger(__name__)

#: ``mallopt`` parameters (glibc's malloc.h)
M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
#: blocks up to this size come from the heap (glibc's own ceiling for its dynamic threshold)
MMAP_THRESHOLD_BYTES = 32 << 20
#: this much free memory at the heap's top is kept for the next request, not given back
TRIM_THRESHOLD_BYTES = 256 << 20


def no_huge_pages() -> bool:
    """Stop numpy asking for transparent huge pages for the arrays it allocates from now
    on in this process (the module docstring): what ``NUMPY_MADVISE_HUGEPAGE=0`` does when
    numpy is imported. Every rule's script (:func:`plenocal.rulelog.log_to_file`) and the
    command line start with it. The numbers do not change. A ``NUMPY_MADVISE_HUGEPAGE``
    in the environment is the user's choice and is left as numpy took it. Returns whether
    the setting was made: False where the environment chose, or where this numpy has no
    such switch (nothing changes)."""
    import os  # noqa: PLC0415

    import numpy as np  # noqa: PLC0415

    if os.environ.get("NUMPY_MADVISE_HUGEPAGE") is not None:
        return False

    setter = getattr(np._core.multiarray, "_set_madvise_hugepage", None)  # numpy 2
    if setter is None:
        return False
    setter(False)
    log.debug("numpy: no transparent huge pages for new arrays")
    return True


def keep_freed_memory(mmap_threshold: int = MMAP_THRESHOLD_BYTES,
                      trim_threshold: int = TRIM_THRESHOLD_BYTES) -> bool:
    """Set this process's glibc ``malloc`` to serve blocks up to ``mmap_threshold`` bytes
    from its heap and to keep up to ``trim_threshold`` bytes free at the heap's top (the
    module docstring), for the rest of the process's life. Costs at most
    ``trim_threshold`` of resident memory beyond what the process holds. Returns whether
    the settings were taken: False where the C library is not glibc (nothing changes)."""
    try:  # the process's own symbols: the C library it runs on
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    ok = (mallopt(M_MMAP_THRESHOLD, int(mmap_threshold)) == 1
          and mallopt(M_TRIM_THRESHOLD, int(trim_threshold)) == 1)
    log.debug("malloc: heap blocks up to %d bytes, %d bytes kept free: %s", mmap_threshold,
              trim_threshold, "set" if ok else "not taken")
    return ok
