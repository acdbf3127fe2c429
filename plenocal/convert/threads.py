"""Threads for the converter: OpenCV and numpy let go of the GIL in their calls, so a
frame's bands and views, and independent measurements, run side by side on a job's
threads (the same bytes with any number: every piece is computed alone)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor


@contextlib.contextmanager
def opencv_threads(n: int | None) -> Iterator[None]:
    """OpenCV's own thread count set to ``n`` inside the block (None: left alone). Our
    threads each call OpenCV on small bands, where its own threads only compete: with them
    at 1, two threads rendered Boys2's 25 views 1.8x as fast as one (2.07 against 3.73 s),
    with OpenCV's at 2 only 1.2x."""
    if n is None:
        yield
        return
    import cv2  # noqa: PLC0415

    before = cv2.getNumThreads()
    cv2.setNumThreads(n)
    try:
        yield
    finally:
        cv2.setNumThreads(before)


class Inline:
    """An executor that runs each job at once, in the caller's thread (one thread)."""

    def submit(self, fn, *args, **kwargs) -> Future:
        job: Future = Future()
        try:
            job.set_result(fn(*args, **kwargs))
        except BaseException as exc:  # noqa: BLE001  (handed on by result())
            job.set_exception(exc)
        return job

    def shutdown(self) -> None:
        pass


def run_all(work, items: list, threads: int) -> None:
    """``work(item)`` for every item, on ``threads`` threads (in order on one); a
    worker's error is raised here."""
    if threads <= 1 or len(items) <= 1:
        for item in items:
            work(item)
        return
    with ThreadPoolExecutor(max_workers=threads) as pool:
        for _ in pool.map(work, items):
            pass


def map_threads(work, items: list, threads: int) -> list:
    """``[work(item) for item in items]``, the items side by side on ``threads`` threads
    (in order on one); the results in the items' order, a worker's error raised here."""
    if threads <= 1 or len(items) <= 1:
        return [work(item) for item in items]
    with ThreadPoolExecutor(max_workers=threads) as pool:
        return list(pool.map(work, items))
