"""Running the CPU networks on every core.

The backbone's matrix products are small (a few thousand rows by 64 columns): a multi-threaded
BLAS gains little on them, while the element-wise work between them runs on one core. Python
threads over independent pieces of work (the field's batches of queries: neighbour search,
radius policy and backbone together) use the cores better (numpy releases the GIL in its
matrix products and element-wise loops), with the BLAS held to one thread each so that they do
not fight (docs/performance.md has the figures). Each piece is cut the same way on any number
of threads, so the answers do not depend on it.

The BLAS limit needs ``threadpoolctl`` (a small pure-Python package in requirements.txt and in
the Blender zips); without it the threads still run, with the BLAS's own threads.
"""

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from typing import Callable, Iterable, Iterator


def cpu_threads() -> int:
    """Threads to use: OMP_NUM_THREADS when set (benchmark workers set 1), else the CPU count."""
    try:
        return max(int(os.environ.get("OMP_NUM_THREADS", "")), 1)
    except ValueError:
        return max(os.cpu_count() or 1, 1)


_held = 0             # one_blas_thread blocks running now, in any thread
_limiter = None       # the threadpoolctl limit they share
_held_lock = threading.Lock()


@contextmanager
def one_blas_thread():
    """Hold the BLAS to one thread while the block runs (no-op without threadpoolctl).

    The blocks share one limit: the first to start sets it, the last to end lifts it (setting
    it costs about a millisecond, and the field nests these blocks batch by batch).
    """
    global _held, _limiter
    with _held_lock:
        if _held == 0:
            try:
                from threadpoolctl import threadpool_limits
            except ImportError:
                pass
            else:
                _limiter = threadpool_limits(1, user_api="blas")
        _held += 1
    try:
        yield
    finally:
        with _held_lock:
            _held -= 1
            if _held == 0 and _limiter is not None:
                _limiter.restore_original_limits()
                _limiter = None


def map_in_threads(task: Callable, items: Iterable, threads: int) -> Iterator:
    """``task(item)`` for every item, on ``threads`` threads (in this thread when 1); yields the
    results in the order of ``items`` as they come, so that the caller can report progress.
    The BLAS is held to one thread either way: a multi-threaded BLAS may round a product
    differently, and the answers must not depend on the thread count.

    The first exception any task raises (a cancel, say) is raised here once the tasks that had
    started have finished; the tasks not yet started are dropped.
    """
    items = list(items)
    with one_blas_thread():  # on one thread too: the same BLAS path, the same answers
        if threads <= 1 or len(items) <= 1:
            for item in items:
                yield task(item)
            return
        with ThreadPoolExecutor(min(threads, len(items))) as pool:
            # closing pool.map's iterator (an error, a cancel, the caller stops reading)
            # cancels the tasks not yet started
            yield from pool.map(task, items)


def run_in_threads(task: Callable, items: Iterable, threads: int) -> None:
    """``task(item)`` for every item, on ``threads`` threads (in this thread when 1).

    The first exception any task raises (a cancel, say) is raised here once the tasks that had
    started have finished.
    """
    for _ in map_in_threads(task, items, threads):
        pass
