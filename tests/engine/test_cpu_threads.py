"""Proofs for running work on several CPU threads."""

import threading

import pytest

from engine.cpu_threads import cpu_threads, run_in_threads


def test_every_item_runs_once_on_the_threads_asked_for():
    seen, names = [], set()

    def task(item):
        seen.append(item)
        names.add(threading.current_thread().name)

    run_in_threads(task, range(50), threads=3)
    assert sorted(seen) == list(range(50))
    assert len(names) <= 3
    seen.clear()
    run_in_threads(task, range(5), threads=1)
    assert seen == list(range(5))                 # one thread: in order, in this thread


def test_a_task_that_raises_stops_the_run_with_its_error():
    def task(item):
        if item == 7:
            raise RuntimeError("cancelled at 7")

    with pytest.raises(RuntimeError, match="cancelled at 7"):
        run_in_threads(task, range(20), threads=2)


def test_thread_count_follows_omp_num_threads(monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    assert cpu_threads() == 1
    monkeypatch.setenv("OMP_NUM_THREADS", "not a number")
    assert cpu_threads() >= 1
    monkeypatch.delenv("OMP_NUM_THREADS")
    assert cpu_threads() >= 1
