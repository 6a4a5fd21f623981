"""Where the tiles of a reconstruction run: in this process, in worker processes, or on a Dask
cluster. Each tile is computed the same way wherever it runs, so the mesh is the same, bit for
bit, for any number of workers.

Worker processes are started fresh (``spawn``: no state inherited from the caller, safe with
threads) and each runs its tiles on one thread, so ``workers`` processes use ``workers`` cores.
On Linux they end with the process that started them, even one killed outright.
Dask (``pip install "dask[distributed]"``) is optional: ``scheduler="local"`` starts a local
cluster of ``workers`` processes, any other value is the address of a running scheduler
(``tcp://host:8786``).

Inside Blender the engine is a subpackage of the extension (``bl_ext.<repository>.<id>.engine``),
whose ``__init__`` needs bpy, which a worker process has not: a worker first puts stand-ins for
the packages above the engine in ``sys.modules`` (:func:`_worker_start`), so the engine imports
alone, without Blender, and does not run Blender's ``__main__`` (:func:`_main_hidden`). Should
the workers not start there all the same, the tiles run in Blender's own process, one after the
other.
"""

import os
import sys
from contextlib import contextmanager
from typing import Callable, List, Optional, Sequence

from .errors import InputError
from .progress import CancelFn, ProgressFn, check_cancel, no_progress, sub_progress

POLL_SECONDS = 0.2
"""How often a waiting run checks for a cancel."""
IN_FLIGHT = 2
"""Tiles sent ahead per worker (one running, one waiting)."""
CONNECT_SECONDS = 10
"""How long to try reaching a Dask scheduler before saying it cannot be reached."""
TERMINATE_SECONDS = 2.0
"""How long a stopped worker process may take to end before it is killed."""


def available_cores() -> int:
    """CPU cores this process may use."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except AttributeError:
        return max(os.cpu_count() or 1, 1)


def run_tiles(task: Callable, count: int, job: Callable[[int], tuple], workers: int = 1,
              scheduler: str = "", progress: Optional[ProgressFn] = None,
              cancel: Optional[CancelFn] = None, costs: Optional[Sequence[float]] = None,
              keep: Optional[Callable[[int, object], object]] = None) -> List:
    """``[keep(i, task(*job(i))) for i in range(count)]``, in order, run as asked.

    task : a module-level function (it is sent to other processes); in this process it also
        gets ``progress=`` and ``cancel=`` keywords.
    job : the arguments of tile ``i``, made only when the tile is about to be sent, so at most
        :data:`IN_FLIGHT` tiles per worker have their inputs in memory at once.
    workers : processes (0: every core); with one, the tiles run in this process.
    scheduler : ``""`` (no Dask), ``"local"`` or a Dask scheduler's address.
    progress : called with the share of tiles done.
    cancel : polled while waiting; on a cancel the workers are stopped and :class:`Cancelled`
        raised.
    costs : an estimate of each tile's work; workers get the costliest tiles first, so that
        the last ones to finish are short (the results keep their order).
    keep : what to keep of tile ``i``'s result, called in this process as each result arrives
        (to put its bulk on disk, say); by default the whole result.
    """
    progress = progress or no_progress
    keep = keep or _whole
    workers = workers or available_cores()
    order = send_order(count, costs)
    if scheduler:
        return _on_dask(task, order, job, workers, scheduler, progress, cancel, keep)
    if workers > 1 and count > 1:
        try:
            return _in_processes(task, order, job, min(workers, count), progress, cancel, keep)
        except _WorkersDidNotStart:  # inside Blender only: see the module docstring
            progress(0.0, "worker processes could not start: making the tiles here")
    results = []
    for number in range(count):
        check_cancel(cancel)
        part = sub_progress(progress, number / count, (number + 1) / count)
        part(0.0, f"tile {number + 1} of {count}")
        results.append(keep(number, task(*job(number), progress=part, cancel=cancel)))
    return results


class _WorkersDidNotStart(Exception):
    """Inside an extension, the worker processes could not start."""


def _whole(number: int, result):
    """The default of what to keep of a tile's result: all of it."""
    return result


def process_resident_bytes() -> int:
    """This process's resident memory now (``VmRSS``), in bytes; 0 where /proc is missing."""
    return _status_bytes("VmRSS")


def _status_bytes(key: str) -> int:
    """A ``kB`` line of /proc/self/status in bytes, 0 where it cannot be read."""
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith(key + ":"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def process_peak_bytes() -> int:
    """This process's peak resident memory so far, in bytes (0 where it cannot be read).

    On Linux ``VmHWM``, which starts afresh when a worker process starts. Not
    ``getrusage(RUSAGE_CHILDREN)`` in the parent: a child started by fork and exec carries in
    it the parent's size at the fork.
    """
    peak = _status_bytes("VmHWM")
    if peak:
        return peak
    try:
        import resource
    except ImportError:  # Windows
        return 0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(peak if sys.platform == "darwin" else peak * 1024)  # bytes on macOS, else kB


def send_order(count: int, costs: Optional[Sequence[float]] = None) -> List[int]:
    """The tile numbers, costliest first (ties by number); in number order without costs."""
    if costs is None:
        return list(range(count))
    return sorted(range(count), key=lambda number: (-costs[number], number))


def _windowed(submit: Callable, wait_some: Callable, order: List[int], job, window: int,
              progress: ProgressFn, cancel: Optional[CancelFn], where: str, keep) -> List:
    """Keep ``window`` tiles in flight (``submit(args) -> future``), sent in ``order``;
    return what ``keep(number, result)`` keeps of their results, by tile number.

    ``wait_some(futures)`` returns the futures finished within :data:`POLL_SECONDS`.
    """
    count = len(order)
    results = [None] * count
    running = {}
    sent = done = 0
    while done < count:
        check_cancel(cancel)
        while sent < count and len(running) < window:
            running[submit(job(order[sent]))] = order[sent]
            sent += 1
        for future in wait_some(list(running)):
            number = running.pop(future)
            results[number] = keep(number, future.result())
            done += 1
        progress(done / count, f"{done} of {count} tiles done {where}")
    return results


def _one_thread() -> None:
    """Worker start-up: one thread per worker process (the workers fill the cores)."""
    os.environ["OMP_NUM_THREADS"] = "1"
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        return
    threadpool_limits(1)


def _pool_worker_start(parent: int) -> None:
    """A worker process's start-up: one thread, and on Linux an end with the run that started
    it: killed outright (out of memory, ``kill -9``), the run leaves no worker computing a tile
    nobody will read. (Not for Dask's workers: their parent is Dask's nanny.)"""
    _one_thread()
    _end_with_parent(parent)


def _end_with_parent(parent: int) -> None:
    """Ask Linux to send this process SIGTERM when its parent (pid ``parent``) ends
    (``PR_SET_PDEATHSIG``)."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes
    import signal

    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGTERM))  # 1: PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return
    if os.getppid() != parent:  # the parent ended before the request: end now
        os.kill(os.getpid(), signal.SIGTERM)


WORKER_SETUP = """
import importlib, sys, types
names = {names!r}
for depth, name in enumerate(names, 1):
    if name not in sys.modules:
        stand_in = types.ModuleType(name)
        stand_in.__path__ = [{folder!r}] if depth == len(names) else []
        sys.modules[name] = stand_in
importlib.import_module({engine!r} + ".tile_runners")._pool_worker_start({parent!r})
"""
"""What a worker runs first when the engine is a subpackage (``{names}``: the packages above it,
outermost first; ``{folder}``: the innermost one's folder)."""


def _worker_start() -> tuple:
    """The worker pool's initializer and its arguments: :func:`_pool_worker_start`, or, when the
    engine is a subpackage (an extension's, inside Blender), ``exec`` of :data:`WORKER_SETUP`
    first: ``exec`` is a builtin, so sending it imports nothing of the extension."""
    parts = __package__.split(".")
    if len(parts) == 1:
        return _pool_worker_start, (os.getpid(),)
    names = [".".join(parts[:depth]) for depth in range(1, len(parts))]
    folder = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    setup = WORKER_SETUP.format(names=names, folder=folder, engine=__package__,
                                parent=os.getpid())
    return exec, (setup, {})


@contextmanager
def _main_hidden(hide: bool):
    """With ``hide``, ``__main__`` names no file and no module while workers start, so that a
    spawned worker does not run it again: inside Blender ``__main__`` is the script Blender
    runs (``--python``, without a ``__name__`` guard as often as not) or a name that is not a
    file (``<blender string>``), and the workers need nothing of it."""
    main = sys.modules.get("__main__")
    if not hide or main is None:
        yield
        return
    saved = {name: main.__dict__[name] for name in ("__file__", "__spec__")
             if name in main.__dict__}
    main.__dict__.pop("__file__", None)
    main.__spec__ = None
    try:
        yield
    finally:
        main.__dict__.pop("__spec__", None)
        main.__dict__.update(saved)


def _in_processes(task, order, job, workers, progress, cancel, keep) -> List:
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    initializer, initargs = _worker_start()
    pool = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=initializer, initargs=initargs)
    try:
        with _main_hidden(initializer is exec):
            if initializer is exec:  # inside an extension: do the workers start at all?
                probe = pool.submit(os.getpid)
                while not probe.done():
                    check_cancel(cancel)
                    wait([probe], timeout=POLL_SECONDS)
                try:
                    probe.result()
                except BrokenProcessPool:
                    raise _WorkersDidNotStart() from None
            return _windowed(lambda args: pool.submit(task, *args),
                             lambda futures: wait(futures, timeout=POLL_SECONDS,
                                                  return_when=FIRST_COMPLETED)[0],
                             order, job, IN_FLIGHT * workers, progress, cancel,
                             f"on {workers} workers", keep)
    except BrokenProcessPool:
        raise InputError("the worker processes stopped before finishing (out of memory, or a "
                         "script that calls reconstruct() outside `if __name__ == "
                         "\"__main__\":`); run with workers=1 to use this process only") from None
    finally:
        processes = list(getattr(pool, "_processes", {}).values())
        for process in processes:
            process.terminate()  # a cancel or an error: stop the tiles still running
        for process in processes:
            # a worker inside numba's compiler (LLVM's signal handlers) may not end on SIGTERM
            process.join(TERMINATE_SECONDS)
            if process.is_alive():
                process.kill()
        pool.shutdown(wait=True, cancel_futures=True)


def _on_dask(task, order, job, workers, scheduler, progress, cancel, keep) -> List:
    try:
        from dask.distributed import Client, LocalCluster, wait
    except ImportError:
        raise InputError("running tiles on Dask needs Dask: pip install \"dask[distributed]\"; "
                         "or run without a scheduler") from None
    cluster = None
    if scheduler == "local":
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=None)
        client = Client(cluster)
    else:
        try:
            client = Client(scheduler, timeout=f"{CONNECT_SECONDS}s")
        except (OSError, TimeoutError) as error:
            raise InputError(f"could not reach the Dask scheduler at {scheduler}: "
                             f"{error}") from None
    running = []
    try:
        client.run(_one_thread)
        window = IN_FLIGHT * max(len(client.scheduler_info()["workers"]), 1)

        def submit(args):
            future = client.submit(task, *args, pure=False)
            running.append(future)
            return future

        def wait_some(futures):
            try:
                return wait(futures, timeout=POLL_SECONDS, return_when="FIRST_COMPLETED").done
            except TimeoutError:
                return []

        return _windowed(submit, wait_some, order, job, window, progress, cancel, "on Dask",
                         keep)
    finally:
        client.cancel([future for future in running if not future.done()])
        client.close()
        if cluster is not None:
            cluster.close()
