"""Running the CPU networks on every core.

The backbone's matrix products are small (a few thousand rows by 64 columns): a multi-threaded
BLAS gains little on them, while the element-wise work between them runs on one core. Python
threads over independent groups of patches use the cores better (numpy releases the GIL), with
the BLAS held to one thread each so that they do not fight (docs/performance.md has the
figures).

The BLAS limit needs ``threadpoolctl`` (a small pure-Python package in requirements.txt and in
the Blender zips); without it the threads still run, with the BLAS's own threads.
"""

import os
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from typing import Callable, Iterable


def cpu_threads() -> int:
    """Threads to use: OMP_NUM_THREADS when set (benchmark workers set 1), else the CPU count."""
    try:
        return max(int(os.environ.get("OMP_NUM_THREADS", "")), 1)
    except ValueError:
        return max(os.cpu_count() or 1, 1)


@contextmanager
def one_blas_thread():
    """Hold the BLAS to one thread while the block runs (no-op without threadpoolctl)."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        yield
        return
    with threadpool_limits(1, user_api="blas"):
        yield


def run_in_threads(task: Callable, items: Iterable, threads: int) -> None:
    """``task(item)`` for every item, on ``threads`` threads (in this thread when 1).

    The first exception any task raises (a cancel, say) is raised here once the tasks that had
    started have finished.
    """
    items = list(items)
    if threads <= 1 or len(items) <= 1:
        for item in items:
            task(item)
        return
    with one_blas_thread(), ThreadPoolExecutor(min(threads, len(items))) as pool:
        for _ in pool.map(task, items):
            pass
