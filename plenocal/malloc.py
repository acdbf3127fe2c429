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
