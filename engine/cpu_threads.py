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


_budget = 0           # cores a reconstruction may use (core_budget), 0: no limit
_pool = threading.local()  # .inside: this thread runs one of map_in_threads's tasks


def cpu_threads() -> int:
    """Threads to use: OMP_NUM_THREADS when set (worker processes set 1), else the CPU count;
    at most the cores of a :func:`core_budget` block."""
    try:
        threads = max(int(os.environ.get("OMP_NUM_THREADS", "")), 1)
    except ValueError:
        threads = max(os.cpu_count() or 1, 1)
    return min(threads, _budget) if _budget else threads


def query_threads() -> int:
    """Threads for one k-d query (``cKDTree.query(workers=...)``): one inside a task of
    :func:`map_in_threads` (its siblings hold the other cores), else :func:`cpu_threads`."""
    return 1 if getattr(_pool, "inside", False) else cpu_threads()


@contextmanager
def core_budget(cores: int):
    """Let the work in the block use at most ``cores`` cores (0: every core): the threads of
    the field, the mesher and the k-d queries, and the BLAS's. ``--workers 1`` is one core."""
    global _budget
    if cores <= 0:
        yield
        return
    before, _budget = _budget, cores if not _budget else min(_budget, cores)
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        limiter = None
    else:
        limiter = threadpool_limits(_budget, user_api="blas")
    try:
        yield
    finally:
        _budget = before
        if limiter is not None:
            limiter.restore_original_limits()


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
        def in_pool(item):
            _pool.inside = True
            return task(item)

        with ThreadPoolExecutor(min(threads, len(items))) as pool:
            # closing pool.map's iterator (an error, a cancel, the caller stops reading)
            # cancels the tasks not yet started
            yield from pool.map(in_pool, items)


def run_in_threads(task: Callable, items: Iterable, threads: int) -> None:
    """``task(item)`` for every item, on ``threads`` threads (in this thread when 1).

    The first exception any task raises (a cancel, say) is raised here once the tasks that had
    started have finished.
    """
    for _ in map_in_threads(task, items, threads):
        pass
