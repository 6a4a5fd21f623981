"""The order tiles are sent to workers in, the order their results come back in, and workers
that end with the run."""

import os
import signal
import subprocess
import sys
import time

import pytest

from engine.progress import no_progress
from engine.tile_runners import _windowed, send_order

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


class _Finished:
    def __init__(self, value):
        self.value = value

    def result(self):
        return self.value


def test_costliest_tiles_go_first():
    assert send_order(5, [3.0, 9.0, 1.0, 9.0, 5.0]) == [1, 3, 4, 0, 2]
    assert send_order(3) == [0, 1, 2]


def test_results_keep_the_tile_order_whatever_the_sending_order():
    """And each result is handed to ``keep`` with its own tile's number as it arrives."""
    sent = []

    def submit(args):
        sent.append(args[0])
        return _Finished(f"tile {args[0]}")

    order = send_order(4, [1.0, 4.0, 2.0, 3.0])
    results = _windowed(submit, lambda futures: futures[:1], order, lambda number: (number,),
                        window=2, progress=no_progress, cancel=None, where="here",
                        keep=lambda number, result: (number, result.upper()))
    assert sent == [1, 3, 2, 0]
    assert results == [(0, "TILE 0"), (1, "TILE 1"), (2, "TILE 2"), (3, "TILE 3")]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_workers_end_when_their_parent_is_killed():
    """A run killed outright (out of memory, kill -9) leaves no worker computing on."""
    parent = subprocess.Popen(
        [sys.executable, "-c", "import time; from engine.tile_runners import run_tiles; "
                               "run_tiles(time.sleep, 2, lambda number: (120.0,), workers=2)"],
        cwd=ROOT, env={**os.environ, "PYTHONPATH": ROOT})
    try:
        workers = []
        deadline = time.monotonic() + 60
        while len(workers) < 2 and time.monotonic() < deadline:
            time.sleep(0.2)
            workers = _spawned_children(parent.pid)
        assert len(workers) == 2, "the workers did not start"
        time.sleep(1.0)  # past their start-up
    finally:
        parent.kill()
        parent.wait()
    deadline = time.monotonic() + 20
    while any(_alive(pid) for pid in workers) and time.monotonic() < deadline:
        time.sleep(0.2)
    left = [pid for pid in workers if _alive(pid)]
    for pid in left:
        os.kill(pid, signal.SIGKILL)
    assert not left, "workers outlived their parent"


def _spawned_children(parent: int) -> list:
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = open(f"/proc/{entry}/stat").read()
            command = open(f"/proc/{entry}/cmdline", "rb").read()
        except OSError:
            continue
        ppid = int(stat.rsplit(")", 1)[1].split()[1])
        if ppid == parent and b"spawn_main" in command:
            found.append(int(entry))
    return found


def _alive(pid: int) -> bool:
    try:
        state = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="VmHWM is Linux's")
def test_a_worker_reports_its_own_peak_memory_not_its_parents():
    import numpy as np

    from engine.tile_runners import process_peak_bytes, run_tiles

    held = np.ones(400 * 2 ** 20 // 8)  # 400 MiB, touched, held by this process
    own = process_peak_bytes()
    assert own >= held.nbytes
    peaks = run_tiles(process_peak_bytes, 2, lambda number: (), workers=2)
    # a fresh worker holds the interpreter, numpy and the engine, far less than its parent
    assert all(0 < peak < own - 300 * 2 ** 20 for peak in peaks), (peaks, own)


def test_blenders_main_is_hidden_from_starting_workers_and_given_back(monkeypatch):
    """Inside Blender ``__main__`` is the script Blender runs (or a name that is no file): a
    spawned worker would run it again, so while workers start it names nothing."""
    import types

    from engine.tile_runners import _main_hidden

    main = types.ModuleType("__main__")
    main.__file__ = "<blender string>"
    monkeypatch.setitem(sys.modules, "__main__", main)
    with _main_hidden(True):
        assert not hasattr(main, "__file__") and main.__spec__ is None
    assert main.__file__ == "<blender string>"
    with _main_hidden(False):  # the command line: scripts keep their __name__ guard
        assert main.__file__ == "<blender string>"
