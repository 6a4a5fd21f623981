"""Proofs for running work on several CPU threads."""

import threading

import numpy as np
import pytest

from engine.cpu_threads import (core_budget, cpu_threads, map_in_threads, query_threads,
                                run_in_threads)


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


def test_a_core_budget_caps_the_threads_and_lifts_after(monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", "8")
    assert cpu_threads() == 8 and query_threads() == 8
    with core_budget(1):
        assert cpu_threads() == 1 and query_threads() == 1
        with core_budget(3):  # a block inside may narrow the budget, never widen it
            assert cpu_threads() == 1
    with core_budget(3):
        assert cpu_threads() == 3
    with core_budget(0):  # 0: every core
        assert cpu_threads() == 8
    assert cpu_threads() == 8


def test_a_k_d_query_inside_a_threaded_task_runs_on_its_thread(monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", "4")
    inside = list(map_in_threads(lambda item: query_threads(), range(8), threads=4))
    assert inside == [1] * 8           # the task's siblings hold the other cores
    assert query_threads() == 4        # outside the tasks: every core


def test_workers_1_runs_every_stage_on_one_core(monkeypatch):
    from engine.reconstruct import reconstruct

    monkeypatch.setenv("OMP_NUM_THREADS", "4")
    rng = np.random.default_rng(0)
    points = np.column_stack([rng.random((3000, 2)), np.zeros(3000)])
    for workers, expected in ((1, 1), (0, 4)):
        seen = set()
        reconstruct(points, {"resolution": 32, "device": "cpu", "workers": workers},
                    progress=lambda fraction, message: seen.add((cpu_threads(),
                                                                 query_threads())),
                    udf_source="nearest")
        assert seen == {(expected, expected)}, (workers, seen)
    assert cpu_threads() == 4
